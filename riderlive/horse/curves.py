"""Pure curve primitives shared by the scalar (live) and NumPy (batch) paths.

Every function takes an :class:`Ops` so the same source runs on Python floats (one
frame per tick) and on arrays (a whole take) and gives the same numbers. Nothing here
keeps state or reads a clock.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

TAU = 2.0 * math.pi
_MASK = (1 << 64) - 1


def _where_scalar(cond: Any, a: Any, b: Any) -> Any:
    return a if cond else b


def _clip01_scalar(x: Any) -> Any:
    return 0.0 if x < 0.0 else (1.0 if x > 1.0 else x)


def _clip01_array(x: Any) -> Any:
    return np.clip(x, 0.0, 1.0)


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose scalar and array forms differ."""

    cos: Callable[[Any], Any]
    exp: Callable[[Any], Any]
    floor: Callable[[Any], Any]
    where: Callable[[Any, Any, Any], Any]
    clip01: Callable[[Any], Any]
    is_array: bool


SCALAR = Ops(math.cos, math.exp, math.floor, _where_scalar, _clip01_scalar, False)
ARRAY = Ops(np.cos, np.exp, np.floor, np.where, _clip01_array, True)


def smoothstep(u: Any) -> Any:
    """``3u^2 - 2u^3`` on [0, 1]: zero slope at both ends (the C1 blend weight)."""
    return u * u * (3.0 - 2.0 * u)


def swing_bump(s: Any) -> Any:
    """Transfer height profile ``16 s^2 (1-s)^2``: 0 at lift-off and placement, 1 at mid-transfer, C1."""
    q = s * (1.0 - s)
    return 16.0 * q * q


def hermite(s: Any, p0: Any, p1: Any, m0: Any, m1: Any) -> Any:
    """Cubic Hermite from ``p0`` to ``p1`` with end slopes ``m0``, ``m1`` (per unit ``s``)."""
    s2 = s * s
    s3 = s2 * s
    return p0 * (2.0 * s3 - 3.0 * s2 + 1.0) + m0 * (s3 - 2.0 * s2 + s) + p1 * (3.0 * s2 - 2.0 * s3) + m1 * (s3 - s2)


@dataclass(frozen=True, slots=True)
class Ramp:
    """Speed settling critically damped from ``(v0, a0)`` at ``t0`` toward ``target``.

    Closed form, so speed and distance are exact at any sample time and rate:
    speed is C1 across re-anchoring (a new ramp starts from the old one's speed
    and acceleration). Speeds in m/s, ``omega`` in 1/s, distance in m.
    """

    t0: float
    v0: float
    a0: float
    target: float
    omega: float

    def at(self, t: Any, ops: Ops) -> tuple[Any, Any, Any]:
        """``(speed, acceleration, distance since t0)`` at time ``t``."""
        tau = t - self.t0
        w = self.omega
        e = ops.exp(-w * tau)
        c1 = self.v0 - self.target
        c2 = self.a0 + w * c1
        lin = c1 + c2 * tau
        v = self.target + lin * e
        a = (c2 - w * lin) * e
        x = self.target * tau + c1 * (1.0 - e) / w + c2 * (1.0 - e * (1.0 + w * tau)) / (w * w)
        return v, a, x

    def retarget(self, t: float, target: float, omega: float) -> Ramp:
        """A new ramp from this one's state at ``t`` (C1 in speed)."""
        v, a, _ = self.at(t, SCALAR)
        return Ramp(t, float(v), float(a), target, omega)


@functools.lru_cache(maxsize=1024)
def _splitmix_scalar(seed: int, k: int) -> float:
    z = (seed * 0x9E3779B97F4A7C15 + (k & _MASK) * 0xD1B54A32D192ED03 + 0x632BE59BD9B4E019) & _MASK
    z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & _MASK
    z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & _MASK
    z ^= z >> 31
    return (z >> 11) * (2.0 / 9007199254740992.0) - 1.0


def _splitmix_array(seed: int, k: Any) -> Any:
    with np.errstate(over="ignore"):
        kk = np.asarray(k).astype(np.int64).astype(np.uint64)
        z = np.uint64((seed * 0x9E3779B97F4A7C15 + 0x632BE59BD9B4E019) & _MASK) + kk * np.uint64(0xD1B54A32D192ED03)
        z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        z = z ^ (z >> np.uint64(31))
    return (z >> np.uint64(11)).astype(np.float64) * (2.0 / 9007199254740992.0) - 1.0


def stride_noise(seed: int, phase: Any, ops: Ops) -> Any:
    """Smooth stride-to-stride noise in [-1, 1]: one hashed value per stride, eased between (C1)."""
    k = ops.floor(phase)
    w = smoothstep(phase - k)
    if ops.is_array:
        r0, r1 = _splitmix_array(seed, k), _splitmix_array(seed, k + 1.0)
    else:
        r0, r1 = _splitmix_scalar(seed, int(k)), _splitmix_scalar(seed, int(k) + 1)
    return r0 + (r1 - r0) * w
