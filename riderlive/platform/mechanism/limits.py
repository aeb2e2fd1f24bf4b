"""The safety stage after IK: soft limits, speed and acceleration limits, and the eased moves.

**Follower** (Model / State / step). Each actuator's command follows its target under
three rules, checked every frame for any frame time ``dt``:

- the target is clipped into the soft limits ``[lower, upper]`` (counted);
- the commanded speed stays within ``max_speed`` and changes by at most
  ``max_accel * dt`` per frame (a spike filter: a one-frame jump of the target moves
  the actuator by at most ``max_accel dt^2``);
- the command never passes a soft limit: the speed toward a limit ``d`` away is at
  most ``brake(d) = sqrt((a dt)^2 + 2 a d) - a dt``, the speed from which braking at
  ``a`` stops within ``d`` for any later frame times (a braking run's distance is a
  right Riemann sum of a falling line, at most ``v^2 / 2a``; so the invariant
  ``v^2 / 2a <= d`` survives every frame).

A target that moves within the limits is followed exactly: the commanded speed is the
target's own (``(target - previous target) / dt``) plus a correction that closes the
remaining error with the same braking curve, so there is no lag and no overshoot of a
target that stops. A non-finite target holds the previous one (counted).

**Eased moves** for the lifecycle: :func:`eased` blends from where the actuators were
to a target with the quintic smoothstep (zero speed and acceleration at both ends),
for the soft start (toward the live target) and for parking (toward the park
pose). :func:`ease_seconds` is the shortest blend that respects the limits (peak
speed ``15/8 D/T``, peak acceleration ``10/sqrt(3) D/T^2`` for a move ``D``).

The per-frame kernel :func:`follow_frame` is plain Python, compiled by numba for the
tick and for a bake, like :mod:`riderlive.platform.mechanism.cueing`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import jit
from riderlive.platform.mechanism.geometry import Geometry

FloatArray = npt.NDArray[np.float64]
PEAK_SPEED = 15.0 / 8.0
"""The quintic smoothstep's largest slope (at its middle)."""
PEAK_ACCEL = 10.0 / math.sqrt(3.0)
"""The quintic smoothstep's largest |second derivative| (at 0.5 -+ sqrt(3)/6)."""

# Counter slots at the end of the state vector (after position, speed, last target per actuator).
SOFT_LIMIT, SPEED_LIMITED, ACCEL_LIMITED, BRAKING, NAN_TARGETS = 0, 1, 2, 3, 4
COUNTERS = ("soft_limit_frames", "speed_limited_frames", "accel_limited_frames", "braking_frames", "nan_targets")


def follow_frame(  # noqa: PLR0917 (a numba kernel: positional arrays)
    lower: Any, upper: Any, vmax: Any, amax: Any, s: Any, target: Any, dt: float, out: Any
) -> None:
    """One frame for ``n = len(lower)`` actuators; ``s`` = positions, speeds, last targets (n each),
    then the counters; updated in place; commands written into ``out``. Plain Python; numba compiles it."""
    n = len(lower)
    c = 3 * n
    if not dt > 0.0:
        for i in range(n):
            out[i] = s[i]
        return
    clipped = limited_v = limited_a = braked = held = False
    for i in range(n):
        t = target[i]
        if not math.isfinite(t):
            t = s[2 * n + i]
            held = True
        lo, hi, a = lower[i], upper[i], amax[i]
        if t < lo:
            t, clipped = lo, True
        elif t > hi:
            t, clipped = hi, True
        q, v, previous = s[i], s[n + i], s[2 * n + i]
        s[2 * n + i] = t
        error = previous - q
        ad = a * dt
        new = (t - previous) / dt
        if error != 0.0:
            correction = math.sqrt(ad * ad + 2.0 * a * abs(error)) - ad
            new += correction if error > 0.0 else -correction
        if new > vmax[i]:
            new, limited_v = vmax[i], True
        elif new < -vmax[i]:
            new, limited_v = -vmax[i], True
        # new > brake(d) exactly when the distance it needs to stop, new^2 / 2a + new dt, exceeds d
        if new > 0.0 and new * new / (2.0 * a) + new * dt > hi - q:
            new, braked = math.sqrt(ad * ad + 2.0 * a * max(hi - q, 0.0)) - ad, True
        elif new < 0.0 and new * new / (2.0 * a) - new * dt > q - lo:
            new, braked = ad - math.sqrt(ad * ad + 2.0 * a * max(q - lo, 0.0)), True
        if new > v + ad:
            new, limited_a = v + ad, True
        elif new < v - ad:
            new, limited_a = v - ad, True
        s[n + i] = new
        s[i] = q + new * dt
        out[i] = s[i]
    s[c + SOFT_LIMIT] += 1.0 if clipped else 0.0
    s[c + SPEED_LIMITED] += 1.0 if limited_v else 0.0
    s[c + ACCEL_LIMITED] += 1.0 if limited_a else 0.0
    s[c + BRAKING] += 1.0 if braked else 0.0
    s[c + NAN_TARGETS] += 1.0 if held else 0.0


_follow_frame = jit(follow_frame)


