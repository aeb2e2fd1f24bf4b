"""Collision primitives (capsules; a sphere is a capsule with equal ends) and projection out of them.

Everything is in world metres. Projection (:func:`push_out`, compiled) moves a vertex
that lies inside a capsule to the capsule's surface along the shortest way out; every
capsule pushes from the same positions (a vertex inside two of them gets both
pushes), and the solver repeats passes so a vertex pushed from one into another is
handled too. :func:`depth` measures (NumPy; for checks and tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import inline, kernel
from riderlive.physics.vec3 import fmax

FloatArray = npt.NDArray[np.float64]
SKIN = 1e-9
"""Metres beyond the surface a pushed vertex is placed, so it tests as outside."""
_ONES3 = np.ones(3)
WEDGE_SKIN = 1e-5
"""A wider margin for a vertex wedged where two shapes overlap, so the pushes converge."""


@dataclass(frozen=True, eq=False)
class Capsules:
    """``K`` capsules: segment ends ``a`` and ``b`` (K, 3) and ``radius`` (K,), metres."""

    a: FloatArray
    b: FloatArray
    radius: FloatArray

    def __len__(self) -> int:
        return int(self.radius.shape[0])

    @staticmethod
    def empty() -> Capsules:
        return Capsules(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0))

    @staticmethod
    def concat(*parts: Capsules) -> Capsules:
        return Capsules(
            np.concatenate([p.a for p in parts]),
            np.concatenate([p.b for p in parts]),
            np.concatenate([p.radius for p in parts]),
        )


def sphere(centre: FloatArray, radius: float) -> Capsules:
    """One sphere as a capsule of zero length."""
    c = np.asarray(centre, dtype=np.float64).reshape(1, 3)
    return Capsules(c, c.copy(), np.array([radius], dtype=np.float64))


def capsule(a: FloatArray, b: FloatArray, radius: float) -> Capsules:
    """One capsule between points ``a`` and ``b``."""
    return Capsules(
        np.asarray(a, dtype=np.float64).reshape(1, 3),
        np.asarray(b, dtype=np.float64).reshape(1, 3),
        np.array([radius], dtype=np.float64),
    )


def _offsets(x: FloatArray, caps: Capsules) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Offsets (K, V, N) per coordinate of (V, 3, N) points from each capsule's nearest axis point.

    Works coordinate by coordinate on (K, V, N) arrays: no reductions over a short middle axis.
    """
    a = caps.a[:, :, None, None]  # (K, 3, 1, 1)
    ab = (caps.b - caps.a)[:, :, None, None]
    axis = caps.b - caps.a
    inv_len2 = 1.0 / np.maximum((axis * axis) @ _ONES3, 1e-18)[:, None, None]
    p0 = x[None, :, 0] - a[:, 0]
    p1 = x[None, :, 1] - a[:, 1]
    p2 = x[None, :, 2] - a[:, 2]
    t = p0 * ab[:, 0]
    t += p1 * ab[:, 1]
    t += p2 * ab[:, 2]
    t *= inv_len2
    np.clip(t, 0.0, 1.0, out=t)
    p0 -= t * ab[:, 0]
    p1 -= t * ab[:, 1]
    p2 -= t * ab[:, 2]
    return p0, p1, p2


def depth(x: FloatArray, caps: Capsules) -> FloatArray:
    """How far each point of (V, 3, N) ``x`` is inside each capsule (K, V, N); <= 0 outside."""
    d0, d1, d2 = _offsets(x, caps)
    return np.asarray(caps.radius[:, None, None] - np.sqrt(d0 * d0 + d1 * d1 + d2 * d2), dtype=np.float64)


@kernel
def push_out(x: FloatArray, first: int, a: FloatArray, b: FloatArray, radius: FloatArray, skin: float) -> float:  # noqa: PLR0917
    """Project vertices ``first:`` of (V, 3, N) ``x`` out of every capsule to ``skin`` beyond its surface, in place.

    Capsule ends ``a``, ``b`` (K, 3), ``radius`` (K,). Returns the largest depth a vertex
    was pushed from (metres), 0.0 when none was inside.
    """
    n_vert, _, n = x.shape
    k_caps = radius.shape[0]
    ab = np.empty((k_caps, 3))
    inv_len2 = np.empty(k_caps)
    for k in range(k_caps):
        for c in range(3):
            ab[k, c] = b[k, c] - a[k, c]
        inv_len2[k] = 1.0 / fmax(ab[k, 0] * ab[k, 0] + ab[k, 1] * ab[k, 1] + ab[k, 2] * ab[k, 2], 1e-18)
    off = np.empty((k_caps, 3))
    scale = np.empty(k_caps)
    deepest = -np.inf
    inside_any, outside_any = False, False
    for v in range(first, n_vert):
        for s in range(n):
            pushed = False
            for k in range(k_caps):
                p0, p1, p2 = x[v, 0, s] - a[k, 0], x[v, 1, s] - a[k, 1], x[v, 2, s] - a[k, 2]
                t = (p0 * ab[k, 0] + p1 * ab[k, 1] + p2 * ab[k, 2]) * inv_len2[k]
                t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
                p0, p1, p2 = p0 - t * ab[k, 0], p1 - t * ab[k, 1], p2 - t * ab[k, 2]
                dist2 = p0 * p0 + p1 * p1 + p2 * p2
                r = radius[k]
                scale[k] = 0.0
                off[k, 0], off[k, 1], off[k, 2] = p0, p1, p2
                if not dist2 < r * r:
                    outside_any = True
                    continue
                inside_any, pushed = True, True
                dist = math.sqrt(dist2)
                if dist < 1e-12:  # on the axis: no direction to push along, leave sideways
                    off[k, 0], off[k, 1], off[k, 2] = perpendicular(ab[k, 0], ab[k, 1], ab[k, 2])
                    scale[k] = r + skin
                else:
                    scale[k] = (r + skin) / dist - 1.0
                deepest = max(deepest, r - dist)
            if pushed:
                for c in range(3):
                    acc = 0.0
                    for k in range(k_caps):
                        acc += off[k, c] * scale[k]
                    x[v, c, s] += acc
    if not inside_any:
        return 0.0
    return max(deepest, 0.0) if outside_any else deepest


@inline
def perpendicular(a0: float, a1: float, a2: float) -> tuple[float, float, float]:
    """A unit vector perpendicular to axis (a0, a1, a2): its cross product with +x, or +y when near x."""
    h0, h1 = (1.0, 0.0) if abs(a0) < 0.9 else (0.0, 1.0)
    o0, o1, o2 = -a2 * h1, a2 * h0, a0 * h1 - a1 * h0
    norm = math.sqrt(o0 * o0 + o1 * o1 + o2 * o2)
    if norm > 1e-12:
        return (o0 / norm, o1 / norm, o2 / norm)
    return (0.0, 0.0, 1.0)
