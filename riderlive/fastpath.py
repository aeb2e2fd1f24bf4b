"""Compile one source: plain Python loops on floats and float64 arrays, run by numba.

The project writes each algorithm once. Where it must be fast, that one source is
compiled, never mirrored by hand (the rules run it on floats, on NumPy arrays and
here; the strand physics is written as loops and only ever compiled)::

    from riderlive.fastpath import batch, inline, kernel

    @inline
    def dot(a0, a1, a2, b0, b1, b2):          # a helper kernels call: inlined by LLVM
        return a0 * b0 + a1 * b1 + a2 * b2

    @kernel
    def normalise(x):                          # loops over a float64 array, in place
        for i in range(x.shape[1]):
            n = math.sqrt(dot(x[0, i], x[1, i], x[2, i], x[0, i], x[1, i], x[2, i]))
            x[:, i] /= n

    normalise(x)             # compiled on first call, cached on disk for the next process
    normalise.py_func(x)     # the very same source, interpreted (tests, debugging)

    rules = make_rules(params, SCALAR_OPS)   # scalar: 13 floats in, a tuple of 37 out
    run = batch(rules, 13, 37)
    run(columns, out)        # every frame: out[:, i] = rules(*columns[:, i]), vectorised

- :func:`kernel`: ``numba.njit`` with NumPy's division semantics (no zero checks, so
  loops vectorise), the GIL released, and a disk cache that goes stale whenever any
  source compiled into the kernel changes: its own file, the files of the kernels
  and :func:`inline` helpers it calls (transitively), and the values of the module
  constants it reads. (numba's own cache watches only the kernel's file.)
- :func:`inline`: a helper for kernels; LLVM inlines it into its callers (no call
  overhead, so a loop over frames can vectorise). Python callers get the function
  unchanged.
- :func:`batch`: turns a scalar function of ``n_in`` floats returning ``n_out``
  floats into a kernel over columns. It works in blocks of :data:`BLOCK` frames: the
  function runs over the block straight from the input columns (LLVM vectorises it
  across frames: 4 frames per AVX2 instruction) into one small buffer, one row per
  output channel, and each row is then copied to its output channel as one contiguous
  run with streaming stores (x86 ``vmovntpd``: the output's cache lines are written
  without being read first, and do not evict the block). One pass over the data, at
  the memory-traffic floor (docs/performance.md). Each distinct function (for the
  rules: each preset) compiles once, a few seconds, and is then loaded from the cache.

Without numba (a dependency; only a broken install lacks it) the decorators return
the Python source unchanged and :func:`batch` loops in Python: slow, but the same
results.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

from riderlive.fastpath_cache import TESTED, sources_stamp
from riderlive.fastpath_core import AVAILABLE, BLOCK, OPTIONS, inline, jit, kernel

if TYPE_CHECKING:
    from riderlive.fastpath_batch import BatchKernel

__all__ = [
    "AVAILABLE",
    "BLOCK",
    "OPTIONS",
    "TESTED",
    "BatchKernel",
    "batch",
    "inline",
    "jit",
    "kernel",
    "sources_stamp",
]


def batch(
    fn: Callable[..., tuple[float, ...]], n_in: int, n_out: int, helpers: Sequence[Any] = (), block: int = BLOCK
) -> BatchKernel:
    """A kernel applying scalar ``fn`` (``n_in`` floats -> tuple of ``n_out`` floats) to every frame of columns.

    ``helpers``: the plain Python functions ``fn`` calls (such as the rules' ``Ops``),
    compiled with it (:func:`inline`).
    """
    from riderlive.fastpath_batch import BatchKernel

    for helper in helpers:
        inline(helper)
    return BatchKernel(fn, n_in, n_out, block)
