"""Motion layers: what the horse's body and hooves do, as pure functions of time.

A layer's :meth:`pose` returns the 19 body channels of ``channels.HORSE`` (the four
hooves' ``tx ty tz``, ``rearPivot.*`` and ``backMid.rz``; ``root.*`` is the
generator's), then the neck and head (``horseNeck.rz``, ``horseNeck.ry``,
``horseHead.rz``), for a time ``t`` (s) or an array of times. Frames (``docs/horse.md``):
hoof ``tx`` is forward (+) / back of the hoof's square-standing spot, ``ty`` its height
above the ground, ``tz`` its side offset (+ left here; ``model.frame`` turns it into
the rig's + right); ``rearPivot.t*`` is the hips'
displacement from standing (m) and ``rearPivot.r*`` / ``backMid.rz`` the trunk's
rotation (deg: ``rz`` + nose up, ``rx`` + roll left here (+ right in the rig), ``ry`` + yaw
left).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from riderlive.horse.curves import TAU, Ops, Ramp, smoothstep, stride_noise
from riderlive.horse.gaits import GaitSpec, Leg

BODY_CHANNELS = 19
"""The trunk and hooves: ``channels.HORSE`` up to ``root.*``."""
LAYER_CHANNELS = BODY_CHANNELS + 3
"""Channels a layer produces: the body, then the neck and head (``channels.HORSE_NECK_HEAD``)."""

PADDLE = 0.02
"""Outward arc of a hoof at mid-transfer (m)."""


class Layer(Protocol):
    """A source of body poses, valid for any time at or after its start."""

    def pose(self, t: Any, ops: Ops) -> list[Any]: ...


@dataclass(frozen=True, slots=True)
class GaitLayer:
    """A steady gait whose stride phase integrates the stride frequency of its speed ramp.

    ``phase`` counts strides: ``phase0`` at ``speed.t0``, then
    ``d phase / dt = a + b * v(t)`` (the gait's linear frequency law), in closed form.
    In support a hoof moves back at the speed (no slip); in transfer it follows a
    cubic Hermite that leaves and meets the support at the support's velocity, lifted
    by a C1 bump: lift-off, transfer, placement in Girard's terms.
    """

    spec: GaitSpec
    speed: Ramp
    phase0: float = 0.0
    variation: float = 0.0
    seed: int = 0
    legs: tuple[tuple[float, float, float, float, int], ...] = field(init=False, repr=False, compare=False)
    trunk: tuple[tuple[float, float, float, bool], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        spec = self.spec
        legs = tuple(
            (spec.offset[leg], spec.duty[leg], spec.lift[0 if leg.is_front else 1], leg.side * PADDLE, 7919 * (leg + 1))
            for leg in Leg
        )
        order = (
            *(spec.surge, spec.heave, spec.sway, spec.roll, spec.yaw, spec.pitch, spec.bend),
            *(spec.neck, spec.neck_side, spec.head),
        )
        varied = (False, True, False, False, False, True, False, False, False, False)
        trunk = tuple((h.amplitude, TAU * h.k, h.at, v) for h, v in zip(order, varied, strict=True))
        object.__setattr__(self, "legs", legs)
        object.__setattr__(self, "trunk", trunk)

    def phase(self, t: Any, ops: Ops) -> tuple[Any, Any]:
        """``(stride phase, speed)`` at ``t``."""
        a, b = self.spec.frequency_slope
        v, _, x = self.speed.at(t, ops)
        return self.phase0 + a * (t - self.speed.t0) + b * x, v

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        phase, v = self.phase(t, ops)
        return self.pose_at(phase, v, ops)

    def pose_at(self, phase: Any, v: Any, ops: Ops) -> list[Any]:
        """The body channels at stride ``phase`` and ground speed ``v`` (m/s): the leg cycle and trunk."""
        a, b = self.spec.frequency_slope
        half_step = v / (2.0 * (a + b * v))  # reach = duty * half_step: half the support sweep
        vary, where, floor, scalar = self.variation, ops.where, ops.floor, not ops.is_array
        out: list[Any] = []
        for offset, duty, peak, paddle, salt in self.legs:
            p = phase - offset
            stride = floor(p)
            p = p - stride
            reach = duty * half_step
            on_ground = reach * (1.0 - 2.0 * p / duty)  # support: back at the ground's speed
            if scalar and p < duty:  # the live path computes only the branch it needs
                out += (on_ground, 0.0, 0.0)
                continue
            # transfer: Hermite -reach -> reach, leaving and meeting the support's velocity
            # (slope -2 reach swing / duty per unit s), lifted by swing_bump(s)
            swing = 1.0 - duty
            s = (p - duty) / swing
            s2 = s * s
            s3 = s2 * s
            slope = -2.0 * reach * swing / duty
            flight = reach * (6.0 * s2 - 4.0 * s3 - 1.0) + slope * (2.0 * s3 - 3.0 * s2 + s)
            q = s - s2
            bump = 16.0 * q * q
            lift = peak * (1.0 + vary * stride_noise(self.seed + salt, p + stride, ops)) if vary else peak
            if scalar:
                out += (flight, lift * bump, paddle * bump)
            else:
                support = p < duty
                out += (
                    where(support, on_ground, flight),
                    where(support, 0.0, lift * bump),
                    where(support, 0.0, paddle * bump),
                )
        gain = 1.0 + vary * stride_noise(self.seed, phase, ops) if vary else 1.0
        cos = ops.cos
        for amplitude, w, at, varied in self.trunk:
            if amplitude == 0.0:
                out.append(0.0)
            else:
                value = amplitude * cos(w * (phase - at))
                out.append(gain * value if varied else value)
        return out


@dataclass(frozen=True, slots=True)
class HaltLayer:
    """Standing square: every body channel at rest."""

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        return [0.0] * LAYER_CHANNELS


@dataclass(frozen=True, slots=True)
class BlendLayer:
    """``before`` eased into ``after`` over ``[t0, t0 + duration]`` (smoothstep weight: C1)."""

    before: Layer
    after: Layer
    t0: float
    duration: float

    def weight(self, t: Any, ops: Ops) -> Any:
        return smoothstep(ops.clip01((t - self.t0) / self.duration))

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        w = self.weight(t, ops)
        if not ops.is_array and w >= 1.0:
            return self.after.pose(t, ops)
        old = self.before.pose(t, ops)
        new = self.after.pose(t, ops)
        return [p + (q - p) * w for p, q in zip(old, new, strict=True)]


FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class Spline:
    """All body channels as one piecewise cubic on shared knots (seconds from the start).

    ``coef[i, c]`` holds the Horner coefficients of channel ``c`` on segment ``i`` in
    ``u = (tau - knots[i]) / (knots[i+1] - knots[i])``. Before the first knot and after
    the last the end values hold.
    """

    knots: FloatArray
    coef: FloatArray  # (segments, channels, 4)

    def __post_init__(self) -> None:
        object.__setattr__(self, "_knot_list", self.knots.tolist())
        object.__setattr__(self, "_rows", [[tuple(c) for c in seg] for seg in self.coef.tolist()])

    @property
    def duration(self) -> float:
        return float(self.knots[-1])

    def at(self, tau: Any, ops: Ops) -> list[Any]:
        knots = self.knots
        if not ops.is_array:
            kl: list[float] = self._knot_list  # type: ignore[attr-defined]
            i = min(max(bisect.bisect_right(kl, tau) - 1, 0), len(kl) - 2)
            u = (tau - kl[i]) / (kl[i + 1] - kl[i])
            u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
            return [c0 + u * (c1 + u * (c2 + u * c3)) for c0, c1, c2, c3 in self._rows[i]]  # type: ignore[attr-defined]
        idx = np.clip(np.searchsorted(knots, tau, side="right") - 1, 0, len(knots) - 2)
        u = np.clip((tau - knots[idx]) / (knots[idx + 1] - knots[idx]), 0.0, 1.0)
        c = self.coef[idx]  # (N, channels, 4)
        uu = u[:, None]
        vals = c[..., 0] + uu * (c[..., 1] + uu * (c[..., 2] + uu * c[..., 3]))
        return list(vals.T)

    @staticmethod
    def from_hermite(knots: FloatArray, values: FloatArray, slopes: FloatArray) -> Spline:
        """From values and slopes (per second) at the knots: ``values`` is (K, channels)."""
        h = np.diff(knots)[:, None]
        p0, p1 = values[:-1], values[1:]
        m0, m1 = slopes[:-1] * h, slopes[1:] * h
        coef = np.stack([p0, m0, 3 * (p1 - p0) - 2 * m0 - m1, 2 * (p0 - p1) + m0 + m1], axis=-1)
        return Spline(np.asarray(knots, dtype=np.float64), coef)


@dataclass(frozen=True, slots=True)
class MoveLayer:
    """A movement clip (:mod:`riderlive.horse.moves`) started at ``t0``."""

    spline: Spline
    t0: float
    head: Spline | None = None
    """The neck and head; None: at rest."""

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        body = self.spline.at(t - self.t0, ops)
        return body + (self.head.at(t - self.t0, ops) if self.head is not None else [0.0, 0.0, 0.0])
