"""The rider (and the horse) as a VMC performer: poses in, one OSC bundle per frame out. Pure.

VMC marionettes (EVMC4U in Unity, VMC4UE / VRM4U in Unreal, VMC4B in Blender) pose a
VRM humanoid whose normalized bones all have the identity rotation in its **T-pose**
(facing +z, arms along x, legs down). Our skeleton's rest is the rider **seated**, also
with identity rotations, so a bone's rotation must be re-expressed against the T-pose:

- ``S_b``: the fixed rotation taking bone ``b`` from the T-pose to our seated rest
  (:data:`TPOSE`: the upper arms and forearms hang and reach forward, the thighs reach
  forward and out, the shins hang; everything else is already aligned, ``S_b = 1``);
- ``A_b = W_b S_b``: the avatar bone's world rotation, ``W_b`` our bone's world rotation
  (relative to the rest, as the solver gives it);
- sent: ``L_b = A_p^-1 A_b`` with ``p`` the bone's humanoid parent (``spine_c`` and
  ``spine_d``, which never rotate, are folded into ``UpperChest``), and the position
  of ``b`` in ``p``'s avatar frame;
- all converted to Unity's axes (left-handed, +x right, +y up, +z forward, metres):
  positions ``(z, y, x)``, quaternions ``quat.to_unity`` ``(-z, -y, -x, w)``.

``/VMC/Ext/Root/Pos`` is the rider's seat: the horse's ``saddle`` bone in the world,
so the rider sits on the horse that the second port (or the page) shows. The horse is
sent as a generic skeleton: every bone by its own name, its local position and its
local rotation relative to its rest (identity rotations; positions = the hello's
``offset`` when at rest), root pose the world origin.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass

from riderlive.skeleton import HUMANOID, quat, rider_rig
from riderlive.skeleton.quat import IDENTITY, Quat, Vec3
from riderlive.skeleton.rig import Pose, Rig
from riderlive.vmc import osc

BONE = "/VMC/Ext/Bone/Pos"
ROOT = "/VMC/Ext/Root/Pos"
TIME = "/VMC/Ext/T"
OK = "/VMC/Ext/OK"
OK_ARGS = (1, 3, 0)
"""loaded = 1, calibration state = 3 (calibrated), calibration mode = 0 (normal): V2.5."""

_FORWARD: Vec3 = (1.0, 0.0, 0.0)
_DOWN: Vec3 = (0.0, -1.0, 0.0)
_BACK: Vec3 = (-1.0, 0.0, 0.0)


def _limb(rig: Rig, joints: tuple[str, str, str], t_dir: Vec3, t_flex: Vec3) -> dict[str, Quat]:
    """``S`` of a two-bone limb (upper, lower, end): its T-pose points along ``t_dir``, flexes towards ``t_flex``."""
    upper, lower, end = joints
    d_upper = quat.unit(rig.bones[rig.index[lower]].offset)
    d_lower = quat.unit(rig.bones[rig.index[end]].offset)
    n_rest = quat.unit(quat.cross(d_upper, d_lower))
    n_t = quat.unit(quat.cross(t_dir, t_flex))
    return {
        upper: quat.frame_rotation(t_dir, n_t, d_upper, n_rest),
        lower: quat.frame_rotation(t_dir, n_t, d_lower, n_rest),
    }


@functools.cache
def tpose_turns() -> dict[str, Quat]:
    """``S_b`` for every humanoid bone (identity where the seated rest already matches the T-pose)."""
    rig = rider_rig()
    turns: dict[str, Quat] = dict.fromkeys(HUMANOID, IDENTITY)
    for side, out in (("lf", -1.0), ("rt", 1.0)):
        arm = _limb(rig, (f"{side}_upperarm", f"{side}_forearm", f"{side}_hand"), (0.0, 0.0, out), _FORWARD)
        leg = _limb(rig, (f"{side}_thigh", f"{side}_shin", f"{side}_foot"), _DOWN, _BACK)
        turns.update(arm)
        turns.update(leg)
        turns[f"{side}_hand"] = arm[f"{side}_forearm"]  # the wrist straight at rest
    return turns


@dataclass(frozen=True)
class HumanoidBone:
    index: int
    """In the rider skeleton."""
    parent: int
    """The nearest humanoid ancestor's index in the rider skeleton, -1 for the hips."""
    unity: str
    template: osc.MessageTemplate


