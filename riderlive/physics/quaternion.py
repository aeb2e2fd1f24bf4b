"""Quaternions (x, y, z, w, last axis) and rotation helpers, vectorised over leading axes.

Conventions: right-handed rotations, a quaternion ``q`` rotates a vector ``v`` as
``q v q*``; :func:`multiply` composes so that ``multiply(p, q)`` applies ``q`` first.
Euler angles are degrees in the rigs' rotate order XYZ (X applied first, then Y, then Z,
as Maya's default): ``R = Rz(rz) Ry(ry) Rx(rx)``.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])


def normalize(v: FloatArray) -> FloatArray:
    """Unit vectors (or quaternions) along the last axis; zero rows stay zero."""
    norm = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.asarray(v / np.where(norm > 0.0, norm, 1.0), dtype=np.float64)


def perpendicular(a: FloatArray) -> FloatArray:
    """A unit vector perpendicular to each unit vector ``a`` (..., 3)."""
    helper = np.zeros_like(a)
    use_x = np.abs(a[..., 0]) < 0.9
    helper[..., 0] = np.where(use_x, 1.0, 0.0)
    helper[..., 1] = np.where(use_x, 0.0, 1.0)
    return normalize(np.cross(a, helper))


def shortest_arc(a: FloatArray, b: FloatArray) -> FloatArray:
    """The smallest rotation taking unit ``a`` to unit ``b`` (..., 3) -> (..., 4).

    Its axis is ``a x b``, perpendicular to ``a``: no twist about ``a``. For opposite
    vectors any perpendicular axis would do; a fixed choice (:func:`perpendicular`)
    keeps the result deterministic.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    q = np.empty((*np.broadcast_shapes(a.shape, b.shape)[:-1], 4))
    q[..., :3] = np.cross(a, b)
    q[..., 3] = 1.0 + np.sum(a * b, axis=-1)
    # No axis when a and b are opposite to within 1e-7 rad (1 + a.b alone is ~1e-10 already
    # 1e-5 rad away, where a x b still gives the axis precisely).
    opposite = np.sum(q * q, axis=-1) < 1e-14
    if np.any(opposite):
        q[opposite, :3] = perpendicular(np.broadcast_to(a, q[..., :3].shape)[opposite])
        q[opposite, 3] = 0.0
    return normalize(q)


def multiply(p: FloatArray, q: FloatArray) -> FloatArray:
    """Hamilton product ``p q`` (apply ``q``, then ``p``)."""
    px, py, pz, pw = np.moveaxis(p, -1, 0)
    qx, qy, qz, qw = np.moveaxis(q, -1, 0)
    return np.stack(
        (
            pw * qx + px * qw + py * qz - pz * qy,
            pw * qy - px * qz + py * qw + pz * qx,
            pw * qz + px * qy - py * qx + pz * qw,
            pw * qw - px * qx - py * qy - pz * qz,
        ),
        axis=-1,
    )


def conjugate(q: FloatArray) -> FloatArray:
    """The inverse of a unit quaternion."""
    return np.asarray(q * np.array([-1.0, -1.0, -1.0, 1.0]), dtype=np.float64)


def rotate(q: FloatArray, v: FloatArray) -> FloatArray:
    """Rotate vectors ``v`` (..., 3) by unit quaternions ``q`` (..., 4)."""
    u = q[..., :3]
    w = q[..., 3:]
    t = 2.0 * np.cross(u, v)
    return np.asarray(v + w * t + np.cross(u, t), dtype=np.float64)


def from_axis_angle(axis: FloatArray, angle: FloatArray | float) -> FloatArray:
    """Rotation by ``angle`` radians about unit ``axis`` (..., 3)."""
    half = 0.5 * np.asarray(angle, dtype=np.float64)
    axis = np.asarray(axis, dtype=np.float64)
    s = np.sin(half)[..., None]
    return np.concatenate([axis * s, np.cos(half)[..., None] * np.ones((*axis.shape[:-1], 1))], axis=-1)


