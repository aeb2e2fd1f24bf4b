"""Quaternions (x, y, z, w) and 3-vectors as tuples of components, written once for two backends.

Rotations act on column vectors: ``mul(a, b)`` applies ``b`` first, then ``a``. Each
component is a Python float (one live frame: plain floats keep the per-tick cost low
and need no NumPy) or a NumPy array of N frames (a whole take at once). Arithmetic is
the same on both; the few primitives that differ (square root, sine, cosine, choice)
come from an :class:`Ops`, as in :mod:`riderlive.rules.kuhnel2003`: ``SCALAR`` for
floats (the default), ``ARRAY`` for arrays.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

IDENTITY: Quat = (0.0, 0.0, 0.0, 1.0)


def _where_scalar(cond: Any, a: Any, b: Any) -> Any:
    return a if cond else b


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose float and array forms differ."""

    sqrt: Callable[[Any], Any]
    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    where: Callable[[Any, Any, Any], Any]
    """``where(cond, a, b)``: ``a`` where ``cond`` holds, else ``b`` (both are evaluated)."""
    maximum: Callable[[Any, Any], Any]
    minimum: Callable[[Any, Any], Any]
    isfinite: Callable[[Any], Any]


SCALAR = Ops(math.sqrt, math.sin, math.cos, _where_scalar, max, min, math.isfinite)
ARRAY = Ops(np.sqrt, np.sin, np.cos, np.where, np.maximum, np.minimum, np.isfinite)


def choose(cond: Any, a: tuple[Any, ...], b: tuple[Any, ...], ops: Ops = SCALAR) -> Any:
    """Component-wise ``a`` where ``cond`` holds, else ``b`` (vectors or quaternions)."""
    if ops is SCALAR:
        return a if cond else b
    return tuple(ops.where(cond, x, y) for x, y in zip(a, b, strict=True))


