"""numba for the platform's sequential kernels (cueing, limits): the same Python source, compiled.

The per-frame kernels of :mod:`riderlive.platform.cueing` and
:mod:`riderlive.platform.limits` are plain Python on floats and indexable
sequences, which the live tick runs as they are. A bake runs them in a loop that
numba compiles from that very source (``nopython``, cached on disk in
``__pycache__``: the first call in a fresh checkout compiles for a few seconds, later
processes load it). Without numba the loops run as Python, slowly but the same.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib.util import find_spec
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])

AVAILABLE = find_spec("numba") is not None
"""numba is installed (a dependency of the package)."""


def jit(fn: F) -> F:
    """``numba.njit`` (disk cache, NumPy division semantics, GIL released), or ``fn`` itself."""
    if not AVAILABLE:  # pragma: no cover
        return fn
    import numba

    return cast(F, numba.njit(cache=True, error_model="numpy", nogil=True)(fn))
