"""Where the strands attach and what they collide with, posed from horse and rider frames (compiled).

World frame: metres, +x forward, +y up, +z to the horse's right (right-handed);
rotations are right-handed about those axes, so a positive ``rz`` raises the nose
and a positive ``ry`` turns the heading toward -z. Horse frames are in
``channels.HORSE`` order (metres, degrees); rider frames in ``channels.RIDER`` order
as :class:`riderlive.rules.RiderModel` returns them (metres with a metre scale,
degrees). The kernel reads both by channel name: :data:`HORSE` and :data:`RIDER`
hold each channel's index, resolved from the names once, at import.

The hindquarters frame: origin at ``root.t* + Ry(root.ry) (pivot_rest + rearPivot.t*)``
(the horse's pivot and hoof channels are displacements from standing), rotation
``Ry(root.ry + rearPivot.ry) Rz(rearPivot.rz) Rx(rearPivot.rx)``. The tail's dock,
the hindquarters sphere and the hip ends of the hind-leg capsules are fixed in it;
the legs' lower ends follow the back hooves. The rider is a simple pose, not a
skeleton: the seat is fixed in the hindquarters frame (lifted by ``cog.ty``, within
``lift_limit``; the hips frame is the spine's frame there), the spine leans
``Rx(lower_back.rx) Ry(lower_back.ry) Rz(-lower_back.rz)``
(a positive ``lower_back.rz`` leans forward), the head turns ``Ry(head.ry) Rz(-head.rz)``.
The braid hangs from the back of the head, the two coat-skirt flaps from the hips;
the rider's back is one capsule. Section 8.9's attributes tilt the ties: ``hair.*``
the braid's (in the head frame), ``cloth.*`` both flaps' (in the hips frame).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.fastpath import inline, kernel
from riderlive.physics.collision import Capsules
from riderlive.physics.config import HorseBody, RiderBody
from riderlive.physics.quaternion import shortest_arc, to_matrix

FloatArray = npt.NDArray[np.float64]


class HorseChannels(NamedTuple):
    """Indices into a horse frame of the channels posing reads (field ``node_attr`` is channel ``node.attr``)."""

    root_tx: int
    root_ty: int
    root_tz: int
    root_ry: int
    rearPivot_tx: int
    rearPivot_ty: int
    rearPivot_tz: int
    rearPivot_rx: int
    rearPivot_ry: int
    rearPivot_rz: int
    lbHoof_tx: int
    lbHoof_ty: int
    lbHoof_tz: int
    rbHoof_tx: int
    rbHoof_ty: int
    rbHoof_tz: int


class RiderChannels(NamedTuple):
    """Indices into a rider frame of the channels posing reads."""

    cog_ty: int
    lower_back_rx: int
    lower_back_ry: int
    lower_back_rz: int
    head_ry: int
    head_rz: int
    hair_up: int
    hair_side: int
    cloth_up: int
    cloth_side: int


def _resolve(fields: tuple[str, ...], index: dict[str, int]) -> tuple[int, ...]:
    """Each field ``node_attr`` looked up as channel ``node.attr`` (the last underscore is the dot)."""
    return tuple(index[f"{node}.{attr}"] for node, _, attr in (f.rpartition("_") for f in fields))


HORSE = HorseChannels(*_resolve(HorseChannels._fields, HORSE_INDEX))
RIDER = RiderChannels(*_resolve(RiderChannels._fields, RIDER_INDEX))
UPRIGHT = np.zeros(len(RIDER_INDEX))
"""The rider frame posing uses without a rider: upright, seated."""

# Frames the posing kernel returns, and rows of its table of body points (metres, in the frame named).
HINDQUARTERS, DOCK, HEAD, BRAID, HIPS, CLOTH_L, CLOTH_R = range(7)
PIVOT, DOCK_AT, CENTRE, HIP_L, HIP_R, HOOF_L, HOOF_R, SEAT, HEAD_AT, BACK_LO, BACK_HI, BRAID_AT, HAIR = range(13)
CLOTH_AT, CLOTH = 13, 14
"""``HAIR`` and ``CLOTH`` are no points: their rows hold the gains per unit of ``hair.up`` / ``cloth.up``
and ``hair.side`` / ``cloth.side`` (deg), then (``CLOTH``) the flaps' tilt limit (deg). ``CLOTH_AT`` is the
right flap's root (the left's is mirrored)."""
MIRROR = np.diag([1.0, 1.0, -1.0])
"""Reflection across the horse's midplane (z to -z)."""


