"""Quaternions (x, y, z, w) and 3-vectors on plain Python floats.

Rotations act on column vectors: ``mul(a, b)`` applies ``b`` first, then ``a``. Plain
floats keep the per-tick cost low (a few dozen bones) and need no NumPy.
"""

from __future__ import annotations

import math

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]

IDENTITY: Quat = (0.0, 0.0, 0.0, 1.0)


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


def norm(a: Vec3) -> float:
    return math.sqrt(dot(a, a))


def unit(a: Vec3) -> Vec3:
    n = norm(a)
    return (a[0] / n, a[1] / n, a[2] / n) if n > 0.0 else (0.0, 0.0, 0.0)


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


def normalize(q: Quat) -> Quat:
    n = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] / n, q[1] / n, q[2] / n, q[3] / n)


def from_axis_angle(axis: Vec3, degrees: float) -> Quat:
    """Right-handed rotation by ``degrees`` about the unit vector ``axis``."""
    half = math.radians(degrees) * 0.5
    s = math.sin(half)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(half))


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


def from_basis(x: Vec3, y: Vec3, z: Vec3) -> Quat:
    """The rotation whose matrix has the orthonormal columns ``x``, ``y``, ``z``."""
    m00, m10, m20 = x
    m01, m11, m21 = y
    m02, m12, m22 = z
    trace = m00 + m11 + m22
    if trace > 0.0:
        s = 2.0 * math.sqrt(trace + 1.0)
        q = ((m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s, 0.25 * s)
    elif m00 > m11 and m00 > m22:
        s = 2.0 * math.sqrt(1.0 + m00 - m11 - m22)
        q = (0.25 * s, (m01 + m10) / s, (m02 + m20) / s, (m21 - m12) / s)
    elif m11 > m22:
        s = 2.0 * math.sqrt(1.0 + m11 - m00 - m22)
        q = ((m01 + m10) / s, 0.25 * s, (m12 + m21) / s, (m02 - m20) / s)
    else:
        s = 2.0 * math.sqrt(1.0 + m22 - m00 - m11)
        q = ((m02 + m20) / s, (m12 + m21) / s, 0.25 * s, (m10 - m01) / s)
    q = normalize(q)
    return q if q[3] >= 0.0 else (-q[0], -q[1], -q[2], -q[3])


def frame_rotation(d0: Vec3, n0: Vec3, d1: Vec3, n1: Vec3) -> Quat:
    """The rotation taking direction ``d0`` to ``d1`` and plane normal ``n0`` to ``n1``.

    ``d`` and ``n`` of each pair must be unit and orthogonal.
    """
    b0 = cross(d0, n0)
    b1 = cross(d1, n1)
    # R = F1 F0^T with F = [d n b] as columns; its columns are R e_x, R e_y, R e_z.
    col = []
    for k in range(3):
        col.append(add(add(scale(d1, d0[k]), scale(n1, n0[k])), scale(b1, b0[k])))
    return from_basis(col[0], col[1], col[2])


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
