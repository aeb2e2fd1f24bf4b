"""The generator's Model / State / step: commands in, frames out, no clocks inside.

:class:`Model` holds what never changes during a take (variation, seed, blend
times); :class:`State` is immutable and carries the current motion layer, the root's
speed ramp and the pending timed events (a movement's end, a blend's end, a script's
next segment). :func:`step` applies every event due by ``t`` at its own time, then
evaluates the frame, so the output never depends on the sampling rate.
:func:`evaluate` does the same for a whole array of times with NumPy (the batch path).
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE, HORSE_INDEX, HORSE_NAMES
from riderlive.horse.curves import ARRAY, SCALAR, Ops, Ramp
from riderlive.horse.gaits import GAIT_TABLE, Gait
from riderlive.horse.layers import BODY_CHANNELS, BlendLayer, GaitLayer, HaltLayer, Layer, MoveLayer
from riderlive.horse.moves import MOVE_TABLE, Move
from riderlive.horse.terrain import Terrain

FloatArray = npt.NDArray[np.float64]
CHUNK = 8192
"""Frames per piece of the batch path."""
SETTLE_RATIO = 4.74
"""A critically damped ramp is 95 % there after ``4.74 / omega`` seconds."""


@dataclass(frozen=True, slots=True)
class SetGait:
    """Change to ``gait`` (speed in m/s, default the gait's; ``ramp`` s to reach it; ``accel``
    m/s^2: the ground speed's rate of change stays within it, :func:`bounded_omega`)."""

    gait: Gait
    speed: float | None = None
    ramp: float | None = None
    accel: float | None = None


@dataclass(frozen=True, slots=True)
class Perform:
    """Start a movement from whatever the horse is doing."""

    move: Move


@dataclass(frozen=True, slots=True)
class _Resume:
    started: float  # the movement's start time: a later command cancels it


@dataclass(frozen=True, slots=True)
class _Settle:
    """A blend's end: drop every finished blend from the layer chain."""


Command = SetGait | Perform | _Resume | _Settle
Event = tuple[float, int, Command]


@dataclass(frozen=True)
class Model:
    """Static parameters: stride-to-stride variation (fraction, 0 = off) and its seed, blend times (s),
    the ground (``terrain``; None: flat and level)."""

    variation: float = 0.0
    seed: int = 0
    move_blend: float = 0.3
    resume_blend: float = 0.4
    terrain: Terrain | None = None

    def __post_init__(self) -> None:
        if not (0.0 <= self.variation <= 0.3):
            raise ValueError(f"variation must be within 0-0.3, got {self.variation!r}")


@dataclass(frozen=True)
class State:
    """Everything that changes: motion, root ramp, pending events.

    ``t`` is the time (s) of the last command or event applied: no later command may
    precede it. A tick without events returns the same object, so a frame costs no copy.
    """

    t: float
    layer: Layer
    ramp: Ramp
    x0: float  # root distance (m) at ramp.t0
    gait: Gait  # the gait in effect, or the one a jump resumes
    gait_speed: float
    move: Move | None = None
    move_started: float | None = None
    events: tuple[Event, ...] = field(default=())
    seq: int = 0


def target_speed(gait: Gait, speed: float | None) -> float:
    """The ground speed (m/s) ``gait`` runs at: its default when ``speed`` is None, else
    ``speed`` checked against the gait's range (ValueError naming the range)."""
    if gait is Gait.HALT:
        if speed not in (None, 0.0):
            raise ValueError("halt has speed 0")
        return 0.0
    spec = GAIT_TABLE[gait]
    return spec.default_speed if speed is None else spec.check_speed(speed)


def initial(model: Model, gait: Gait, speed: float | None = None, t: float = 0.0) -> State:
    """The horse already moving steadily in ``gait`` at time ``t``."""
    v = target_speed(gait, speed)
    ramp = Ramp(t, v, 0.0, v, 3.0)
    layer: Layer = HaltLayer() if gait is Gait.HALT else _gait_layer(model, gait, ramp)
    return State(t=t, layer=layer, ramp=ramp, x0=0.0, gait=gait, gait_speed=v)


def _gait_layer(model: Model, gait: Gait, ramp: Ramp, phase0: float = 0.0) -> GaitLayer:
    return GaitLayer(GAIT_TABLE[gait], ramp, phase0, model.variation, model.seed)


def _schedule(state: State, at: float, command: Command) -> State:
    events = list(state.events)
    heapq.heappush(events, (at, state.seq, command))
    return replace(state, events=tuple(events), seq=state.seq + 1)


def peak_acceleration(v0: float, a0: float, target: float, omega: float) -> float:
    """The largest ``|dv/dt|`` (m/s^2) of a :class:`Ramp` from speed ``v0`` and acceleration ``a0``
    toward ``target`` at ``omega``: ``a(tau) = (a0 - omega c2 tau) exp(-omega tau)``,
    ``c2 = a0 + omega (v0 - target)``, extreme at ``tau* = (a0 + c2) / (omega c2)``."""
    c2 = a0 + omega * (v0 - target)
    peak = abs(a0)
    if c2 != 0.0:
        tau = (a0 + c2) / (omega * c2)
        if tau > 0.0:
            peak = max(peak, abs(c2) * math.exp(-omega * tau))
    return peak


def bounded_omega(ramp: Ramp, at: float, target: float, omega: float, accel: float) -> float:
    """The largest rate <= ``omega`` whose ramp from ``ramp``'s state at ``at`` toward ``target``
    keeps ``|dv/dt|`` within ``accel`` (m/s^2): the acceleration already under way when the
    command starts is kept (speed stays C1): beyond ``accel`` (after a movement's own ramp) it
    is the bound until the ramp has let it go."""
    v0, a0, _ = ramp.at(at, SCALAR)
    v0, a0 = float(v0), float(a0)
    bound = max(accel, abs(a0))
    if peak_acceleration(v0, a0, target, omega) <= bound:
        return omega
    lo, hi = 1e-6, omega  # the peak grows with omega: bisect for the fastest ramp within the bound
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if peak_acceleration(v0, a0, target, mid) <= bound else (lo, mid)
    return lo


def _retarget(state: State, at: float, target: float, omega: float) -> State:
    _, _, x = state.ramp.at(at, SCALAR)
    return replace(state, ramp=state.ramp.retarget(at, target, omega), x0=state.x0 + float(x))


MAX_BLENDS = 6
"""Fading layers kept at once; a burst of more commands drops the oldest (the only non-C1 case)."""


def _prune(layer: Layer, at: float, keep: int = MAX_BLENDS) -> Layer:
    """``layer`` without the blends finished by ``at`` and with at most ``keep`` blends."""
    if not isinstance(layer, BlendLayer):
        return layer
    if at >= layer.t0 + layer.duration or keep <= 0:
        return _prune(layer.after, at, keep)
    return replace(layer, before=_prune(layer.before, at, keep - 1))


def _blend_to(state: State, at: float, layer: Layer, duration: float) -> State:
    blend = BlendLayer(_prune(state.layer, at, MAX_BLENDS - 1), layer, at, duration)
    return _schedule(replace(state, layer=blend), at + duration, _Settle())


def apply(model: Model, state: State, at: float, command: Command) -> State:
    """The state after ``command`` takes effect at time ``at`` (s)."""
    if isinstance(command, _Settle):
        return replace(state, layer=_prune(state.layer, at))
    if isinstance(command, _Resume):
        if state.move_started != command.started or state.move is None:
            return state
        spec = MOVE_TABLE[state.move]
        gait = state.gait if spec.resumes_gait else Gait.HALT
        speed = state.gait_speed if spec.resumes_gait else None
        return _set_gait(
            model, replace(state, move=None, move_started=None), at, SetGait(gait, speed), blend=model.resume_blend
        )
    if isinstance(command, Perform):
        spec = MOVE_TABLE[command.move]
        state = _retarget(state, at, spec.speed, spec.omega)
        state = _blend_to(state, at, MoveLayer(spec.spline, at, spec.head_spline), model.move_blend)
        state = replace(state, move=command.move, move_started=at)
        return _schedule(state, at + spec.duration - model.resume_blend, _Resume(at))
    return _set_gait(model, replace(state, move=None, move_started=None), at, command)


def _set_gait(
    model: Model,
    state: State,
    at: float,
    cmd: SetGait,
    *,
    blend: float | None = None,
) -> State:
    gait, speed, ramp = cmd.gait, cmd.speed, cmd.ramp
    target = target_speed(gait, speed)
    same = gait is state.gait and isinstance(state.layer, GaitLayer)
    omega = SETTLE_RATIO / ramp if ramp else (2.0 if same else 3.0)
    if cmd.accel is not None:
        omega = bounded_omega(state.ramp, at, target, omega, cmd.accel)
    state = replace(_retarget(state, at, target, omega), gait=gait, gait_speed=target)
    if gait is Gait.HALT:
        return _blend_to(state, at, HaltLayer(), blend or 0.8)
    if same:  # a speed change within the gait: same layer, phase carried over
        return replace(state, layer=_retarget_gait(model, state.layer, at, target, omega))
    incoming = state.layer.after if isinstance(state.layer, BlendLayer) else None
    if isinstance(incoming, GaitLayer) and incoming.spec.gait is gait and isinstance(state.layer, BlendLayer):
        # already blending into this gait: only its speed changes (a slider stays cheap)
        return replace(state, layer=replace(state.layer, after=_retarget_gait(model, incoming, at, target, omega)))
    spec = GAIT_TABLE[gait]
    v_now = min(max(state.ramp.v0, spec.speed[0]), spec.speed[1])
    legs = _gait_layer(model, gait, Ramp(at, v_now, 0.0, target, omega))
    duration = blend or min(max(1.0 / spec.frequency_at(target), 0.4), 1.2)
    return _blend_to(state, at, legs, duration)


def _retarget_gait(model: Model, layer: Layer, at: float, target: float, omega: float) -> GaitLayer:
    """The same gait layer heading for a new speed from ``at``: phase and speed stay C1."""
    assert isinstance(layer, GaitLayer)
    phase, _ = layer.phase(at, SCALAR)
    own = layer.speed.retarget(at, target, omega)  # the legs' own speed
    return _gait_layer(model, layer.spec.gait, own, float(phase))


def command(model: Model, state: State, cmd: SetGait | Perform, at: float | None = None) -> State:
    """Apply a user command at ``at`` (s; default the state's time), after any events due by then."""
    if at is not None:
        state = advance(model, state, at)
    when = state.t if at is None else at
    return replace(apply(model, state, when, cmd), t=when)


def unschedule(state: State) -> State:
    """Drop every queued user command (a script's remaining segments); internal events stay."""
    kept = [e for e in state.events if not isinstance(e[2], SetGait | Perform)]
    heapq.heapify(kept)
    return replace(state, events=tuple(kept))


def schedule(state: State, at: float, cmd: SetGait | Perform) -> State:
    """Queue a user command for time ``at`` (a shot script's next segment)."""
    return _schedule(state, at, cmd)


def advance(model: Model, state: State, t: float) -> State:
    """Apply every event due at or before ``t``, each at its own time (``t`` >= ``state.t``)."""
    if not math.isfinite(t):
        raise ValueError(f"time must be finite, got {t!r}")
    if t < state.t:
        raise ValueError(f"time went backwards: {t!r} after {state.t!r}")
    while state.events and state.events[0][0] <= t:
        events = list(state.events)
        at, _, cmd = heapq.heappop(events)
        state = apply(model, replace(state, events=tuple(events), t=max(state.t, at)), at, cmd)
    return state


_TO_RIG_SIDE = tuple(
    -1.0 if name.endswith(".tz") or name == "rearPivot.rx" else 1.0 for name in HORSE_NAMES[:BODY_CHANNELS]
)
"""The layers count sideways + to the horse's left; the rig is right-handed (+Z right)."""


def to_rig_sides(pose: list[Any]) -> list[Any]:
    """A layer's body channels (sideways + left) in the rig's convention (+Z right); the neck and head pass."""
    body = [v if sign > 0.0 else -v for v, sign in zip(pose[:BODY_CHANNELS], _TO_RIG_SIDE, strict=True)]
    return body + pose[BODY_CHANNELS:]


_PITCH = HORSE_INDEX["rearPivot.rz"]


def frame(state: State, t: Any, ops: Ops, terrain: Terrain | None = None) -> list[Any]:
    """All channels of ``channels.HORSE`` at ``t`` (float or array) from ``state``.

    Rig convention (``channels``): right-handed, +X forward, +Y up, +Z to the horse's
    right, so ``tz`` is + right and ``rearPivot.rx`` is + when the horse rolls right.
    On ``terrain`` (``riderlive.horse.terrain``) the distance travelled is along the
    ground: ``root.tx`` / ``root.ty`` are its world position, ``ground.rz`` the trunk's
    ground pitch, added to ``rearPivot.rz`` (the trunk's world pitch), ``ground.ty`` =
    ``root.ty``; the hooves and the rest of the trunk stay relative to the local ground.
    """
    _, _, x = state.ramp.at(t, ops)
    pose = to_rig_sides(state.layer.pose(t, ops))
    if terrain is None:
        return [*pose[:BODY_CHANNELS], state.x0 + x, 0.0, 0.0, 0.0, *pose[BODY_CHANNELS:], 0.0, 0.0]
    gx, gy, pitch = terrain.place(state.x0 + x, ops)
    pose[_PITCH] = pose[_PITCH] + pitch
    return [*pose[:BODY_CHANNELS], gx, gy, 0.0, 0.0, *pose[BODY_CHANNELS:], pitch, gy]


def step(model: Model, state: State, t: float) -> tuple[State, list[float]]:
    """One live tick: the state at ``t`` and its frame (metres, degrees)."""
    state = advance(model, state, t)
    return state, frame(state, t, SCALAR, model.terrain)


def evaluate(model: Model, state: State, times: FloatArray) -> tuple[State, FloatArray]:
    """Frames for sorted ``times`` at once, shape (N, len(HORSE)); same numbers as :func:`step`."""
    times = np.asarray(times, dtype=np.float64)
    out = np.empty((len(times), len(HORSE)), dtype=np.float64)
    start = 0
    while start < len(times):
        state = advance(model, state, float(times[start]))
        stop = len(times)
        if state.events:
            stop = int(np.searchsorted(times, state.events[0][0], side="left"))
            stop = max(stop, start + 1)
        for lo in range(start, stop, CHUNK):  # cache-sized pieces: temporaries stay in cache
            hi = min(lo + CHUNK, stop)
            for column, values in enumerate(frame(state, times[lo:hi], ARRAY, model.terrain)):
                out[lo:hi, column] = values
        start = stop
    return state, out
