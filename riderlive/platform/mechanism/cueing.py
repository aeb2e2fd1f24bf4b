"""Motion cueing: the saddle's pose in, the platform's cue pose out (Model / State / step).

Input, per frame: the saddle pose ``saddle.tx ty tz rx ry rz`` (m, deg, the rig frame
of :mod:`riderlive.channels`). Output: the cue, a pose of the platform's cue centre
relative to home (same units and order). Per axis:

1. **Centre tracking: replay, moves that fit, washout.** A first-order tracker ``r``
   follows the input; the cue is ``c = k (x - r)``. Three regimes, by the size of ``c``:

   - inside the **gait envelope** (1.25 x the scaled ``reference_amplitude``, the
     largest gait swing): **replay**. The tracker's cut-off is ``drift_cutoff_hz``, so
     an IMU's drift or an offset is removed and the stride's oscillation (>= 0.67 Hz)
     passes at >= 99 % amplitude;
   - outside the envelope but below ``knee`` of the axis' room: a **move that fits**
     is played as it is: the tracker all but stops (2 % of the drift cut-off), so
     the platform comes back to centre exactly when the saddle does, with no undershoot;
   - past the knee on any axis (a jump, a rear, a stop, a buck too big for the
     platform): **washout**, on every axis at once (a move is a whole-body event: the
     stop's 12 deg of pitch come with 0.35 m of drop). Within ``washout_attack_s``
     the cut-offs rise to ``washout_*_hz``; they stay there until every axis' cue has
     been back inside its gait envelope for ``washout_hold_s``, then relax to replay
     (``washout_release_s``).

   For a steady input the tracker's error decays as ``exp(-omega t)`` with ``omega > 0``:
   it **never changes sign, so the return to centre cannot pass centre**, at any
   cut-off and any frame rate (each frame multiplies the error by ``exp(-omega dt)``).
   A second-order high-pass (classical washout) would undershoot by up to 13 %.
2. **Scale into the workspace.** ``k = scale x intensity``; ``scale`` defaults to the
   largest that keeps a gait of ``reference_amplitude`` (the procedural horse's largest
   saddle swing per axis) below the knee, at most 1. Beyond the knee the cue is
   compressed smoothly (``tanh``) toward the axis' room (``share`` of how far the
   axis reaches alone from home), never past it.
3. **Tilt coordination.** The saddle's sustained surge and sway acceleration (a
   critically damped low-pass at ``tilt_cutoff_hz`` of its second derivative) is
   rendered as a pitch and a roll of ``atan(a / g)``, so gravity pushes the rider as
   the acceleration would: nose up for a forward acceleration, rolled left for an
   acceleration to the right. It is limited to ``tilt_max_deg`` and moves no faster
   than ``tilt_rate_dps`` (below the rotation a rider notices as such).

Live parameters: :meth:`CueingModel.with_params` makes a new model; :func:`step`
blends the state's parameters toward it with the time constant ``blend_s``, so a new
intensity or cut-off never jumps the platform. A frame with NaN or inf holds the last
finite value of that axis (counted). The per-frame kernel :func:`cue_frame` is the
one source: plain Python on floats, compiled by numba for the tick (:func:`step`,
one frame) and for a bake (:func:`run`, a loop); tests run the Python source too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import jit
from riderlive.platform.mechanism.cueing_params import PRESETS, CueingParams

FloatArray = npt.NDArray[np.float64]
GRAVITY = 9.80665
DEG = math.pi / 180.0
TWO_PI = 2.0 * math.pi


# Parameter vector: per-axis blocks of 6, then scalars.
K, WN, WP, GATE = 0, 6, 12, 18
OR, OW_T, OW_R = 24, 25, 26  # replay (drift) and washout cut-offs (translations, rotations), rad/s
KNEE, HOLD, ATTACK, RELEASE, TILT_W, TILT_RATE, TILT_MAX, TILT_K = 27, 28, 29, 30, 31, 32, 33, 34
N_PARAMS = 35
# State vector: per axis the tracker, the time since the cue was last outside the gait envelope and
# the last finite input; then the washout latch and its smoothed engagement, the tilt filter, counters.
R, H, U = 0, 6, 12
LATCH, M = 18, 19
TP, TV, TA = 20, 22, 24  # tilt filter position, velocity (surge, sway); tilt (pitch, roll), deg
PRIMED, NAN_FRAMES, COMPRESSED, ENGAGED = 26, 27, 28, 29
N_STATE = 30
NEVER = 1e9
"""Time since the cue was last outside the gait envelope, before it ever was (s)."""
ENVELOPE_MARGIN = 1.25
"""The gait envelope is this times the scaled reference amplitude (room for stride-to-stride variation)."""
FROZEN = 0.02
"""Share of the drift cut-off left while a move that fits holds the cue outside the gait envelope
(0.08 Hz -> a 100 s time constant: a move is played as it is, a stuck offset still leaks away)."""


def cue_frame(p: Any, s: Any, u: Any, dt: float, y: Any) -> None:
    """One frame: parameters ``p``, state ``s`` (updated in place), saddle ``u``, step ``dt`` (s),
    cue written into ``y``. Plain Python on floats and sequences; numba compiles the same source."""
    dt = max(dt, 0.0)
    held = False
    for i in range(6):
        x = u[i]
        if math.isfinite(x):
            s[U + i] = x
        else:
            held = True
    if held:
        s[NAN_FRAMES] += 1.0
    if s[PRIMED] == 0.0:
        for i in range(6):
            s[R + i] = s[U + i]
        s[TP], s[TP + 1], s[TV], s[TV + 1] = s[U], s[U + 2], 0.0, 0.0
        s[PRIMED] = 1.0
    knee = p[KNEE]
    w, step_max, tilt_max = p[TILT_W], p[TILT_RATE] * dt, p[TILT_MAX]
    for j in range(2):
        acc = w * w * (s[U + 2 * j] - s[TP + j]) - 2.0 * w * s[TV + j]
        s[TV + j] += acc * dt
        s[TP + j] += s[TV + j] * dt
        want = p[TILT_K] * math.atan(acc / GRAVITY) / DEG
        if j == 1:
            want = -want
        want = min(max(want, -tilt_max), tilt_max)
        s[TA + j] += min(max(want - s[TA + j], -step_max), step_max)
    knee_passed = False
    for i in range(6):
        c = p[K + i] * (s[U + i] - s[R + i])
        room = p[WP + i] if c >= 0.0 else p[WN + i]
        a = abs(c)
        if a > knee * room:
            knee_passed = True
        if a > min(p[GATE + i], knee * room):
            s[H + i] = 0.0
        else:
            s[H + i] += dt
    if knee_passed:
        s[LATCH] = 1.0
    elif s[LATCH] > 0.0:
        settled = True
        for i in range(6):
            if s[H + i] <= p[HOLD]:
                settled = False
        if settled:
            s[LATCH] = 0.0
    m = s[M]
    if s[LATCH] > 0.0:
        if m < 1.0:
            m += (1.0 - m) * (1.0 - math.exp(-dt / p[ATTACK]))
    elif m > 0.0:
        m *= math.exp(-dt / p[RELEASE])
        if m < 1e-9:  # released: replay exactly
            m = 0.0
    s[M] = m
    if m > 0.5:
        s[ENGAGED] += 1.0
    compressed = False
    # the tracker's per-frame factor 1 - exp(-omega dt): omega is one of four (translation or
    # rotation, replaying or frozen); each is computed once, when an axis first needs it
    f_t = f_t_frozen = f_r = f_r_frozen = -1.0
    for i in range(6):
        x = s[U + i]
        replaying = s[H + i] > 0.0
        if i < 3:
            f = f_t if replaying else f_t_frozen
        else:
            f = f_r if replaying else f_r_frozen
        if f < 0.0:
            replay = p[OR] if replaying else FROZEN * p[OR]
            f = 1.0 - math.exp(-(replay + ((p[OW_T] if i < 3 else p[OW_R]) - replay) * m) * dt)
            if i < 3 and replaying:
                f_t = f
            elif i < 3:
                f_t_frozen = f
            elif replaying:
                f_r = f
            else:
                f_r_frozen = f
        s[R + i] += (x - s[R + i]) * f
        c = p[K + i] * (x - s[R + i])
        if i == 5:
            c += s[TA]
        elif i == 3:
            c += s[TA + 1]
        room = p[WP + i] if c >= 0.0 else p[WN + i]
        bend = knee * room
        a = abs(c)
        if a > bend:
            compressed = True
            a = bend + (room - bend) * math.tanh((a - bend) / (room - bend))
            c = a if c > 0.0 else -a
        y[i] = c
    if compressed:
        s[COMPRESSED] += 1.0


def blend(p: Any, target: Any, dt: float, tau: float) -> bool:
    """Move parameters ``p`` (in place) toward ``target``, time constant ``tau`` (s); True while moving."""
    f = 1.0 - math.exp(-dt / tau) if tau > 0.0 else 1.0
    moving = False
    for j in range(len(p)):
        d = target[j] - p[j]
        if abs(d) <= 1e-6 * (1.0 + abs(target[j])):
            p[j] = target[j]
        else:
            p[j] += d * f
            moving = True
    return moving


_cue_frame = jit(cue_frame)
_blend = jit(blend)


def _run(  # noqa: PLR0917 (a numba kernel: positional arrays)
    target: Any, p: Any, s: Any, u: Any, dt: Any, tau: float, out: Any
) -> None:
    moving = True
    for k in range(u.shape[0]):
        if moving:
            moving = _blend(p, target, dt[k], tau)
        _cue_frame(p, s, u[k], dt[k], out[k])


_run_compiled = jit(_run)


@dataclass(frozen=True)
class CueingModel:
    """Static cueing: the parameters and the room each axis has.

    ``ranges`` are ``(down, up)`` per pose axis: how far the axis reaches alone from
    home (m, deg; :func:`riderlive.platform.mechanism.ik.axis_ranges`); ``axes`` says which axes
    the mechanism moves (the others get no cue; tilt still goes to pitch and roll).
    """

    params: CueingParams = field(default_factory=CueingParams)
    ranges: tuple[tuple[float, float], ...] = ((0.1, 0.1),) * 3 + ((15.0, 15.0),) * 3
    axes: tuple[bool, ...] = (True,) * 6

    def __post_init__(self) -> None:
        if len(self.ranges) != 6 or len(self.axes) != 6:
            raise ValueError("ranges and axes need one entry per pose axis")
        vector = np.array(self._build_vector())
        vector.flags.writeable = False
        object.__setattr__(self, "_vector", vector)

    def _build_vector(self) -> list[float]:
        p = self.params
        v = [0.0] * N_PARAMS
        scales = self.scales
        for i in range(6):
            down, up = self.ranges[i]
            if scales[i] > 0.0:
                v[K + i] = scales[i] * p.intensity / 100.0
                v[WN + i], v[WP + i] = p.share * down, p.share * up
            else:
                v[WN + i] = v[WP + i] = 1.0
            v[GATE + i] = ENVELOPE_MARGIN * v[K + i] * p.reference_amplitude[i]
        v[OR], v[OW_T], v[OW_R] = (
            TWO_PI * f for f in (p.drift_cutoff_hz, p.washout_translation_hz, p.washout_rotation_hz)
        )
        v[KNEE], v[HOLD], v[ATTACK], v[RELEASE] = p.knee, p.washout_hold_s, p.washout_attack_s, p.washout_release_s
        v[TILT_W], v[TILT_RATE], v[TILT_MAX] = TWO_PI * p.tilt_cutoff_hz, p.tilt_rate_dps, p.tilt_max_deg
        v[TILT_K] = p.tilt_gain * p.intensity / 100.0
        return v

    @property
    def vector(self) -> FloatArray:
        """The parameters as the kernel reads them (offsets ``K`` ... ``TILT_K``; read-only)."""
        return self._vector  # type: ignore[attr-defined,no-any-return]

    @property
    def scales(self) -> tuple[float, ...]:
        """Replay scale per axis before the intensity (0 for an axis the mechanism lacks)."""
        p = self.params
        out = []
        for i in range(6):
            down, up = self.ranges[i]
            if not self.axes[i] or min(down, up) <= 0.0:
                out.append(0.0)
            elif p.scale is not None:
                out.append(p.scale[i])
            else:
                out.append(min(1.0, p.knee * p.share * min(down, up) / p.reference_amplitude[i]))
        return tuple(out)

    @property
    def room(self) -> tuple[tuple[float, float], ...]:
        """``(down, up)`` per axis the cue may use (``share`` of the ranges)."""
        return tuple((self.params.share * d, self.params.share * u) for d, u in self.ranges)

    def with_params(self, **changes: Any) -> CueingModel:
        """The same model with some parameters changed (validated); a state blends toward it."""
        params = CueingParams.model_validate({**self.params.model_dump(), **changes})
        return CueingModel(params, self.ranges, self.axes)

    def with_preset(self, name: str, **changes: Any) -> CueingModel:
        if name not in PRESETS:
            raise ValueError(f"unknown cueing preset {name!r}; choose one of {', '.join(PRESETS)}")
        return CueingModel(PRESETS[name], self.ranges, self.axes).with_params(**changes)


class CueingState(NamedTuple):
    """Everything that changes: the kernel's state vector and the blended parameters.

    Both arrays are never written after the state is made (:func:`step` copies)."""

    values: FloatArray
    params: FloatArray

    @property
    def washout(self) -> float:
        """0 (replay) .. 1 (washout engaged)."""
        return float(self.values[M])

    @property
    def tilt(self) -> tuple[float, float]:
        """Tilt coordination now: (pitch, roll), deg."""
        return float(self.values[TA]), float(self.values[TA + 1])

    @property
    def counters(self) -> dict[str, int]:
        """Frames with a held (non-finite) input; compressed toward the room; in washout."""
        v = self.values
        return {
            "nan_frames": int(v[NAN_FRAMES]),
            "compressed_frames": int(v[COMPRESSED]),
            "washout_frames": int(v[ENGAGED]),
        }


def initial(model: CueingModel) -> CueingState:
    """The state before the first frame (which becomes the centre: the first cue is zero)."""
    values = np.zeros(N_STATE)
    values[H : H + 6] = NEVER
    return CueingState(values, model.vector)


def step(model: CueingModel, state: CueingState, saddle: Any, dt: float) -> tuple[CueingState, list[float]]:
    """One frame: ``saddle`` (6 values, m and deg), ``dt`` seconds since the last frame.

    Runs the compiled :func:`cue_frame` (a few microseconds; the Python source without numba)."""
    p = state.params
    target = model.vector
    if p is not target:
        p = p.copy()
        if not _blend(p, target, dt, model.params.blend_s):
            p = target
    s = state.values.copy()
    y = np.empty(6)
    _cue_frame(p, s, np.asarray(saddle, dtype=np.float64), dt, y)
    return CueingState(s, p), y.tolist()


def run(
    model: CueingModel, state: CueingState, saddle: FloatArray, dt: float | FloatArray
) -> tuple[CueingState, FloatArray]:
    """Many frames at once (compiled): ``saddle`` is ``(N, 6)``; ``dt`` one step or one per frame."""
    u = np.ascontiguousarray(saddle, dtype=np.float64)
    if u.ndim != 2 or u.shape[1] != 6:
        raise ValueError(f"expected an (N, 6) saddle array, got {u.shape}")
    steps = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=np.float64), (u.shape[0],)))
    s = state.values.copy()
    p = state.params.copy()
    out = np.empty_like(u)
    _run_compiled(model.vector, p, s, u, steps, model.params.blend_s, out)
    return CueingState(s, model.vector if np.array_equal(p, model.vector) else p), out
