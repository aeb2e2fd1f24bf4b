"""The compile core of :mod:`riderlive.fastpath`: which numba, its options, and the decorators.

``kernel`` and ``jit`` compile with :data:`OPTIONS`; ``kernel``'s disk cache is stamped
with every source compiled in (:mod:`riderlive.fastpath_cache`), ``jit``'s is numba's
own (a self-contained loop: only its own file matters). numba is imported on the first
decoration, never by importing this module.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from importlib.util import find_spec
from typing import Any, TypeVar, cast

F = TypeVar("F", bound=Callable[..., Any])

AVAILABLE = find_spec("numba") is not None
"""numba is installed."""
BLOCK = 1000
"""Frames per block of :func:`riderlive.fastpath.batch`: the block's outputs stay in L2 (~300 KB for 37
channels), and each output run is 8 KB. Not a power of two, so the rows do not compete for cache sets.
250-1000 measure alike; 2000 and 4000 were ~7% slower (one sweep, N = 10^6)."""
OPTIONS: dict[str, Any] = {"error_model": "numpy", "nogil": True}
"""numba options of every kernel."""


def inline(fn: F) -> F:
    """A helper for kernels, inlined by LLVM into each kernel that calls it (a plain function for Python).

    Idempotent; anything but a plain Python function (a builtin such as ``abs``, which
    numba knows already) is returned untouched.
    """
    if not AVAILABLE or not isinstance(fn, types.FunctionType) or getattr(fn, "_fastpath_inline", False):
        return fn
    from numba.extending import register_jitable

    register_jitable(forceinline=True)(fn)
    fn._fastpath_inline = True  # type: ignore[attr-defined]
    return fn


def kernel(fn: F) -> F:
    """Compile ``fn`` with numba (on first call; then from the disk cache). ``.py_func`` is ``fn`` itself."""
    if not AVAILABLE:  # pragma: no cover
        fn.py_func = fn  # type: ignore[attr-defined]
        return fn
    import numba

    from riderlive.fastpath_cache import cache_for

    dispatcher = numba.njit(**OPTIONS)(fn)
    dispatcher._cache = cache_for(dispatcher.py_func)  # numba's cache, stamped with every source compiled in
    return cast(F, dispatcher)


def jit(fn: F) -> F:
    """``numba.njit`` with :data:`OPTIONS` and numba's own disk cache (a self-contained loop), or ``fn``."""
    if not AVAILABLE:  # pragma: no cover
        return fn
    import numba

    return cast(F, numba.njit(cache=True, **OPTIONS)(fn))