def from_matrix(m: FloatArray) -> FloatArray:
    """Unit quaternions (w >= 0) from rotation matrices (..., 3, 3) whose columns are the rotated axes."""
    m = np.asarray(m, dtype=np.float64)
    # Four candidate formulas; use the numerically largest one per matrix.
    trace = m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2]
    cand = np.stack(
        (
            np.stack((1 + 2 * m[..., 0, 0] - trace, m[..., 1, 0] + m[..., 0, 1],
                      m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] - m[..., 1, 2]), axis=-1),
            np.stack((m[..., 1, 0] + m[..., 0, 1], 1 + 2 * m[..., 1, 1] - trace,
                      m[..., 2, 1] + m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0]), axis=-1),
            np.stack((m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] + m[..., 1, 2],
                      1 + 2 * m[..., 2, 2] - trace, m[..., 1, 0] - m[..., 0, 1]), axis=-1),
            np.stack((m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0],
                      m[..., 1, 0] - m[..., 0, 1], 1 + trace), axis=-1),
        ),
        axis=-2,
    )  # fmt: skip
    best = np.argmax(np.stack((m[..., 0, 0], m[..., 1, 1], m[..., 2, 2], trace), axis=-1), axis=-1)
    q = np.take_along_axis(cand, best[..., None, None], axis=-2)[..., 0, :]
    q = normalize(q)
    return np.where(q[..., 3:] < 0.0, -q, q)


def to_matrix(q: FloatArray) -> FloatArray:
    """Rotation matrices (..., 3, 3) of unit quaternions; columns are the rotated x, y, z axes."""
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    rows = (
        (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
        (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
        (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
    )
    return np.stack([np.stack(row, axis=-1) for row in rows], axis=-2)


def to_euler_xyz(q: FloatArray) -> FloatArray:
    """Euler degrees (rx, ry, rz), rotate order XYZ: ``R = Rz Ry Rx``; (..., 4) -> (..., 3).

    Reads only the matrix entries it needs (those of :func:`to_matrix`, same arithmetic).
    """
    q = np.asarray(q, dtype=np.float64)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    xx, yy, zz = x * x, y * y, z * z
    m00, m01 = 1.0 - 2.0 * (yy + zz), 2.0 * (x * y - w * z)
    m10, m11 = 2.0 * (x * y + w * z), 1.0 - 2.0 * (xx + zz)
    m20, m21, m22 = 2.0 * (x * z - w * y), 2.0 * (y * z + w * x), 1.0 - 2.0 * (xx + yy)
    ry = np.arcsin(np.clip(-m20, -1.0, 1.0))
    rx = np.arctan2(m21, m22)
    rz = np.arctan2(m10, m00)
    gimbal = np.abs(m20) > 1.0 - 1e-9  # ry = +-90 deg: put the rest in rz, rx = 0
    rx = np.where(gimbal, 0.0, rx)
    rz = np.where(gimbal, np.arctan2(-m01, m11), rz)
    return np.asarray(np.degrees(np.stack((rx, ry, rz), axis=-1)), dtype=np.float64)


def from_euler_xyz(deg: FloatArray) -> FloatArray:
    """Inverse of :func:`to_euler_xyz`: degrees (..., 3) -> quaternions (..., 4)."""
    rad = np.radians(np.asarray(deg, dtype=np.float64))
    ex = np.array([1.0, 0.0, 0.0])
    ey = np.array([0.0, 1.0, 0.0])
    ez = np.array([0.0, 0.0, 1.0])
    qx = from_axis_angle(np.broadcast_to(ex, rad.shape), rad[..., 0])
    qy = from_axis_angle(np.broadcast_to(ey, rad.shape), rad[..., 1])
    qz = from_axis_angle(np.broadcast_to(ez, rad.shape), rad[..., 2])
    return multiply(qz, multiply(qy, qx))


def twist_angle(q: FloatArray, axis: FloatArray) -> FloatArray:
    """The angle (radians, in (-pi, pi]) of the twist part of ``q`` about unit ``axis``."""
    along = np.sum(q[..., :3] * axis, axis=-1)
    angle = 2.0 * np.arctan2(along, q[..., 3])
    return np.asarray((angle + np.pi) % (2.0 * np.pi) - np.pi, dtype=np.float64)


def rotation_y(deg: float) -> FloatArray:
    """3x3 rotation about +y by ``deg`` degrees (heading)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rotation_z(deg: float) -> FloatArray:
    """3x3 rotation about +z by ``deg`` degrees (x turns toward y: nose up)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_x(deg: float) -> FloatArray:
    """3x3 rotation about +x by ``deg`` degrees (roll)."""
    c, s = math.cos(math.radians(deg)), math.sin(math.radians(deg))
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
