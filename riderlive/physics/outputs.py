"""Publishing: the bone chains' channels (outside the step), in the rigs' node.attr form.

Per bone ``tail_NN`` / ``braid_NN`` / ``lf_cloth_NN`` / ``rt_cloth_NN`` (NN from 00 at the root):

- ``tx ty tz``: world position of the bone's head (its strand vertex), metres;
- ``qx qy qz qw``: local rotation (relative to the parent bone; bone 00 relative to
  the hindquarters frame for the tail, the head frame for the braid, the hips frame for
  the cloth flaps), unit quaternion;
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
from riderlive.physics.skinned import BRAID, CLOTH_L, CLOTH_R, TAIL, SkinnedModel, SkinnedState

FloatArray = npt.NDArray[np.float64]
BONE_ATTRS: tuple[str, ...] = ("tx", "ty", "tz", "rx", "ry", "rz", "qx", "qy", "qz", "qw")
CHAINS: tuple[tuple[str, int], ...] = (("tail", TAIL), ("braid", BRAID), ("lf_cloth", CLOTH_L), ("rt_cloth", CLOTH_R))
"""Published chains in output order: name prefix and strand column."""


def channel_names(model: SkinnedModel) -> tuple[str, ...]:
    """Every published channel of the skinned tail, braid and cloth flaps, in output order."""
    bones = model.strands.n_vertices - 1
    names: list[str] = []
    for prefix, column in CHAINS:
        for j in range(bones):
            names += [f"{prefix}_{j:02d}.{a}" for a in BONE_ATTRS]
            if model.bones.fan_profile[j, column] > 0.0:
                names.append(f"{prefix}_{j:02d}.fan")
    return tuple(names)


def local_rotations(state: SkinnedState) -> FloatArray:
    """Local rotations (B, C, 4) of every bone (xyzw), bone 0 relative to its anchor's parent frame."""
    parents = np.stack([p.rotation for p in state.parents])[None]  # (1, C, 3, 3)
    both = quaternion.from_matrix(np.concatenate((parents, chain.world_rotations(state.bones)), axis=0))
    local = quaternion.multiply(quaternion.conjugate(both[:-1]), both[1:])
    return np.where(local[..., 3:] < 0.0, -local, local)


def publish(model: SkinnedModel, state: SkinnedState) -> FloatArray:
    """One frame of :func:`channel_names` values for ``state``: per chain, per bone, the
    head position, Euler degrees, quaternion and (where published) the fan distance."""
    local = local_rotations(state)  # (B, C, 4)
    heads = state.strands.x[:-1].transpose(0, 2, 1)  # (B, C, 3)
    fan = state.bones.fan[:, :, None]  # (B, C, 1)
    per_bone = np.concatenate((heads, quaternion.to_euler_xyz(local), local, fan), axis=-1)
    keep = np.ones(per_bone.shape, dtype=bool)
    keep[..., -1] = model.bones.fan_profile > 0.0
    order = [column for _, column in CHAINS]
    return np.asarray(per_bone[:, order].transpose(1, 0, 2)[keep[:, order].transpose(1, 0, 2)], dtype=np.float64)
