"""Collision primitives (capsules; a sphere is a capsule with equal ends) and projection out of them.

Everything is in world metres. Projection moves a vertex that lies inside a capsule
to the capsule's surface along the shortest way out; all capsules are handled in one
vectorised pass (a vertex inside two of them gets both pushes), and the solver
repeats passes so a vertex pushed from one into another is handled too.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
SKIN = 1e-9
"""Metres beyond the surface a pushed vertex is placed, so it tests as outside."""
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


def _offsets(x: FloatArray, caps: Capsules) -> FloatArray:
    """For (V, 3, N) points: offset from the nearest axis point of each capsule, (K, V, 3, N)."""
    a = caps.a[:, None, :, None]
    ab = (caps.b - caps.a)[:, None, :, None]
    p = x[None] - a
    ab_len2 = np.maximum(np.sum((caps.b - caps.a) ** 2, axis=1), 1e-18)[:, None, None]
    t = np.sum(p * ab, axis=2) / ab_len2
    np.clip(t, 0.0, 1.0, out=t)
    p -= t[:, :, None, :] * ab
    return p


def depth(x: FloatArray, caps: Capsules) -> FloatArray:
    """How far each point of (V, 3, N) ``x`` is inside each capsule (K, V, N); <= 0 outside."""
    d = _offsets(x, caps)
    return np.asarray(caps.radius[:, None, None] - np.sqrt(np.sum(d * d, axis=2)), dtype=np.float64)


def push_out(x: FloatArray, caps: Capsules, skin: float = SKIN) -> bool:
    """Project the (V, 3, N) points ``x`` out of every capsule to ``skin`` beyond its surface, in place.

    Returns True if any point moved.
    """
    d = _offsets(x, caps)
    dist = np.sqrt(np.sum(d * d, axis=2))
    radius = caps.radius[:, None, None]
    inside = dist < radius
    if not inside.any():
        return False
    on_axis = inside & (dist < 1e-12)
    if on_axis.any():  # no direction to push along: leave sideways (perpendicular to the axis)
        k, v, n = np.nonzero(on_axis)
        d[k, v, :, n] = _perpendicular(caps.b[k] - caps.a[k])
        dist[k, v, n] = 1.0
    scale = np.where(inside, (radius + skin) / np.maximum(dist, 1e-12) - 1.0, 0.0)
    x += np.sum(d * scale[:, :, None, :], axis=0)
    return True


def _perpendicular(axis: FloatArray) -> FloatArray:
    """A unit vector perpendicular to each row of (M, 3) ``axis`` (any, for zero rows)."""
    helper = np.where(np.abs(axis[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    out = np.cross(axis, helper)
    norm = np.linalg.norm(out, axis=1, keepdims=True)
    out = np.where(norm > 1e-12, out / np.maximum(norm, 1e-12), [[0.0, 0.0, 1.0]])
    return np.asarray(out, dtype=np.float64)