@functools.cache
def humanoid_bones() -> tuple[HumanoidBone, ...]:
    rig = rider_rig()
    out = []
    for i, bone in enumerate(rig.bones):
        if bone.name not in HUMANOID:
            continue
        parent = bone.parent
        while parent >= 0 and rig.bones[parent].name not in HUMANOID:
            parent = rig.bones[parent].parent
        unity = HUMANOID[bone.name][0]
        out.append(HumanoidBone(i, parent, unity, osc.MessageTemplate(BONE, unity, 7)))
    return tuple(out)


def to_unity_position(p: Vec3) -> Vec3:
    return (p[2], p[1], p[0])


_ROOT = osc.MessageTemplate(ROOT, "root", 7)
_OK_ELEMENT = osc.element(osc.message(OK, OK_ARGS))


def _time_element(t: float, timecode: str = "") -> bytes:
    """``/VMC/Ext/T`` seconds, then (appended: receivers ignore arguments they do not know) the
    frame's SMPTE timecode label when there is one (docs/timecode.md)."""
    return osc.element(osc.message(TIME, (float(t), timecode) if timecode else (float(t),)))


def _pose_message(template: osc.MessageTemplate, p: Vec3, q: Quat) -> bytes:
    up = to_unity_position(p)
    uq = quat.to_unity(q)
    return template.encode(up[0], up[1], up[2], uq[0], uq[1], uq[2], uq[3])


def rider_elements(pose: Pose) -> list[bytes]:
    """One ``/VMC/Ext/Bone/Pos`` bundle element per humanoid bone (see the module docstring)."""
    turns = tpose_turns()
    rig = rider_rig()
    avatar: dict[int, Quat] = {}
    out = []
    for b in humanoid_bones():
        a = quat.mul(pose.world_rotations[b.index], turns[rig.bones[b.index].name])
        avatar[b.index] = a
        if b.parent < 0:
            local_q, local_p = a, pose.world_positions[b.index]
        else:
            inverse = quat.conj(avatar[b.parent])
            local_q = quat.mul(inverse, a)
            local_p = quat.rotate(inverse, quat.sub(pose.world_positions[b.index], pose.world_positions[b.parent]))
        out.append(_pose_message(b.template, local_p, quat.normalize(local_q)))
    return out


def rider_bundle(pose: Pose, root_position: Vec3, root_rotation: Quat, t: float, timecode: str = "") -> bytes:
    """The rider's frame: OK, time (and timecode), root (the seat in the world), every humanoid bone."""
    root = _pose_message(_ROOT, root_position, root_rotation)
    return osc.bundle_of_elements([_OK_ELEMENT, _time_element(t, timecode), root, *rider_elements(pose)])


@functools.cache
def _horse_templates(names: tuple[str, ...]) -> tuple[osc.MessageTemplate, ...]:
    return tuple(osc.MessageTemplate(BONE, name, 7) for name in names)


def horse_bundle(pose: Pose, names: Sequence[str], t: float, timecode: str = "") -> bytes:
    """The horse's frame: OK, time (and timecode), root at the origin, every bone's local pose by its own name."""
    root = _pose_message(_ROOT, (0.0, 0.0, 0.0), IDENTITY)
    bones = [
        _pose_message(template, pose.local_offsets[i], pose.local_rotations[i])
        for i, template in enumerate(_horse_templates(tuple(names)))
    ]
    return osc.bundle_of_elements([_OK_ELEMENT, _time_element(t, timecode), root, *bones])
