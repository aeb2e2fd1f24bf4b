"""The ground under the procedural horse: a slope, or a profile of slope against distance.

Thesis section 10: the rules assumed "a flat ground plane"; this is the uneven ground.
The ground is a curve in the vertical plane of the horse's straight path. Its slope
``theta(s)`` (degrees, + rising ahead) is given against the distance ``s`` travelled
along the ground (m, what the horse's speed integrates): a constant ``slope``, or a
``profile`` of ``[distance, slope]`` knots, linear between knots and constant beyond
them. So the slope is continuous, and the world position has a closed form
(:meth:`Terrain.place`): ``x(s) = integral cos theta ds`` forward, ``y(s) = integral
sin theta ds`` up, exact at any distance on both the scalar and the array path.

The trunk's pitch follows the line through the ground under the hind and the fore
hooves, :data:`HOOF_BASE` apart: the pitch of the chord from ``s - B/2`` to ``s + B/2``.
On a constant slope that is the slope; where the slope changes it is a moving mean of
it over the body's length, so the pitch has continuous velocity (C1) even at a knot.

A running horse can change ground (the live service's ``PUT /api/source``): :func:`join`
keeps the old ground under and behind the horse and eases the slope into the new one
over :data:`TRANSITION` metres ahead, so its position and pitch carry on (C1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Self

import numpy as np
import numpy.typing as npt
import pydantic

from riderlive.configfile import StrictModel
from riderlive.horse.curves import ARRAY, SCALAR, Ops

FloatArray = npt.NDArray[np.float64]

MAX_SLOPE = 30.0
"""Steepest ground a script may give (deg): steeper than a ridden horse climbs or descends."""
MAX_DISTANCE = 1e5
"""Farthest profile knot (m): ``channels`` ranges ``root.t*`` within 100 km."""
HOOF_BASE = 1.25
"""Distance (m) from the hind to the fore hooves' ground contact of the standing horse: the
default skeleton's (``riderlive.skeleton.horse``, fore hooves at +0.60, hind at -0.65)."""
TRANSITION = 5.0
"""Distance (m) over which the slope goes linearly from the old ground's to the new ground's
when the ground changes under a running horse (:func:`join`): 0.3 s at a gallop, 3 s at a walk."""


class TerrainConfig(StrictModel):
    """The ``[terrain]`` table of a shot script: exactly one of ``slope`` or ``profile``.

    ``slope``: degrees, + uphill; ``profile``: ``[[distance m, slope deg], ...]`` with
    distances strictly increasing from 0.
    """

    slope: float | None = pydantic.Field(default=None, ge=-MAX_SLOPE, le=MAX_SLOPE)
    profile: list[tuple[float, float]] | None = pydantic.Field(default=None, min_length=1, max_length=10_000)

    @pydantic.field_validator("profile")
    @classmethod
    def _knots(cls, value: list[tuple[float, float]] | None) -> list[tuple[float, float]] | None:
        if value is None:
            return None
        last = -math.inf
        for i, (distance, slope) in enumerate(value):
            if not (0.0 <= distance <= MAX_DISTANCE):
                raise ValueError(f"knot {i}: distance must be within 0-{MAX_DISTANCE:g} m, got {distance!r}")
            if not distance > last:
                raise ValueError(f"knot {i}: distances must increase strictly, got {distance!r} after {last!r}")
            if not (-MAX_SLOPE <= slope <= MAX_SLOPE):
                raise ValueError(f"knot {i}: slope must be within -{MAX_SLOPE:g}-{MAX_SLOPE:g} deg, got {slope!r}")
            last = distance
        return value

    @pydantic.model_validator(mode="after")
    def _one_kind(self) -> Self:
        if (self.slope is None) == (self.profile is None):
            raise ValueError("terrain has exactly one of 'slope' (deg) or 'profile' ([[distance m, slope deg], ...])")
        return self

    def terrain(self) -> Terrain | None:
        """The ground (None when it is flat and level: the horse of before, exactly)."""
        knots = np.array([(0.0, self.slope)] if self.slope is not None else self.profile or (), dtype=np.float64)
        if not knots[:, 1].any():
            return None
        return Terrain(tuple(knots[:, 0].tolist()), tuple(knots[:, 1].tolist()))

    def describe(self, start: float = 0.0) -> dict[str, Any]:
        """A short JSON-able account of this ground (a profile by its knot count and length, not
        its knots), with ``from``: the horse's distance (m) where its distance 0 lies."""
        if self.slope is not None:
            return {"kind": "slope", "slope": self.slope, "from": start}
        profile = self.profile or [(0.0, 0.0)]
        return {"kind": "profile", "knots": len(profile), "length": profile[-1][0], "from": start}


def _sinc(u: Any, ops: Ops) -> Any:
    """``sin(u) / u`` (1 at 0), for ``|u|`` up to a few radians."""
    if ops.is_array:
        return np.sinc(u / math.pi)
    return math.sin(u) / u if u != 0.0 else 1.0


