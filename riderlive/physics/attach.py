"""Where the strands attach and what they collide with, posed from horse and rider frames.

World frame: metres, +x forward, +y up, +z to the horse's right (right-handed);
rotations are right-handed about those axes, so a positive ``rz`` raises the nose
and a positive ``ry`` turns the heading toward -z. Horse frames are in
``channels.HORSE`` order (metres, degrees); rider frames in ``channels.RIDER`` order
as :class:`riderlive.rules.RiderModel` returns them (metres with a metre scale,
degrees).

The hindquarters frame: origin at ``root.t* + Ry(root.ry) rearPivot.t*``, rotation
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
from riderlive.physics.quaternion import rotation_x, rotation_y, rotation_z

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Frame:
    """A rigid frame: ``origin`` (3,) in world metres, ``rotation`` (3, 3) whose columns are its axes."""

    origin: FloatArray
    rotation: FloatArray

    def point(self, local: FloatArray) -> FloatArray:
        """World position of a point given in this frame."""
        return np.asarray(self.origin + self.rotation @ np.asarray(local, dtype=np.float64), dtype=np.float64)


def _h(frame: FloatArray, name: str) -> float:
    return float(frame[HORSE_INDEX[name]])


def heading(frame: FloatArray) -> FloatArray:
    """The horse's heading rotation ``Ry(root.ry)``."""
    return rotation_y(_h(frame, "root.ry"))


def hindquarters(frame: FloatArray) -> Frame:
    """The rear pivot's world frame for one horse frame."""
    yaw = heading(frame)
    root = np.array([_h(frame, "root.tx"), _h(frame, "root.ty"), _h(frame, "root.tz")])
    pivot = np.array([_h(frame, "rearPivot.tx"), _h(frame, "rearPivot.ty"), _h(frame, "rearPivot.tz")])
    rot = (
        rotation_y(_h(frame, "root.ry") + _h(frame, "rearPivot.ry"))
        @ rotation_z(_h(frame, "rearPivot.rz"))
        @ rotation_x(_h(frame, "rearPivot.rx"))
    )
    return Frame(root + yaw @ pivot, rot)


def horse_colliders(frame: FloatArray, body: HorseBody) -> Capsules:
    """The hindquarters sphere and the two hind-leg capsules for one horse frame."""
    hq = hindquarters(frame)
    yaw = heading(frame)
    root = np.array([_h(frame, "root.tx"), _h(frame, "root.ty"), _h(frame, "root.tz")])
    centre = hq.point(np.array(body.hindquarters_centre))
    a_rows = [centre]
    b_rows = [centre]
    radii = [body.hindquarters_radius]
    for hoof, side in (("lbHoof", -1.0), ("rbHoof", 1.0)):
        hip = hq.point(np.array(body.hip_offset) * np.array([1.0, 1.0, side]))
        hoof_local = np.array(
            [_h(frame, f"{hoof}.tx"), _h(frame, f"{hoof}.ty") + body.leg_radius, _h(frame, f"{hoof}.tz")]
        )
        hoof_local[2] += side * abs(body.hip_offset[2])
        a_rows.append(hip)
        b_rows.append(root + yaw @ hoof_local)
        radii.append(body.leg_radius)
    return Capsules(np.array(a_rows), np.array(b_rows), np.array(radii))


def dock(frame: FloatArray, body: HorseBody) -> Frame:
    """The tail's dock: origin at the tail root, x along the dock (pointing away from the horse)."""
    hq = hindquarters(frame)
    return Frame(hq.point(np.array(body.dock_offset)), hq.rotation @ _aim(np.array(body.dock_direction)))


def _aim(direction: FloatArray) -> FloatArray:
    """A rotation whose x axis is ``direction`` and whose z axis stays horizontal (the side)."""
    x = direction / np.linalg.norm(direction)
    z = np.cross(x, np.array([0.0, 1.0, 0.0]))
    if np.linalg.norm(z) < 1e-9:
        z = np.array([0.0, 0.0, 1.0])
    z /= np.linalg.norm(z)
    y = np.cross(z, x)
    return np.column_stack((x, y, z))


@dataclass(frozen=True, eq=False)
class RiderPose:
    """The parts of the rider the strands need: the head frame and the back capsule."""

    head: Frame
    back: Capsules


def _r(rider: FloatArray | None, name: str) -> float:
    return 0.0 if rider is None else float(rider[RIDER_INDEX[name]])


def rider_pose(frame: FloatArray, rider: FloatArray | None, body: RiderBody) -> RiderPose:
    """The rider's head frame and back capsule for a horse frame and the rules' rider frame."""
    hq = hindquarters(frame)
    lift = float(np.clip(_r(rider, "cog.ty"), -body.lift_limit, body.lift_limit))
    seat = hq.point(np.array(body.seat_offset) + np.array([0.0, lift, 0.0]))
    spine = (
        hq.rotation
        @ rotation_x(_r(rider, "lower_back.rx"))
        @ rotation_y(_r(rider, "lower_back.ry"))
        @ rotation_z(-_r(rider, "lower_back.rz"))
    )
    head_rot = spine @ rotation_y(_r(rider, "head.ry")) @ rotation_z(-_r(rider, "head.rz"))
    head = Frame(seat + spine @ np.array([0.0, body.head_height, 0.0]), head_rot)
    back = Capsules(
        (seat + spine @ np.array(body.back_bottom))[None, :],
        (seat + spine @ np.array(body.back_top))[None, :],
        np.array([body.back_radius]),
    )
    return RiderPose(head, back)


def braid_frame(pose: RiderPose, body: RiderBody) -> Frame:
    """The braid's root: at the back of the head, x along the braid's first segment."""
    return Frame(
        pose.head.point(np.array(body.braid_offset)), pose.head.rotation @ _aim(np.array(body.braid_direction))
    )
