"""riderlive skeletons as Blender armatures: build from the hello, pose from the stream, key a take.

Axes: riderlive's skeletons are +x forward, +y up, +z right (metres); Blender's
characters face -Y with +X on their left and +Z up, so a vector ``(x, y, z)`` becomes
``(-z, -x, y)`` (a proper rotation: quaternions map their vector part the same way).
Each Blender bone points from its joint towards its first child; its rest rotation
``B`` (``bone.matrix_local``) therefore differs per bone, while riderlive's rests are
all identity. A riderlive local rotation ``L`` and translation delta ``d`` (in the
parent's frame) become the pose bone's ``rotation_quaternion = B^-1 L B`` and
``location = B^-1 d`` (both in Blender axes), which gives every bone exactly
riderlive's world pose.
"""

from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix, Quaternion, Vector

FLOATS_PER_BONE = 7
_TO_BLENDER = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
"""Rows: Blender X, Y, Z in riderlive axes."""
_FROM_GLTF = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
"""Rows: riderlive x, y, z in glTF axes (glTF: +x left, +y up, +z forward)."""


def vectors(v: np.ndarray, axes: np.ndarray = _TO_BLENDER) -> np.ndarray:
    """(..., 3) vectors (or quaternion vector parts) in other axes."""
    return np.asarray(v, dtype=np.float64) @ axes.T


def quaternions(q: np.ndarray, axes: np.ndarray = _TO_BLENDER) -> np.ndarray:
    """(..., 4) x y z w quaternions in other axes (a proper rotation of the frame)."""
    q = np.asarray(q, dtype=np.float64)
    return np.concatenate((vectors(q[..., :3], axes), q[..., 3:]), axis=-1)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton products of x y z w quaternions (apply ``b``, then ``a``)."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack(
        (
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ),
        axis=-1,
    )


def rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``v`` (..., 3) turned by ``q`` (..., 4)."""
    qv = np.concatenate((v, np.zeros((*v.shape[:-1], 1))), axis=-1)
    conj = q * np.array([-1.0, -1.0, -1.0, 1.0])
    return qmul(qmul(q, qv), conj)[..., :3]


def build(name: str, bones: list[dict]) -> bpy.types.Object:
    """An armature object from skeleton bones (``name``, ``parent`` index, ``offset`` in metres, riderlive axes)."""
    rest = []
    for bone in bones:
        offset = vectors(np.array(bone["offset"], dtype=np.float64))
        rest.append(offset if bone["parent"] < 0 else rest[bone["parent"]] + offset)
    data = bpy.data.armatures.new(name)
    obj = bpy.data.objects.new(name, data)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    bpy.ops.object.mode_set(mode="EDIT")
    edit = []
    for i, bone in enumerate(bones):
        children = [j for j, b in enumerate(bones) if b["parent"] == i]
        direction = rest[children[0]] - rest[i] if children else None
        if direction is None or np.linalg.norm(direction) < 1e-6:
            parent = bone["parent"]
            direction = rest[i] - rest[parent] if parent >= 0 else np.array([0.0, 0.0, 1.0])
            if np.linalg.norm(direction) < 1e-6:
                direction = np.array([0.0, 0.0, 1.0])
        eb = data.edit_bones.new(bone["name"])
        eb.head = Vector(rest[i])
        eb.tail = (
            Vector(rest[i] + 0.05 * direction / np.linalg.norm(direction))
            if not children
            else Vector(rest[i] + direction)
        )
        eb.roll = 0.0
        if bone["parent"] >= 0:
            eb.parent = edit[bone["parent"]]
        edit.append(eb)
    bpy.ops.object.mode_set(mode="OBJECT")
    for pose_bone in obj.pose.bones:
        pose_bone.rotation_mode = "QUATERNION"
    return obj


def rest_frames(obj: bpy.types.Object, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Per bone of ``names``: rest rotation ``B`` (x y z w) and rest offset from its parent (Blender axes)."""
    rots, offsets = [], []
    for name in names:
        bone = obj.data.bones[name]
        q = bone.matrix_local.to_quaternion()
        rots.append((q.x, q.y, q.z, q.w))
        head = bone.head_local if bone.parent is None else bone.head_local - bone.parent.head_local
        offsets.append(tuple(head))
    return np.array(rots), np.array(offsets)


def basis(obj: bpy.types.Object, names: list[str], floats: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose-bone rotations (..., B, 4, x y z w) and locations (..., B, 3) for riderlive pose floats (..., B*7)."""
    b_rot, b_off = rest_frames(obj, names)
    pose = np.asarray(floats, dtype=np.float64).reshape(*np.shape(floats)[:-1], len(names), FLOATS_PER_BONE)
    local_rot = quaternions(pose[..., 3:])
    delta = vectors(pose[..., :3]) - b_off
    b_inv = b_rot * np.array([-1.0, -1.0, -1.0, 1.0])
    rotation = qmul(b_inv, qmul(local_rot, b_rot))
    location = rotate(np.broadcast_to(b_inv, (*delta.shape[:-1], 4)), delta)
    return rotation, location


def apply_pose(obj: bpy.types.Object, names: list[str], floats: list[float]) -> None:
    """Pose ``obj`` from one frame's pose floats (``tx ty tz qx qy qz qw`` per bone, riderlive axes)."""
    rotation, location = basis(obj, names, np.asarray(floats))
    for name, q, loc in zip(names, rotation, location, strict=False):
        pose_bone = obj.pose.bones[name]
        pose_bone.rotation_quaternion = Quaternion((q[3], q[0], q[1], q[2]))
        pose_bone.location = Vector(loc)


def world_pose(parents: list[int], floats: list[float]) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (B, 4) and positions (B, 3) of a skeleton from its pose floats (riderlive axes)."""
    pose = np.asarray(floats, dtype=np.float64).reshape(len(parents), FLOATS_PER_BONE)
    rot = np.zeros((len(parents), 4))
    pos = np.zeros((len(parents), 3))
    for i, p in enumerate(parents):
        if p < 0:
            rot[i], pos[i] = pose[i, 3:], pose[i, :3]
        else:
            rot[i] = qmul(rot[p], pose[i, 3:])
            pos[i] = pos[p] + rotate(rot[p], pose[i, :3])
    return rot, pos


def place(obj: bpy.types.Object, rotation: np.ndarray, position: np.ndarray) -> None:
    """Put an armature object's origin at a riderlive world pose (the rider's seat on the saddle)."""
    q = quaternions(rotation)
    matrix = Quaternion((q[3], q[0], q[1], q[2])).to_matrix().to_4x4()
    matrix.translation = Vector(vectors(position))
    obj.matrix_world = Matrix(matrix)