def add(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(a: Vec3, s: float) -> Vec3:
    return (a[0] * s, a[1] * s, a[2] * s)


def dot(a: Vec3, b: Vec3) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def norm(a: Vec3, ops: Ops = SCALAR) -> float:
    return ops.sqrt(dot(a, a))  # type: ignore[no-any-return]


def unit(a: Vec3, ops: Ops = SCALAR) -> Vec3:
    """``a`` scaled to length 1; the zero vector stays zero."""
    n = ops.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    if ops is SCALAR:
        inv = 1.0 / n if n > 0.0 else 0.0
    else:
        positive = n > 0.0
        inv = ops.where(positive, 1.0 / ops.where(positive, n, 1.0), 0.0)
    return (a[0] * inv, a[1] * inv, a[2] * inv)


def mul(a: Quat, b: Quat) -> Quat:
    """The rotation ``b`` followed by ``a``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def conj(q: Quat) -> Quat:
    """The inverse of a unit quaternion."""
    return (-q[0], -q[1], -q[2], q[3])


def normalize(q: Quat, ops: Ops = SCALAR) -> Quat:
    n = ops.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def from_axis_angle(axis: Vec3, degrees: float, ops: Ops = SCALAR) -> Quat:
    """Right-handed rotation by ``degrees`` about the unit vector ``axis``."""
    half = degrees * (math.pi / 360.0)
    s = ops.sin(half)
    return (axis[0] * s, axis[1] * s, axis[2] * s, ops.cos(half))


def rotate(q: Quat, v: Vec3) -> Vec3:
    """``v`` rotated by the unit quaternion ``q``."""
    qx, qy, qz, qw = q
    tx = 2.0 * (qy * v[2] - qz * v[1])
    ty = 2.0 * (qz * v[0] - qx * v[2])
    tz = 2.0 * (qx * v[1] - qy * v[0])
    return (
        v[0] + qw * tx + qy * tz - qz * ty,
        v[1] + qw * ty + qz * tx - qx * tz,
        v[2] + qw * tz + qx * ty - qy * tx,
    )


def from_basis(x: Vec3, y: Vec3, z: Vec3, ops: Ops = SCALAR) -> Quat:
    """The rotation whose matrix has the orthonormal columns ``x``, ``y``, ``z`` (``w >= 0``).

    Shepperd's method: the largest of ``w``, ``x``, ``y``, ``z`` is found from the diagonal
    and the others divided by it. On arrays every case is computed and the right one
    chosen per frame (the square roots are clamped so unused cases stay finite).
    """
    m00, m10, m20 = x
    m01, m11, m21 = y
    m02, m12, m22 = z
    trace = m00 + m11 + m22
    big_w = trace > 0.0
    big_x = (m00 > m11) & (m00 > m22) if ops is ARRAY else (m00 > m11 and m00 > m22)
    big_y = m11 > m22

    def half_root(v: Any) -> Any:
        return 2.0 * ops.sqrt(ops.maximum(v, 1e-300))

    def case_w() -> Quat:
        s = half_root(trace + 1.0)
        return ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)

    def case_x() -> Quat:
        s = half_root(1.0 + m00 - m11 - m22)
        return (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)

    def case_y() -> Quat:
        s = half_root(1.0 + m11 - m00 - m22)
        return ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)

    def case_z() -> Quat:
        s = half_root(1.0 + m22 - m00 - m11)
        return ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)

    if ops is SCALAR:
        q = case_w() if big_w else case_x() if big_x else case_y() if big_y else case_z()
    else:
        q = choose(big_w, case_w(), choose(big_x, case_x(), choose(big_y, case_y(), case_z(), ops), ops), ops)
    q = normalize(q, ops)
    return choose(q[3] >= 0.0, q, (-q[0], -q[1], -q[2], -q[3]), ops)  # type: ignore[no-any-return]


def frame_rotation(d0: Vec3, n0: Vec3, d1: Vec3, n1: Vec3, ops: Ops = SCALAR) -> Quat:
    """The rotation taking direction ``d0`` to ``d1`` and plane normal ``n0`` to ``n1``.

    ``d`` and ``n`` of each pair must be unit and orthogonal.
    """
    b0 = cross(d0, n0)
    b1 = cross(d1, n1)
    # R = F1 F0^T with F = [d n b] as columns; its columns are R e_x, R e_y, R e_z.
    col = []
    for k in range(3):
        col.append(add(add(scale(d1, d0[k]), scale(n1, n0[k])), scale(b1, b0[k])))
    return from_basis(col[0], col[1], col[2], ops)


def to_unity(q: Quat) -> Quat:
    """A rotation in riderlive's frame (x forward, y up, z right) in Unity's (x right, y up, z forward).

    The two frames differ by swapping x and z (one right-handed, one left-handed), so a
    rotation's axis maps like a pseudo-vector: ``(-z, -y, -x, w)``.
    """
    return (-q[2], -q[1], -q[0], q[3])


def to_unreal(q: Quat) -> Quat:
    """The same rotation in Unreal's axes (x forward, y right, z up; left-handed): ``(-x, -z, -y, w)``.

    Positions map as ``(x, z, y)`` and metres to centimetres (x 100).
    """
    return (-q[0], -q[2], -q[1], q[3])


def to_godot(q: Quat) -> Quat:
    """The same rotation in Godot's axes (x right, y up, -z forward; right-handed): ``(z, y, -x, w)``.

    Positions map as ``(z, y, -x)``.
    """
    return (q[2], q[1], -q[0], q[3])


def to_gltf(q: Quat) -> Quat:
    """The same rotation in glTF's (and our BVH files') axes: x to the character's left, y up,
    z forward; right-handed, so a proper rotation of ours: ``(-z, y, x, w)``.

    Positions map as ``(-z, y, x)`` (:data:`GLTF_AXES`).
    """
    return (-q[2], q[1], q[0], q[3])


GLTF_AXES = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])
"""Rows: glTF x, y, z in our axes; ``gltf = GLTF_AXES @ ours`` for positions and quaternion vector parts."""
