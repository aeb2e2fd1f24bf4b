"""Skeleton axes (x forward, y up, z right) to file axes (glTF and BVH: x left, y up, z forward)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from riderlive.skeleton.quat import GLTF_AXES

FloatArray = npt.NDArray[np.float64]


_PICK = np.argmax(np.abs(GLTF_AXES), axis=1)
_SIGN = GLTF_AXES[np.arange(3), _PICK]


def positions(p: FloatArray) -> FloatArray:
    """(..., 3) positions or offsets in file axes (metres): ``GLTF_AXES @ p``, a signed permutation."""
    return np.asarray(p[..., _PICK] * _SIGN + 0.0, dtype=np.float64)  # + 0.0: no negative zeros


def rotations(q: FloatArray) -> FloatArray:
    """(..., 4) quaternions x y z w in file axes (a proper rotation: the vector part turns like a position)."""
    return np.concatenate((positions(q[..., :3]), q[..., 3:]), axis=-1)
