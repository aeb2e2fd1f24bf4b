"""BVH files of a take: one skeleton per file (``NAME.rider.bvh``, ``NAME.horse.bvh``).

Axes: right-handed, +Y up, the characters face +Z (+X is their left), as most BVH
readers expect; lengths in metres (``unit="cm"``: centimetres). Each file has one
``ROOT`` named after the skeleton (``rider``: its seat point, moving with the horse's
saddle when the take has a horse; ``horse``: the world origin) and the skeleton's bones
as joints, in the skeleton's order, with their rest offsets. Rotation channels are
``Zrotation Yrotation Xrotation`` (degrees; the joint's matrix is ``Rz Ry Rx``, the
local rotation relative to the rest pose, whose orientations are all identity),
unwrapped over time so no angle jumps by 360. The root and every joint that
translates (the rider's hips, spine, neck and head; the horse's root and rear pivot)
also have ``Xposition Yposition Zposition`` first: the joint's full local position
(its OFFSET is the rest value), as MotionBuilder writes them. Leaf joints end in an
``End Site`` 5 cm along their bone.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import IO

import numpy as np
import numpy.typing as npt
import polars as pl

from riderlive.export import axes
from riderlive.export.take import SkeletonTrack
from riderlive.physics.quaternion import to_euler_xyz

FloatArray = npt.NDArray[np.float64]
UNITS = {"m": 1.0, "cm": 100.0}
POSITION = "Xposition Yposition Zposition"
ROTATION = "Zrotation Yrotation Xrotation"
END_SITE = 0.05
"""Metres from a leaf joint to its end site."""
BRANCH_BELOW = 0.001
"""Metres: children whose offsets average closer than this to their joint get a branch joint (Blender's threshold)."""


def frame_time(rate: float) -> str:
    """``1 / rate`` written shortest-exact (``repr``): a reader's ``1 / float(text)`` is ``rate`` again
    (120 fps: ``0.008333333333333333``, read back 120.0; 8 decimals read back 120.00005)."""
    return repr(1.0 / rate)


def _fmt(v: FloatArray) -> str:
    return " ".join(f"{x:.6f}" for x in v)


@dataclass(frozen=True)
class Joint:
    """One BVH joint: a bone of the rig, the skeleton's root or a static branch joint."""

    name: str
    bone: int | None
    """The rig's bone index; None for the skeleton's ROOT and for a branch joint."""
    offset: FloatArray
    """Rest offset from the parent joint, skeleton axes, metres."""
    children: list[int] = field(default_factory=list)
    """Indices into the layout."""
    position: bool = False
    """Has position channels (the root, a translating bone)."""


def _static_root(track: SkeletonTrack) -> bool:
    """The skeleton's origin stays at the world origin, unturned (the horse's always does)."""
    return bool(np.all(track.root_position == 0.0) and np.all(track.root_rotation == np.array([0.0, 0.0, 0.0, 1.0])))


def layout(track: SkeletonTrack) -> list[Joint]:
    """The joints depth first (children in bone order), as :func:`hierarchy` and :func:`motion` write them.

    Two rules keep every joint's bone a length (Blender's importer aims a joint at the mean of
    its children's heads and warns "zero length node found" when that is its own head):

    - a static root (:func:`_static_root`) whose only bone sits on it at a zero offset and
      translates is not written: that bone (the horse's ``root``) is the ROOT;
    - a joint whose children's offsets average to under 1 mm (the rider's ``hips``: the lower
      back up, the thighs down and to either side) keeps its first child and has the others
      under a static branch joint ``NAME_branch`` at a zero offset (rotation channels, always 0).
    """
    rig = track.rig
    moving = {d.bone for d in rig.translations}
    kids: list[list[int]] = [[] for _ in rig.bones]
    for i, bone in enumerate(rig.bones):
        if bone.parent >= 0:
            kids[bone.parent].append(i)
    roots = [i for i, bone in enumerate(rig.bones) if bone.parent < 0]
    joints: list[Joint] = []

    def add(name: str, bone: int | None, offset: FloatArray, position: bool) -> int:
        joints.append(Joint(name, bone, offset, [], position))
        return len(joints) - 1

    def visit(i: int, parent: int) -> None:
        bone = rig.bones[i]
        here = add(bone.name, i, np.asarray(bone.offset, dtype=np.float64), bone.name in moving)
        joints[parent].children.append(here)
        below(i, here)

    def below(i: int, here: int) -> None:
        children = kids[i]
        mean = np.mean([rig.bones[c].offset for c in children], axis=0) if len(children) > 1 else None
        if mean is None or float(np.linalg.norm(mean)) > BRANCH_BELOW:
            for child in children:
                visit(child, here)
            return
        visit(children[0], here)
        branch = add(f"{rig.bones[i].name}_branch", None, np.zeros(3), False)
        joints[here].children.append(branch)
        for child in children[1:]:
            visit(child, branch)

    only = roots[0] if len(roots) == 1 else -1
    if only >= 0 and _static_root(track) and rig.bones[only].name in moving and not any(rig.bones[only].offset):
        add(rig.bones[only].name, only, np.zeros(3), True)
        below(only, 0)
    else:
        add(rig.name, None, np.zeros(3), True)
        for i in roots:
            visit(i, 0)
    return joints


def hierarchy(track: SkeletonTrack, unit: str = "m") -> str:
    """The HIERARCHY text (joints in the order of :func:`layout`, as :func:`motion`)."""
    scale = UNITS[unit]
    joints = layout(track)
    lines = ["HIERARCHY"]

    def write(k: int, depth: int) -> None:
        pad = "\t" * depth
        joint = joints[k]
        offset = axes.positions(joint.offset) * scale
        channels = f"CHANNELS 6 {POSITION} {ROTATION}" if joint.position else f"CHANNELS 3 {ROTATION}"
        kind = "ROOT" if k == 0 else "JOINT"
        lines.extend([f"{pad}{kind} {joint.name}", f"{pad}{{", f"{pad}\tOFFSET {_fmt(offset)}", f"{pad}\t{channels}"])
        for child in joint.children:
            write(child, depth + 1)
        if not joint.children:
            length = float(np.linalg.norm(joint.offset))
            tip = joint.offset / length if length > 0.0 else np.array([0.0, 1.0, 0.0])
            end = axes.positions(tip * END_SITE) * scale
            lines.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET {_fmt(end)}", f"{pad}\t}}"])
        lines.append(f"{pad}}}")

    write(0, 0)
    return "\n".join(lines) + "\n"


