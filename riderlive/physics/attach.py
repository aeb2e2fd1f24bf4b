"""Where the strands attach and what they collide with, posed from horse and rider frames.

World frame: metres, +x forward, +y up, +z to the horse's right (right-handed);
rotations are right-handed about those axes, so a positive ``rz`` raises the nose
and a positive ``ry`` turns the heading toward -z. Horse frames are in
``channels.HORSE`` order (metres, degrees); rider frames in ``channels.RIDER`` order
as :class:`riderlive.rules.RiderModel` returns them (metres with a metre scale,
degrees).

The hindquarters frame: origin at ``root.t* + Ry(root.ry) (pivot_rest + rearPivot.t*)``
(the horse's pivot and hoof channels are displacements from standing), rotation
``Ry(root.ry + rearPivot.ry) Rz(rearPivot.rz) Rx(rearPivot.rx)``. The tail's dock,
the hindquarters sphere and the hip ends of the hind-leg capsules are fixed in it;
the legs' lower ends follow the back hooves. The rider is a simple pose, not a
skeleton: the seat is fixed in the hindquarters frame (lifted by ``cog.ty``), the
spine leans by ``lower_back.*`` (a positive ``lower_back.rz`` leans forward), the head
turns by ``head.*``. The braid hangs from the back of the head; the rider's back is
one capsule. A skeleton module can later replace :func:`rider_pose` alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.channels import HORSE_INDEX, RIDER_INDEX
from riderlive.physics.collision import Capsules
from riderlive.physics.config import HorseBody, RiderBody
from riderlive.physics.quaternion import rotation_x, rotation_y, rotation_z, shortest_arc, to_matrix

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Frame:
    """A rigid frame: ``origin`` (3,) in world metres, ``rotation`` (3, 3) whose columns are its axes."""

    origin: FloatArray
    rotation: FloatArray

    def point(self, local: FloatArray) -> FloatArray:
        """World position of a point given in this frame."""
        return np.asarray(self.origin + self.rotation @ np.asarray(local, dtype=np.float64), dtype=np.float64)


_NO_OFFSET = np.zeros(3)


def _h(frame: FloatArray, name: str) -> float:
    return float(frame[HORSE_INDEX[name]])


def heading(frame: FloatArray) -> FloatArray:
    """The horse's heading rotation ``Ry(root.ry)``."""
    return rotation_y(_h(frame, "root.ry"))


def hindquarters(frame: FloatArray, pivot_rest: FloatArray = _NO_OFFSET) -> Frame:
    """The rear pivot's world frame for one horse frame (``pivot_rest``: the pivot at rest, root frame)."""
    yaw = heading(frame)
    root = frame[_ROOT]
    rot = (
        rotation_y(_h(frame, "root.ry") + _h(frame, "rearPivot.ry"))
        @ rotation_z(_h(frame, "rearPivot.rz"))
        @ rotation_x(_h(frame, "rearPivot.rx"))
    )
    return Frame(root + yaw @ (frame[_PIVOT] + pivot_rest), rot)


_ROOT = [HORSE_INDEX[f"root.{a}"] for a in ("tx", "ty", "tz")]
_PIVOT = [HORSE_INDEX[f"rearPivot.{a}"] for a in ("tx", "ty", "tz")]
_HOOVES = [[HORSE_INDEX[f"{h}.{a}"] for a in ("tx", "ty", "tz")] for h in ("lbHoof", "rbHoof")]


def aim(direction: FloatArray) -> FloatArray:
    """The shortest-arc rotation taking +x to ``direction`` (so a direction in the x-y plane keeps z as the side)."""
    d = np.asarray(direction, dtype=np.float64)
    return to_matrix(shortest_arc(np.array([1.0, 0.0, 0.0]), d / np.linalg.norm(d)))


class HorseAttachment:
    """The tail's dock and the horse's collision shapes, from :class:`HorseBody` (arrays precomputed)."""

    def hindquarters(self, frame: FloatArray) -> Frame:
        """The rear pivot's world frame for a horse frame."""
        return hindquarters(frame, self.pivot_rest)

    def __init__(self, body: HorseBody) -> None:
        self.pivot_rest = np.array(body.pivot_rest)
        self.dock_offset = np.array(body.dock_offset)
        self.dock_rest = aim(np.array(body.dock_direction))
        self.centre = np.array(body.hindquarters_centre)
        self.hips = np.array([body.hip_offset, body.hip_offset]) * np.array([[1.0, 1.0, -1.0], [1.0, 1.0, 1.0]])
        rest = np.array(body.hind_hoof_rest) + np.array([0.0, body.leg_radius, 0.0])
        self.hoof_shift = np.array([rest * np.array([1.0, 1.0, -1.0]), rest])
        self.radius = np.array([body.hindquarters_radius, body.leg_radius, body.leg_radius])

    def dock(self, hq: Frame) -> Frame:
        """The dock for hindquarters ``hq``: origin at the tail root, x along the dock, z to the side."""
        return Frame(hq.origin + hq.rotation @ self.dock_offset, hq.rotation @ self.dock_rest)

    def colliders(self, frame: FloatArray, hq: Frame) -> Capsules:
        """The hindquarters sphere and the two hind-leg capsules (hip to back hoof) for a horse frame."""
        centre = hq.origin + hq.rotation @ self.centre
        hips = hq.origin + self.hips @ hq.rotation.T
        hooves = frame[_ROOT] + (frame[_HOOVES] + self.hoof_shift) @ heading(frame).T
        return Capsules(np.vstack((centre, hips)), np.vstack((centre, hooves)), self.radius)


@dataclass(frozen=True, eq=False)
class RiderPose:
    """The parts of the rider the strands need: the head frame and the back capsule."""

    head: Frame
    back: Capsules


def _r(rider: FloatArray | None, name: str) -> float:
    return 0.0 if rider is None else float(rider[RIDER_INDEX[name]])


class RiderAttachment:
    """A simple rider pose and the braid's root, from :class:`RiderBody` (arrays precomputed)."""

    def __init__(self, body: RiderBody) -> None:
        self.lift_limit = body.lift_limit
        self.seat = np.array(body.seat_offset)
        self.head_offset = np.array([0.0, body.head_height, 0.0])
        self.back_ends = np.array([body.back_bottom, body.back_top])
        self.back_radius = np.array([body.back_radius])
        self.braid_offset = np.array(body.braid_offset)
        self.braid_rest = aim(np.array(body.braid_direction))

    def pose(self, hq: Frame, rider: FloatArray | None) -> RiderPose:
        """The head frame and back capsule on hindquarters ``hq`` for the rules' rider frame (None: upright)."""
        lift = min(max(_r(rider, "cog.ty"), -self.lift_limit), self.lift_limit)
        seat = hq.origin + hq.rotation @ (self.seat + np.array([0.0, lift, 0.0]))
        spine = (
            hq.rotation
            @ rotation_x(_r(rider, "lower_back.rx"))
            @ rotation_y(_r(rider, "lower_back.ry"))
            @ rotation_z(-_r(rider, "lower_back.rz"))
        )
        head_rot = spine @ rotation_y(_r(rider, "head.ry")) @ rotation_z(-_r(rider, "head.rz"))
        back = seat + self.back_ends @ spine.T
        return RiderPose(
            Frame(seat + spine @ self.head_offset, head_rot), Capsules(back[:1], back[1:], self.back_radius)
        )

    def braid(self, pose: RiderPose) -> Frame:
        """The braid's root at the back of the head, x along its first segment."""
        return Frame(pose.head.point(self.braid_offset), pose.head.rotation @ self.braid_rest)
