"""Motion layers: what the horse's body and hooves do, as pure functions of time.

A layer's :meth:`pose` returns the 19 body channels of ``channels.HORSE`` (the four
hooves' ``tx ty tz``, ``rearPivot.*`` and ``backMid.rz``; ``root.*`` is the
generator's) for a time ``t`` (s) or an array of times. Frames (see ``docs/horse.md``):
hoof ``tx`` is forward (+) / back of the hoof's square-standing spot, ``ty`` its height
above the ground, ``tz`` its side offset (+ left); ``rearPivot.t*`` is the hips'
displacement from standing (m) and ``rearPivot.r*`` / ``backMid.rz`` the trunk's
rotation (deg: ``rz`` + nose up, ``rx`` + roll left, ``ry`` + yaw left).
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np
import numpy.typing as npt

from riderlive.horse.curves import TAU, Ops, Ramp, hermite, smoothstep, stride_noise, swing_bump
from riderlive.horse.gaits import GaitSpec, Harmonic, Leg

BODY_CHANNELS = 19
"""Channels a layer produces: everything of ``channels.HORSE`` but ``root.*``."""

PADDLE = 0.02
"""Outward arc of a hoof at mid-transfer (m)."""


class Layer(Protocol):
    """A source of body poses, valid for any time at or after its start."""

    def pose(self, t: Any, ops: Ops) -> list[Any]: ...


def _harmonic(h: Harmonic, phase: Any, ops: Ops) -> Any:
    if h.amplitude == 0.0:
        return 0.0
    return h.amplitude * ops.cos(TAU * h.k * (phase - h.at))


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

    def phase(self, t: Any, ops: Ops) -> tuple[Any, Any]:
        """``(stride phase, speed)`` at ``t``."""
        a, b = self.spec.frequency_slope
        v, _, x = self.speed.at(t, ops)
        return self.phase0 + a * (t - self.speed.t0) + b * x, v

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        spec = self.spec
        phase, v = self.phase(t, ops)
        a, b = spec.frequency_slope
        freq = a + b * v
        vary = self.variation
        out: list[Any] = []
        for leg in Leg:
            duty = spec.duty[leg]
            p = phase - spec.offset[leg]
            stride = ops.floor(p)
            p = p - stride
            reach = v * duty / (2.0 * freq)  # half the support sweep
            swing = 1.0 - duty
            s = (p - duty) / swing
            lift = spec.lift[0] if leg.is_front else spec.lift[1]
            if vary:
                lift = lift * (1.0 + vary * stride_noise(self.seed + 7919 * (leg + 1), p + stride, ops))
            bump = swing_bump(s)
            support = p < duty
            tx = ops.where(
                support,
                reach * (1.0 - 2.0 * p / duty),
                hermite(s, -reach, reach, -2.0 * reach * swing / duty, -2.0 * reach * swing / duty),
            )
            out.append(tx)
            out.append(ops.where(support, 0.0, lift * bump))
            out.append(ops.where(support, 0.0, leg.side * PADDLE * bump))
        gain = 1.0 + vary * stride_noise(self.seed, phase, ops) if vary else 1.0
        out.append(_harmonic(spec.surge, phase, ops))
        out.append(gain * _harmonic(spec.heave, phase, ops))
        out.append(_harmonic(spec.sway, phase, ops))
        out.append(_harmonic(spec.roll, phase, ops))
        out.append(_harmonic(spec.yaw, phase, ops))
        out.append(gain * _harmonic(spec.pitch, phase, ops))
        out.append(_harmonic(spec.bend, phase, ops))
        return out


@dataclass(frozen=True, slots=True)
class HaltLayer:
    """Standing square: every body channel at rest."""

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        return [0.0] * BODY_CHANNELS


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

    def pose(self, t: Any, ops: Ops) -> list[Any]:
        return self.spline.at(t - self.t0, ops)