def _euler(q: FloatArray) -> FloatArray:
    """(..., N, 4) local rotations in file axes -> (..., N, 3) channel values Z, Y, X, unwrapped over time."""
    return np.asarray(np.unwrap(to_euler_xyz(q)[..., ::-1], axis=-2, period=360.0), dtype=np.float64)


def motion(track: SkeletonTrack, unit: str = "m") -> FloatArray:
    """(N, channels) MOTION values in the order of :func:`hierarchy` (all bones converted at once)."""
    scale = UNITS[unit]
    poses = track.poses
    frames = poses.local_rotations.shape[1]
    angles = _euler(axes.rotations(poses.local_rotations))  # (B, N, 3)
    offsets = axes.positions(poses.local_offsets) * scale  # (B, N, 3)
    columns: list[FloatArray] = []
    for joint in layout(track):
        if joint.bone is None and joint.position:  # the skeleton's own ROOT
            columns.extend((axes.positions(track.root_position) * scale).T)
            columns.extend(_euler(axes.rotations(track.root_rotation)).T)
        elif joint.bone is None:  # a branch joint: never turns
            columns.extend(np.zeros((3, frames)))
        else:
            if joint.position:
                columns.extend(offsets[joint.bone].T)
            columns.extend(angles[joint.bone].T)
    return np.column_stack(columns)


def write_bvh(fh: IO[bytes], track: SkeletonTrack, rate: float, unit: str = "m") -> None:
    """One skeleton's BVH (text, ``\\n`` line ends) to a binary file."""
    text = hierarchy(track, unit)
    values = motion(track, unit)
    frames = values.shape[0]
    fh.write(text.encode())
    fh.write(f"MOTION\nFrames: {frames}\nFrame Time: {frame_time(rate)}\n".encode())
    # Rounded, then written shortest: 4x faster than a fixed precision, and as exact (1e-5 m, deg).
    values = np.round(values, 5)
    table = pl.DataFrame({f"c{i}": values[:, i] for i in range(values.shape[1])})
    table.write_csv(fh, include_header=False, separator=" ")
