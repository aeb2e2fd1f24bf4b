"""A horse frame from the estimator's state: the gait's hooves at the estimated phase, the measured trunk.

:func:`horse_frame` is pure: the estimator's :class:`~riderlive.saddle.estimator.State`
and a time ``t`` (s, at or after the last sample; the tick's read time) give one frame
in ``channels.HORSE`` order, metres and degrees, that the rules can use:

- hooves and ``backMid.rz``: the procedural horse's leg cycle
  (:meth:`riderlive.horse.layers.GaitLayer.pose_at`) at the locked gait, the
  oscillator's phase and the speed of its stride frequency, scaled by the hooves'
  weight (eased in on a lock, out on a loss: standing square without a lock);
  a gait switch blends the old gait's legs into the new over ``model.ease``;
- ``rearPivot.*``: the measured saddle pose (smoothed, drift removed from the
  translations and the yaw, the slow level removed from pitch and roll) scaled by the
  pose's weight, moved back from the saddle point to the hips with the model's bend
  (:func:`riderlive.saddle.pose.trunk_from_saddle`);
- ``root.tx``: distance at the estimated speed; ``root.ty tz ry`` 0.

After ``model.hold`` s without a sample both weights ease to 0: the rider settles to
the standing horse's pose instead of freezing mid-stride.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE, HORSE_OPTIONAL
from riderlive.horse.curves import SCALAR as HORSE_SCALAR
from riderlive.horse.model import to_rig_sides
from riderlive.saddle.estimate import estimate
from riderlive.saddle.estimator import Model, State, step
from riderlive.saddle.pose import SCALAR, trunk_from_saddle
from riderlive.saddle.track import Track

FloatArray = npt.NDArray[np.float64]
BODY = 19
_OPTIONAL_AT_REST = (0.0,) * len(HORSE_OPTIONAL)
"""``channels.HORSE_OPTIONAL``: a saddle stream says nothing of the neck, head or ground: at rest, flat."""
HOOVES = 12
BEND = 18
DRIFTING = (True, True, True, False, True, False)
"""Channels whose baseline is the drift line (translations, yaw); pitch and roll keep their level."""


def _fade(model: Model, state: State, t: float) -> float:
    late = t - state.t - model.hold
    if late <= 0.0:
        return 1.0
    u = min(late / model.ease, 1.0)
    return 1.0 - u * u * (3.0 - 2.0 * u)


def _distance(model: Model, state: State, t: float) -> float:
    """Distance travelled (m): the oscillator's speed, slowing to a stop (smoothstep) once the stream stops."""
    track = state.tracking.track
    if track is None:
        return 0.0
    held = state.t + model.hold
    if t <= held:
        return track.distance(t)
    u = min((t - held) / model.ease, 1.0)
    coasted = u - u * u * u + 0.5 * u * u * u * u  # the integral of 1 - smoothstep over [0, u]
    return track.distance(held) + track.speed * model.ease * coasted


def _legs(model: Model, track: Track, t: float) -> list[float]:
    layer = model.templates[track.gait].layer
    return to_rig_sides(layer.pose_at(track.phase(t), track.speed, HORSE_SCALAR))[:BODY]  # a saddle knows no neck


def _body(model: Model, state: State, t: float, weight: float) -> list[float]:
    """The hooves' and bend's channels (the first 19 of HORSE but the trunk), weighted."""
    tr = state.tracking
    track = tr.track
    if weight <= 0.0 or track is None:
        return [0.0] * BODY
    body = _legs(model, track, t)
    blend = model.ease_time(track.frequency)
    if tr.previous is not None and t < tr.switched + blend:
        u = max((t - tr.switched) / blend, 0.0)
        u = u * u * (3.0 - 2.0 * u)
        old = _legs(model, tr.previous, t)
        body = [p + (q - p) * u for p, q in zip(old, body, strict=True)]
    return [v * weight for v in body]


def measured_saddle(model: Model, state: State, t: float, weight: float) -> list[float]:
    """The measured saddle pose at ``t``: smoothed, baseline removed, weighted (m, deg)."""
    tr = state.tracking
    drift, level = tr.drift, tr.level
    if weight <= 0.0 or drift is None or level is None:
        return [0.0] * 6
    out = []
    for i, drifting in enumerate(DRIFTING):
        value = state.smooth[i]
        if math.isnan(value):  # an axis never seen
            out.append(0.0)
            continue
        base = drift.at(i, t) if drifting else level[i]
        out.append((value - base) * weight)
    return out


def horse_frame(model: Model, state: State, t: float) -> list[float]:
    """One horse frame (``channels.HORSE`` order, metres and degrees) at ``t`` (s)."""
    fade = _fade(model, state, t)
    tr = state.tracking
    body = _body(model, state, t, tr.hooves.at(t) * fade)
    saddle = measured_saddle(model, state, t, tr.pose.at(t) * fade)
    trunk = trunk_from_saddle(saddle, body[BEND], model.point, SCALAR)
    distance = _distance(model, state, t)
    frame = [*body[:HOOVES], *trunk, body[BEND], distance, 0.0, 0.0, 0.0, *_OPTIONAL_AT_REST]
    assert len(frame) == len(HORSE)
    return frame


@dataclass(frozen=True)
class Rebuilt:
    """A whole saddle take run through the estimator: horse frames and the estimate per row."""

    horse: FloatArray  # (N, len(HORSE))
    lock: tuple[str, ...]
    gait: tuple[str | None, ...]
    stride_hz: FloatArray
    phase: FloatArray
    final: State


def rebuild(model: Model, times: FloatArray, saddle: FloatArray) -> Rebuilt:
    """Step the estimator through a take (``saddle`` (N, 6) in ``channels.SADDLE`` order) and
    rebuild a horse frame at every sample time: what a bake of a saddle file does."""
    state = State()
    frames = np.empty((len(times), len(HORSE)))
    locks: list[str] = []
    gaits: list[str | None] = []
    stride = np.zeros(len(times))
    phase = np.zeros(len(times))
    for i, (t, row) in enumerate(zip(times.tolist(), saddle.tolist(), strict=True)):
        state = step(model, state, t, row)
        frames[i] = horse_frame(model, state, t)
        found = estimate(state, t)
        locks.append(found.lock)
        gaits.append(found.gait)
        stride[i], phase[i] = found.stride_hz, found.phase
    return Rebuilt(frames, tuple(locks), tuple(gaits), stride, phase, state)
