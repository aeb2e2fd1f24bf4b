"""3-vectors as float tuples for the physics kernels (numba keeps them in registers), inlined into each kernel.

Arrays of vectors are laid out (rows, 3, columns): vertex or bone, coordinate, strand
or chain. Plain Python functions too, so the same source runs uncompiled.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from riderlive.fastpath import inline

FloatArray = npt.NDArray[np.float64]
Vec = tuple[float, float, float]


@inline
def fmax(a: float, b: float) -> float:
    """``np.maximum`` for two floats (a NaN in either propagates)."""
    return a if (a >= b or math.isnan(a)) else b


@inline
def at(a: FloatArray, i: int, s: int) -> Vec:
    """Row ``i``, column ``s`` of a (rows, 3, columns) array."""
    return (a[i, 0, s], a[i, 1, s], a[i, 2, s])


@inline
def put(a: FloatArray, i: int, s: int, v: Vec) -> None:
    a[i, 0, s], a[i, 1, s], a[i, 2, s] = v


@inline
def sub(a: Vec, b: Vec) -> Vec:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@inline
def dot(a: Vec, b: Vec) -> float:
    """Summed in index order (as NumPy's matmul with a ones vector)."""
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@inline
def cross(a: Vec, b: Vec) -> Vec:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@inline
def scaled(a: Vec, k: float) -> Vec:
    return (a[0] * k, a[1] * k, a[2] * k)


@inline
def divided(a: Vec, k: float) -> Vec:
    return (a[0] / k, a[1] / k, a[2] / k)
