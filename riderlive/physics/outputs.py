"""Publishing: the bone chains' channels (outside the step), in the rigs' node.attr form.

Per bone ``tail_NN`` / ``braid_NN`` (NN from 00 at the root):

- ``tx ty tz``: world position of the bone's head (its strand vertex), metres;
- ``qx qy qz qw``: local rotation (relative to the parent bone; bone 00 relative to
  the hindquarters frame for the tail, the head frame for the braid), unit quaternion;
- ``rx ry rz``: the same local rotation as Euler degrees, rotate order XYZ, in the
  rigs' axis convention: the bone's long axis is local X (``rx`` twists), ``rz``
  bends front/back, ``ry`` side to side;
- ``fan`` (tail bones of the lower half): the distance of the three sub-chain bones
  from the centre bone, metres; sub-chain bone ``k`` sits at local
  ``(0, fan cos(2 pi k / 3), fan sin(2 pi k / 3))`` of its centre bone.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from riderlive.physics import chain, quaternion
from riderlive.physics.skinned import BRAID, TAIL, SkinnedModel, SkinnedState

FloatArray = npt.NDArray[np.float64]
BONE_ATTRS: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz", "qx", "qy", "qz", "qw")


def channel_names(model: SkinnedModel) -> tuple[str, ...]:
    """Every published channel of the skinned tail and braid, in output order."""
    bones = model.strands.n_vertices - 1
    names: list[str] = []
    for prefix, column in (("tail", TAIL), ("braid", BRAID)):
        for j in range(bones):
            names += [f"{prefix}_{j:02d}.{a}" for a in BONE_ATTRS]
            if model.bones.fan_profile[j, column] > 0.0:
                names.append(f"{prefix}_{j:02d}.fan")
    return tuple(names)


def local_rotations(state: SkinnedState) -> FloatArray:
    """Local rotations (B, C, 4) of every bone (xyzw), bone 0 relative to its anchor's parent frame."""
    world = quaternion.from_matrix(chain.world_rotations(state.bones))
    parents = np.stack([quaternion.from_matrix(p.rotation) for p in state.parents])
    parent = np.concatenate((parents[None], world[:-1]), axis=0)
    local = quaternion.multiply(quaternion.conjugate(parent), world)
    return np.where(local[..., 3:] < 0.0, -local, local)


def publish(model: SkinnedModel, state: SkinnedState) -> FloatArray:
    """One frame of :func:`channel_names` values for ``state``."""
    local = local_rotations(state)
    euler = quaternion.to_euler_xyz(local)
    heads = state.strands.x[:-1]  # (B, 3, C)
    out: list[float] = []
    for column in (TAIL, BRAID):
        for j in range(heads.shape[0]):
            out += heads[j, :, column].tolist()
            out += euler[j, column].tolist()
            out += local[j, column].tolist()
            if model.bones.fan_profile[j, column] > 0.0:
                out.append(float(state.bones.fan[j, column]))
    return np.array(out)