@dataclass(frozen=True, eq=False)
class Frame:
    """A rigid frame: ``origin`` (3,) in world metres, ``rotation`` (3, 3) whose columns are its axes."""

    origin: FloatArray
    rotation: FloatArray

    def point(self, local: FloatArray) -> FloatArray:
        """World position of a point given in this frame."""
        return np.asarray(self.origin + self.rotation @ np.asarray(local, dtype=np.float64), dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Pose:
    """Hindquarters, dock, head, braid, hips and flap frames; the colliders (the horse's three, the rider's back)."""

    origins: FloatArray  # (7, 3): HINDQUARTERS, DOCK, HEAD, BRAID, HIPS, CLOTH_L, CLOTH_R
    rotations: FloatArray  # (7, 3, 3)
    colliders: Capsules  # hindquarters sphere, left and right hind legs, rider's back

    def frame(self, which: int) -> Frame:
        return Frame(self.origins[which], self.rotations[which])

    @property
    def horse_colliders(self) -> Capsules:
        c = self.colliders
        return Capsules(c.a[:3], c.b[:3], c.radius[:3])


def aim(direction: tuple[float, float, float]) -> FloatArray:
    """The shortest-arc rotation taking +x to ``direction`` (so a direction in the x-y plane keeps z as the side)."""
    d = np.asarray(direction, dtype=np.float64)
    return to_matrix(shortest_arc(np.array([1.0, 0.0, 0.0]), d / np.linalg.norm(d)))


class Body:
    """The horse's and the rider's shapes as the posing kernel takes them (from the config's bodies)."""

    def __init__(self, horse: HorseBody, rider: RiderBody) -> None:
        mirror = np.array([1.0, 1.0, -1.0])
        hoof = np.array(horse.hind_hoof_rest) + np.array([0.0, horse.leg_radius, 0.0])
        hip = np.array(horse.hip_offset)
        rows = {
            PIVOT: horse.pivot_rest,
            DOCK_AT: horse.dock_offset,
            CENTRE: horse.hindquarters_centre,
            HIP_L: hip * mirror,
            HIP_R: hip,
            HOOF_L: hoof * mirror,
            HOOF_R: hoof,
            SEAT: rider.seat_offset,
            HEAD_AT: (0.0, rider.head_height, 0.0),
            BACK_LO: rider.back_bottom,
            BACK_HI: rider.back_top,
            BRAID_AT: rider.braid_offset,
            HAIR: (rider.hair_up_gain, rider.hair_side_gain, 0.0),
            CLOTH_AT: rider.cloth_offset,
            CLOTH: (rider.cloth_up_gain, rider.cloth_side_gain, rider.cloth_tilt_limit),
        }
        self.points = np.ascontiguousarray([rows[i] for i in range(len(rows))], dtype=np.float64)
        self.dock_rest = aim(horse.dock_direction)
        self.braid_rest = aim(rider.braid_direction)
        right = aim(rider.cloth_direction)
        self.cloth_rest = np.ascontiguousarray([MIRROR @ right @ MIRROR, right])
        """The flaps' rest rotations in the hips frame (left, right): the left is the right's mirror image."""
        self.radius = np.array([horse.hindquarters_radius, horse.leg_radius, horse.leg_radius, rider.back_radius])
        self.lift_limit = float(rider.lift_limit)

    def pose(self, horse: FloatArray, rider: FloatArray | None = None) -> Pose:
        """The frames and colliders for one horse frame and rider frame (None: upright)."""
        origins, rotations, a, b = pose(
            np.ascontiguousarray(horse, dtype=np.float64),
            UPRIGHT if rider is None else np.ascontiguousarray(rider, dtype=np.float64),
            self.points,
            self.dock_rest,
            self.braid_rest,
            self.cloth_rest,
            self.lift_limit,
        )
        return Pose(origins, rotations, Capsules(a, b, self.radius))


# ----------------------------------------------------------------------------- the kernel


@inline
def rotation(axis: int, deg: float) -> FloatArray:
    """3x3 rotation about axis 0 (x), 1 (y) or 2 (z) by ``deg`` degrees, right-handed."""
    rad = deg * (math.pi / 180.0)
    c, s = math.cos(rad), math.sin(rad)
    m = np.zeros((3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    m[axis, axis] = 1.0
    m[i, i], m[j, j] = c, c
    m[i, j], m[j, i] = -s, s
    return m


@inline
def matmul(a: FloatArray, b: FloatArray) -> FloatArray:
    """a @ b for 3x3 matrices, summed in index order."""
    out = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            out[r, c] = a[r, 0] * b[0, c] + a[r, 1] * b[1, c] + a[r, 2] * b[2, c]
    return out


@inline
def place(out: FloatArray, origin: FloatArray, m: FloatArray, x: float, y: float, z: float) -> None:  # noqa: PLR0917
    """out = origin + m @ (x, y, z)."""
    for r in range(3):
        out[r] = origin[r] + (m[r, 0] * x + m[r, 1] * y + m[r, 2] * z)


@kernel
def pose(  # noqa: PLR0917
    h: FloatArray,
    rider: FloatArray,
    points: FloatArray,
    dock_rest: FloatArray,
    braid_rest: FloatArray,
    cloth_rest: FloatArray,
    lift_limit: float,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Frame origins (7, 3) and rotations (7, 3, 3) (HINDQUARTERS, DOCK, HEAD, BRAID, HIPS, CLOTH_L, CLOTH_R),
    capsule ends (4, 3) x 2; ``cloth_rest`` (2, 3, 3) are the flaps' rest rotations (left, right)."""
    origins, rotations = np.empty((7, 3)), np.empty((7, 3, 3))
    cap_a, cap_b = np.empty((4, 3)), np.empty((4, 3))
    root = np.array([h[HORSE.root_tx], h[HORSE.root_ty], h[HORSE.root_tz]])
    yaw = rotation(1, h[HORSE.root_ry])
    hq_rot = matmul(
        matmul(rotation(1, h[HORSE.root_ry] + h[HORSE.rearPivot_ry]), rotation(2, h[HORSE.rearPivot_rz])),
        rotation(0, h[HORSE.rearPivot_rx]),
    )
    p = points[PIVOT]
    hq = origins[HINDQUARTERS]
    place(hq, root, yaw, h[HORSE.rearPivot_tx] + p[0], h[HORSE.rearPivot_ty] + p[1], h[HORSE.rearPivot_tz] + p[2])
    rotations[HINDQUARTERS] = hq_rot
    place(origins[DOCK], hq, hq_rot, points[DOCK_AT, 0], points[DOCK_AT, 1], points[DOCK_AT, 2])
    rotations[DOCK] = matmul(hq_rot, dock_rest)
    for k, row in ((0, CENTRE), (1, HIP_L), (2, HIP_R)):
        place(cap_a[k], hq, hq_rot, points[row, 0], points[row, 1], points[row, 2])
    cap_b[0] = cap_a[0]  # the hindquarters: a sphere
    lb, rb = points[HOOF_L], points[HOOF_R]
    place(cap_b[1], root, yaw, h[HORSE.lbHoof_tx] + lb[0], h[HORSE.lbHoof_ty] + lb[1], h[HORSE.lbHoof_tz] + lb[2])
    place(cap_b[2], root, yaw, h[HORSE.rbHoof_tx] + rb[0], h[HORSE.rbHoof_ty] + rb[1], h[HORSE.rbHoof_tz] + rb[2])
    lift = min(max(rider[RIDER.cog_ty], -lift_limit), lift_limit)
    seat = np.empty(3)
    place(seat, hq, hq_rot, points[SEAT, 0], points[SEAT, 1] + lift, points[SEAT, 2])
    spine = matmul(
        matmul(matmul(hq_rot, rotation(0, rider[RIDER.lower_back_rx])), rotation(1, rider[RIDER.lower_back_ry])),
        rotation(2, -rider[RIDER.lower_back_rz]),
    )
    head_rot = matmul(matmul(spine, rotation(1, rider[RIDER.head_ry])), rotation(2, -rider[RIDER.head_rz]))
    place(cap_a[3], seat, spine, points[BACK_LO, 0], points[BACK_LO, 1], points[BACK_LO, 2])
    place(cap_b[3], seat, spine, points[BACK_HI, 0], points[BACK_HI, 1], points[BACK_HI, 2])
    place(origins[HEAD], seat, spine, points[HEAD_AT, 0], points[HEAD_AT, 1], points[HEAD_AT, 2])
    rotations[HEAD] = head_rot
    place(origins[BRAID], origins[HEAD], head_rot, points[BRAID_AT, 0], points[BRAID_AT, 1], points[BRAID_AT, 2])
    # Section 8.9's attributes tilt the braid's tie like the thesis' set-driven keys: up and back
    # (about the head's z) with hair.up, to the rider's right (about its x) with hair.side.
    tilt = matmul(
        rotation(2, -points[HAIR, 0] * rider[RIDER.hair_up]), rotation(0, -points[HAIR, 1] * rider[RIDER.hair_side])
    )
    rotations[BRAID] = matmul(matmul(head_rot, tilt), braid_rest)
    # The cloth attributes tilt both flaps' ties the same way, in the hips frame, each tilt within the limit.
    origins[HIPS] = seat
    rotations[HIPS] = spine
    limit = points[CLOTH, 2]
    rise = min(max(points[CLOTH, 0] * rider[RIDER.cloth_up], -limit), limit)
    swing = min(max(points[CLOTH, 1] * rider[RIDER.cloth_side], -limit), limit)
    skirt = matmul(spine, matmul(rotation(2, -rise), rotation(0, -swing)))
    c = points[CLOTH_AT]
    for k, frame, z in ((0, CLOTH_L, -c[2]), (1, CLOTH_R, c[2])):
        place(origins[frame], seat, spine, c[0], c[1], z)
        rotations[frame] = matmul(skirt, cloth_rest[k])
    return origins, rotations, cap_a, cap_b
