"""The saddle pose: where the saddle point on the horse's back is, from any horse frame.

Frames (``riderlive.channels``): right-handed, +X forward, +Y up, +Z to the horse's
right; metres and degrees. ``saddle.tx ty tz`` is the saddle point's displacement from
where it is when the horse stands square, in the horse's travelling frame (``root.*``
does not enter: a platform or a recording wants the motion, not the distance
travelled). ``saddle.rz`` is its pitch (+ nose up), ``rx`` its roll (+ rolling right),
``ry`` its yaw (+ turning left), the same signs as ``rearPivot.r*``.

Orientation from three angles is ``R = Ry(ry) Rz(rz) Rx(rx)``: heading, then pitch,
then roll (applied to the horse's own axes), for the trunk and for the saddle alike.

The back is two rigid segments: the rear one from the rear pivot (hips) to the
mid-back pivot ``BACK_MID`` metres ahead, bent by ``backMid.rz`` against the front
one up to the withers (``WITHERS`` ahead). The saddle point sits ``forward`` metres
ahead of the rear pivot and ``up`` metres above it, on whichever segment carries it.
One source for the live path (Python floats) and for whole takes (NumPy arrays):
only the primitives of :class:`Ops` differ.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
import pydantic

from riderlive.channels import HORSE_INDEX
from riderlive.configfile import StrictModel

FloatArray = npt.NDArray[np.float64]

WITHERS = 0.95
"""The withers' distance ahead of the rear pivot along the back (m), for the 1.6 m horse."""
BACK_MID = 0.40
"""The mid-back pivot's (``backMid``) distance ahead of the rear pivot (m)."""

TRUNK_CHANNELS: tuple[str, ...] = (
    "rearPivot.tx",
    "rearPivot.ty",
    "rearPivot.tz",
    "rearPivot.rx",
    "rearPivot.ry",
    "rearPivot.rz",
)
"""The rear pivot's pose, in the order of ``channels.SADDLE`` (t xyz, r xyz)."""
TRUNK_COLUMNS: tuple[int, ...] = tuple(HORSE_INDEX[n] for n in TRUNK_CHANNELS)
BEND_COLUMN = HORSE_INDEX["backMid.rz"]
_RAD = math.pi / 180.0
_DEG = 180.0 / math.pi


class SaddlePoint(StrictModel):
    """Where the saddle sits: metres ahead of and above the rear pivot (hips)."""

    forward: float = pydantic.Field(default=0.60, ge=0.0, le=WITHERS)
    up: float = pydantic.Field(default=0.15, ge=-0.3, le=0.5)


@dataclass(frozen=True, slots=True)
class Ops:
    """The primitives whose scalar and array forms differ."""

    sin: Callable[[Any], Any]
    cos: Callable[[Any], Any]
    asin: Callable[[Any], Any]
    atan2: Callable[[Any, Any], Any]
    clip1: Callable[[Any], Any]


def _clip1_scalar(x: Any) -> Any:
    return -1.0 if x < -1.0 else (1.0 if x > 1.0 else x)


SCALAR = Ops(math.sin, math.cos, math.asin, math.atan2, _clip1_scalar)
ARRAY = Ops(np.sin, np.cos, np.arcsin, np.arctan2, lambda x: np.clip(x, -1.0, 1.0))

Matrix = tuple[Any, Any, Any, Any, Any, Any, Any, Any, Any]


def matrix(rx: Any, ry: Any, rz: Any, ops: Ops) -> Matrix:
    """``Ry(ry) Rz(rz) Rx(rx)`` (degrees) as nine entries, row by row."""
    a, b, c = ry * _RAD, rz * _RAD, rx * _RAD
    ca, sa, cb, sb, cc, sc = ops.cos(a), ops.sin(a), ops.cos(b), ops.sin(b), ops.cos(c), ops.sin(c)
    return (
        ca * cb,
        sa * sc - ca * sb * cc,
        ca * sb * sc + sa * cc,
        sb,
        cb * cc,
        -cb * sc,
        -sa * cb,
        sa * sb * cc + ca * sc,
        ca * cc - sa * sb * sc,
    )