@dataclass(frozen=True)
class Terrain:
    """The ground: slope knots ``distances`` (m, increasing) and ``slopes`` (deg); ``origin``
    is the world ``(x, y)`` (m) of the first knot."""

    distances: tuple[float, ...]
    slopes: tuple[float, ...]
    origin: tuple[float, float] = (0.0, 0.0)
    _s: FloatArray = field(init=False, repr=False)
    _theta: FloatArray = field(init=False, repr=False)
    _rate: FloatArray = field(init=False, repr=False)
    _x: FloatArray = field(init=False, repr=False)
    _y: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        s = np.fromiter(self.distances, np.float64, len(self.distances))
        theta = np.radians(np.fromiter(self.slopes, np.float64, len(self.slopes)))
        rate = np.zeros_like(s)  # rad per m; 0 beyond the last knot
        rate[:-1] = np.diff(theta) / np.diff(s)
        # The world position at each knot, by the closed form: sums in knot order from the origin
        # (vectorised: a 10 000-knot ground is built within a tick when it changes live).
        d = np.diff(s)
        half = 0.5 * rate[:-1] * d
        mean = theta[:-1] + half
        step = d * _sinc(half, ARRAY)
        x = np.cumsum(np.concatenate(([self.origin[0]], step * np.cos(mean))))
        y = np.cumsum(np.concatenate(([self.origin[1]], step * np.sin(mean))))
        for name, value in (("_s", s), ("_theta", theta), ("_rate", rate), ("_x", x), ("_y", y)):
            object.__setattr__(self, name, value)

    def position(self, s: Any, ops: Ops) -> tuple[Any, Any]:
        """World ``(x forward, y up)`` (m) of the ground at distance ``s`` along it (float or array)."""
        knots = self._s
        if ops.is_array:
            k = np.clip(np.searchsorted(knots, s, side="right") - 1, 0, len(knots) - 1)
        else:
            k = min(max(int(np.searchsorted(knots, s, side="right")) - 1, 0), len(knots) - 1)
        d = s - knots[k]
        rate = ops.where(d > 0.0, self._rate[k], 0.0)  # before the first knot: its slope, constant
        half = 0.5 * rate * d
        mean = self._theta[k] + half
        sinc = _sinc(half, ops)
        if ops.is_array:
            return self._x[k] + d * np.cos(mean) * sinc, self._y[k] + d * np.sin(mean) * sinc
        return float(self._x[k] + d * math.cos(mean) * sinc), float(self._y[k] + d * math.sin(mean) * sinc)

    def place(self, s: Any, ops: Ops) -> tuple[Any, Any, Any]:
        """``(x, y, pitch)`` at distance ``s``: world position (m) and the trunk's ground pitch
        (deg, + nose up): the chord through the ground under the hind and the fore hooves."""
        x, y = self.position(s, ops)
        x0, y0 = self.position(s - 0.5 * HOOF_BASE, ops)
        x1, y1 = self.position(s + 0.5 * HOOF_BASE, ops)
        if ops.is_array:
            return x, y, np.degrees(np.arctan2(y1 - y0, x1 - x0))
        return x, y, math.degrees(math.atan2(y1 - y0, x1 - x0))

    def slope_at(self, s: float) -> float:
        """The slope (deg) at distance ``s``: linear between knots, constant beyond them."""
        return float(np.interp(s, self._s, self.slopes))


FLAT = Terrain((0.0,), (0.0,))
"""Flat and level ground as a :class:`Terrain` (a horse on it runs as on ``None``)."""


def join(old: Terrain | None, new: Terrain | None, at: float) -> tuple[Terrain | None, float]:
    """The ground after changing from ``old`` to ``new`` under a horse at distance ``at`` (m),
    and where the new ground's distance 0 lies (m, in the horse's distance).

    The old ground stays up to the fore hooves (``at + HOOF_BASE / 2``: the position and the
    pitch at ``at`` are unchanged), then the slope goes linearly to the new ground's first
    slope over :data:`TRANSITION` m, then the new ground follows, its knots shifted to start
    there. The slope stays continuous, so the pitch stays C1. Knots more than half a body
    behind the horse are dropped (the first kept one's world position becomes the origin),
    so changes do not pile up knots. ``(None, 0)`` when both are flat (None).
    """
    if old is None and new is None:
        return None, 0.0
    old = FLAT if old is None else old
    new = FLAT if new is None else new
    fore = at + 0.5 * HOOF_BASE
    first = max(int(np.searchsorted(old._s, at - 0.5 * HOOF_BASE, side="right")) - 1, 0)
    kept = old._s[first:] < fore  # vectorised: a long profile joins within a tick
    ahead = new._s > 0.0
    start = fore + TRANSITION
    distances = np.concatenate((old._s[first:][kept], [fore, start], start + new._s[ahead]))
    slopes = np.concatenate(
        (np.asarray(old.slopes[first:])[kept], [old.slope_at(fore), new.slopes[0]], np.asarray(new.slopes)[ahead])
    )
    origin = (float(old._x[first]), float(old._y[first])) if kept.any() else old.position(fore, SCALAR)
    return Terrain(tuple(distances.tolist()), tuple(slopes.tolist()), origin), start