def _follow_run(  # noqa: PLR0917 (a numba kernel: positional arrays)
    lower: Any, upper: Any, vmax: Any, amax: Any, s: Any, targets: Any, dt: Any, out: Any
) -> None:
    for k in range(targets.shape[0]):
        _follow_frame(lower, upper, vmax, amax, s, targets[k], dt[k], out[k])


_follow_run_compiled = jit(_follow_run)


@dataclass(frozen=True, eq=False)
class SafetyModel:
    """Per-actuator soft limits, speeds and accelerations (units of the actuator positions)."""

    lower: FloatArray
    upper: FloatArray
    max_speed: FloatArray
    max_accel: FloatArray

    @classmethod
    def from_geometry(cls, g: Geometry) -> SafetyModel:
        arrays = [np.array(v, dtype=np.float64) for v in (g.lower, g.upper, g.max_speed, g.max_accel)]
        for a in arrays:
            a.flags.writeable = False
        return cls(*arrays)

    @property
    def legs(self) -> int:
        return int(self.lower.shape[0])


class SafetyState(NamedTuple):
    """Commanded positions and speeds, the last target, and the counters (never written after creation)."""

    values: FloatArray

    @classmethod
    def at(cls, positions: Sequence[float] | FloatArray) -> SafetyState:
        """At rest at ``positions`` (where the actuators are when the lifecycle arms)."""
        q = np.asarray(positions, dtype=np.float64)
        return cls(np.concatenate([q, np.zeros_like(q), q, np.zeros(len(COUNTERS))]))

    @property
    def legs(self) -> int:
        return int(self.values.shape[0] - len(COUNTERS)) // 3

    @property
    def positions(self) -> FloatArray:
        return self.values[: self.legs]

    @property
    def speeds(self) -> FloatArray:
        return self.values[self.legs : 2 * self.legs]

    @property
    def counters(self) -> dict[str, int]:
        tail = self.values[3 * self.legs :]
        return {name: int(tail[i]) for i, name in enumerate(COUNTERS)}


def step(
    model: SafetyModel, state: SafetyState, targets: Sequence[float] | FloatArray, dt: float
) -> tuple[SafetyState, FloatArray]:
    """One frame: commands for ``targets`` after ``dt`` seconds."""
    s = state.values.copy()
    out = np.empty(model.legs)
    q = np.asarray(targets, dtype=np.float64)
    _follow_frame(model.lower, model.upper, model.max_speed, model.max_accel, s, q, dt, out)
    return SafetyState(s), out


def run(
    model: SafetyModel, state: SafetyState, targets: FloatArray, dt: float | FloatArray
) -> tuple[SafetyState, FloatArray]:
    """Many frames (compiled): ``targets`` is ``(N, legs)``; ``dt`` one step or one per frame."""
    q = np.ascontiguousarray(targets, dtype=np.float64)
    if q.ndim != 2 or q.shape[1] != model.legs:
        raise ValueError(f"expected an (N, {model.legs}) target array, got {q.shape}")
    steps = np.ascontiguousarray(np.broadcast_to(np.asarray(dt, dtype=np.float64), (q.shape[0],)))
    s = state.values.copy()
    out = np.empty_like(q)
    _follow_run_compiled(model.lower, model.upper, model.max_speed, model.max_accel, s, q, steps, out)
    return SafetyState(s), out


def ease(u: float) -> float:
    """The quintic smoothstep: 0 -> 0, 1 -> 1, zero slope and curvature at both ends (clamped)."""
    u = min(max(u, 0.0), 1.0)
    return u * u * u * (10.0 + u * (6.0 * u - 15.0))


def eased(start: Sequence[float], goal: Sequence[float], elapsed: float, seconds: float) -> list[float]:
    """Where an eased move from ``start`` to ``goal`` over ``seconds`` is after ``elapsed``.

    The soft start calls it with the live target as ``goal`` each frame; parking with
    the park positions. ``seconds <= 0`` is the goal at once.
    """
    f = ease(elapsed / seconds) if seconds > 0.0 else 1.0
    return [a + f * (b - a) for a, b in zip(start, goal, strict=True)]


def ease_seconds(
    start: Sequence[float], goal: Sequence[float], max_speed: Sequence[float], max_accel: Sequence[float]
) -> float:
    """The shortest :func:`eased` move from ``start`` to ``goal`` within every actuator's limits (s)."""
    need = 0.0
    for a, b, v, acc in zip(start, goal, max_speed, max_accel, strict=True):
        d = abs(b - a)
        need = max(need, PEAK_SPEED * d / v, math.sqrt(PEAK_ACCEL * d / acc))
    return need


def eased_track(start: Sequence[float], goal: Sequence[float], seconds: float, rate: float) -> FloatArray:
    """The whole eased move sampled at ``rate`` Hz, both ends included: ``(N, legs)``."""
    frames = max(math.ceil(seconds * rate), 1) + 1
    f = np.array([ease(k / rate / seconds) if seconds > 0.0 else 1.0 for k in range(frames)])
    a, b = np.asarray(start, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    return a + f[:, None] * (b - a)