def angles(m: Matrix, ops: Ops) -> tuple[Any, Any, Any]:
    """``(rx, ry, rz)`` in degrees of a matrix built as :func:`matrix` does."""
    rz = ops.asin(ops.clip1(m[3])) * _DEG
    ry = ops.atan2(-m[6], m[0]) * _DEG
    rx = ops.atan2(-m[5], m[4]) * _DEG
    return rx, ry, rz


def _bend_z(m: Matrix, bend: Any, ops: Ops) -> Matrix:
    """``m Rz(bend)`` (degrees): the front segment bent about the mid-back's lateral axis."""
    cd, sd = ops.cos(bend * _RAD), ops.sin(bend * _RAD)
    return (
        m[0] * cd + m[1] * sd,
        m[1] * cd - m[0] * sd,
        m[2],
        m[3] * cd + m[4] * sd,
        m[4] * cd - m[3] * sd,
        m[5],
        m[6] * cd + m[7] * sd,
        m[7] * cd - m[6] * sd,
        m[8],
    )


def _lever(point: SaddlePoint, bend: Any, ops: Ops) -> tuple[Any, Any, Any]:
    """The saddle point in the trunk's frame (from the rear pivot), the back bent by ``bend``."""
    if point.forward <= BACK_MID:  # on the rear segment: the bend does not move it
        return point.forward, point.up, 0.0
    cd, sd = ops.cos(bend * _RAD), ops.sin(bend * _RAD)
    ahead = point.forward - BACK_MID
    return BACK_MID + ahead * cd - point.up * sd, ahead * sd + point.up * cd, 0.0


def _saddle_bend(point: SaddlePoint, bend: Any) -> Any:
    return bend if point.forward > BACK_MID else 0.0


def saddle_from_trunk(trunk: Sequence[Any], bend: Any, point: SaddlePoint, ops: Ops) -> tuple[Any, ...]:
    """The saddle pose from the rear pivot's pose (``TRUNK_CHANNELS`` order) and the back's bend."""
    px, py, pz, rx, ry, rz = trunk
    m = matrix(rx, ry, rz, ops)
    lx, ly, lz = _lever(point, bend, ops)
    x = px + m[0] * lx + m[1] * ly + m[2] * lz - point.forward
    y = py + m[3] * lx + m[4] * ly + m[5] * lz - point.up
    z = pz + m[6] * lx + m[7] * ly + m[8] * lz
    sx, sy, sz = angles(_bend_z(m, _saddle_bend(point, bend), ops), ops)
    return x, y, z, sx, sy, sz


def trunk_from_saddle(saddle: Sequence[Any], bend: Any, point: SaddlePoint, ops: Ops) -> tuple[Any, ...]:
    """The rear pivot's pose from a saddle pose and the back's bend: the inverse of :func:`saddle_from_trunk`."""
    sx_, sy_, sz_, rx, ry, rz = saddle
    m = _bend_z(matrix(rx, ry, rz, ops), -_saddle_bend(point, bend), ops)
    lx, ly, lz = _lever(point, bend, ops)
    x = sx_ + point.forward - (m[0] * lx + m[1] * ly + m[2] * lz)
    y = sy_ + point.up - (m[3] * lx + m[4] * ly + m[5] * lz)
    z = sz_ - (m[6] * lx + m[7] * ly + m[8] * lz)
    tx, ty, tz = angles(m, ops)
    return x, y, z, tx, ty, tz


def saddle_from_horse(frame: Sequence[float], point: SaddlePoint | None = None) -> list[float]:
    """One horse frame (``channels.HORSE`` order) -> ``channels.SADDLE`` values (the live path)."""
    point = point or SaddlePoint()
    trunk = [frame[i] for i in TRUNK_COLUMNS]
    return list(saddle_from_trunk(trunk, frame[BEND_COLUMN], point, SCALAR))


def saddle_matrix(horse: FloatArray, point: SaddlePoint | None = None) -> FloatArray:
    """Horse frames (N, len(HORSE)) -> saddle poses (N, len(SADDLE)) (the batch path)."""
    point = point or SaddlePoint()
    horse = np.asarray(horse, dtype=np.float64)
    trunk = [horse[:, i] for i in TRUNK_COLUMNS]
    out = saddle_from_trunk(trunk, horse[:, BEND_COLUMN], point, ARRAY)
    return np.column_stack([np.broadcast_to(np.asarray(v, dtype=np.float64), (len(horse),)) for v in out])
