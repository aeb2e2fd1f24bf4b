"""A BVH file read into joint transforms: the parser behind the fit's mocap riders.

:func:`read_bvh` returns the hierarchy (joint names, parents, rest offsets, channel lists)
and, per frame, each joint's local rotation matrix and local position, in the file's own
axes and length unit. BVH semantics: a joint's rotation channels, in the order listed,
compose left to right (``Zrotation Xrotation Yrotation`` is ``Rz Rx Ry``), degrees; a
joint without position channels sits at its ``OFFSET``; with them, the channels are its
full local position (MotionBuilder, Mixamo and ``riderlive export`` write them so).
``End Site`` blocks are skipped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from riderlive.fit.problem import FitInputError

FloatArray = npt.NDArray[np.float64]

_AXIS = {"X": 0, "Y": 1, "Z": 2}


@dataclass(frozen=True)
class BvhJoint:
    name: str
    parent: int  # -1 for a root
    offset: FloatArray  # (3,) file units
    channels: tuple[str, ...]  # e.g. ("Xposition", ..., "Zrotation", ...)


@dataclass(frozen=True)
class BvhTake:
    """Joints (parents first), the frame time (s), and per joint (J, N, 3, 3) local rotations and (J, N, 3)
    local positions, file axes and units."""

    joints: tuple[BvhJoint, ...]
    frame_time: float
    rotations: FloatArray
    positions: FloatArray

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(j.name for j in self.joints)


def axis_rotation(axis: int, degrees: FloatArray) -> FloatArray:
    """(N, 3, 3) rotations by ``degrees`` about file axis ``axis`` (0 x, 1 y, 2 z), right hand."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    out = np.zeros((len(a), 3, 3))
    i, j = (axis + 1) % 3, (axis + 2) % 3
    out[:, axis, axis] = 1.0
    out[:, i, i], out[:, i, j], out[:, j, i], out[:, j, j] = c, -s, s, c
    return out


def _parse_hierarchy(source: str, tokens: list[str]) -> tuple[list[BvhJoint], int]:
    joints: list[BvhJoint] = []
    stack: list[int] = []
    pending: tuple[str, int] | None = None
    i, end_site = 0, 0
    while i < len(tokens) and tokens[i] != "MOTION":
        tok = tokens[i]
        if tok in ("ROOT", "JOINT"):
            pending = (tokens[i + 1], stack[-1] if stack else -1)
            i += 2
        elif tok == "End":
            end_site += 1
            pending = None
            i += 2
        elif tok == "{":
            stack.append(len(joints) if pending is not None else -2)
            if pending is not None:
                joints.append(BvhJoint(pending[0], pending[1], np.zeros(3), ()))
            pending = None
            i += 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            offset = np.array([float(v) for v in tokens[i + 1 : i + 4]])
            if stack and stack[-1] >= 0:
                j = joints[stack[-1]]
                joints[stack[-1]] = BvhJoint(j.name, j.parent, offset, j.channels)
            i += 4
        elif tok == "CHANNELS":
            count = int(tokens[i + 1])
            j = joints[stack[-1]]
            joints[stack[-1]] = BvhJoint(j.name, j.parent, j.offset, tuple(tokens[i + 2 : i + 2 + count]))
            i += 2 + count
        elif tok == "HIERARCHY":
            i += 1
        else:
            raise FitInputError(f"{source}: unexpected {tok!r} in the BVH hierarchy")
    return joints, i  # End Site blocks (-2 on the stack) are skipped


def read_bvh(path: str) -> BvhTake:
    """Parse the BVH at ``path`` (see the module docstring); :class:`FitInputError` on a malformed file."""
    try:
        text = open(path, encoding="utf-8").read()  # noqa: SIM115 - read whole, closed by GC
    except (OSError, UnicodeDecodeError) as exc:
        raise FitInputError(f"{path}: cannot be read: {exc}") from None
    head, sep, motion = text.partition("MOTION")
    if not sep or not head.lstrip().startswith("HIERARCHY"):
        raise FitInputError(f"{path}: not a BVH file (no HIERARCHY and MOTION sections)")
    try:
        joints, _ = _parse_hierarchy(path, head.split())
        lines = motion.strip().splitlines()
        frames = int(lines[0].split(":")[1])
        frame_time = float(lines[1].split(":")[1])
        values = np.array([[float(v) for v in line.split()] for line in lines[2 : 2 + frames]], dtype=np.float64)
    except (IndexError, ValueError) as exc:
        raise FitInputError(f"{path}: malformed BVH: {exc}") from None
    width = sum(len(j.channels) for j in joints)
    if values.ndim != 2 or values.shape != (frames, width) or frames < 2 or not frame_time > 0.0:
        raise FitInputError(f"{path}: expected {frames} frames of {width} values and a frame time > 0")
    n = values.shape[0]
    rotations = np.tile(np.eye(3), (len(joints), n, 1, 1))
    positions = np.empty((len(joints), n, 3))
    column = 0
    for k, joint in enumerate(joints):
        positions[k] = joint.offset
        for name in joint.channels:
            axis = _AXIS.get(name[:1].upper())
            kind = name[1:].lower()
            if axis is None or kind not in ("rotation", "position"):
                raise FitInputError(f"{path}: joint {joint.name}: unknown channel {name!r}")
            if kind == "position":
                positions[k, :, axis] = values[:, column]
            else:
                rotations[k] = rotations[k] @ axis_rotation(axis, values[:, column])
            column += 1
    return BvhTake(tuple(joints), frame_time, rotations, positions)
