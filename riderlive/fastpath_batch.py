"""The loop of :func:`riderlive.fastpath.batch`: a scalar function over columns, in blocks, streamed out.

Imported on the first ``batch`` (with numba: its intrinsics, :mod:`riderlive.fastpath_llvm`).
The Python definitions of the helpers below are their semantics (and what runs without numba).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt

from riderlive.fastpath_core import AVAILABLE, inline, kernel

FloatArray = npt.NDArray[np.float64]


class BatchKernel:
    """``run(columns, out, in_gain=None, out_gain=None, out_offset=None)``; see :func:`batch`.

    ``columns``: ``n_in`` 1-D float64 arrays of ``N`` frames (copied when not contiguous);
    ``out``: a C-contiguous ``(n_out, N)`` float64 array (one row per output channel).
    Each input is multiplied by ``in_gain`` before ``fn`` sees it; each output becomes
    ``value * out_gain + out_offset`` (both skipped when not given).
    """

    def __init__(self, fn: Callable[..., tuple[float, ...]], n_in: int, n_out: int, block: int) -> None:
        self.fn, self.n_in, self.n_out, self.block = fn, n_in, n_out, block
        self._run = _compile_batch(inline(fn), n_out, block)

    def __call__(
        self,
        columns: Sequence[FloatArray],
        out: FloatArray,
        in_gain: FloatArray | None = None,
        out_gain: FloatArray | None = None,
        out_offset: FloatArray | None = None,
    ) -> None:
        if len(columns) != self.n_in or out.ndim != 2 or out.shape[0] != self.n_out:
            raise ValueError(f"expected {self.n_in} input columns and an ({self.n_out}, N) output")
        if not (out.flags.c_contiguous and out.dtype == np.float64):
            raise ValueError("the output must be a C-contiguous float64 array")
        n = out.shape[1]
        cols = tuple(np.ascontiguousarray(c, dtype=np.float64) for c in columns)
        if any(c.shape != (n,) for c in cols):
            raise ValueError(f"every input column must have {n} frames")
        affine = out_gain is not None or out_offset is not None
        self._run(
            cols,
            _vector(in_gain, self.n_in, 1.0),
            out,
            _vector(out_gain, self.n_out, 1.0),
            _vector(out_offset, self.n_out, 0.0),
            affine,
        )


def _vector(values: FloatArray | None, n: int, default: float) -> FloatArray:
    return np.full(n, default) if values is None else np.ascontiguousarray(values, dtype=np.float64).reshape(n)


def _compile_batch(one: Callable[..., tuple[float, ...]], n_out: int, block: int) -> Callable[..., None]:
    """The batch loop around ``one``, compiled: a closure, so numba's cache keys it on ``one``'s code and constants."""

    def batch_kernel(  # noqa: PLR0917
        columns: Any, in_gain: Any, out: Any, out_gain: Any, out_offset: Any, affine: bool
    ) -> None:
        n = out.shape[1]
        flat = out.reshape(-1)  # row j, frame i at j * n + i
        gains = _load_strided(in_gain, 0, 1, columns)  # the input gains as values, not loads in the loop
        work = np.empty(n_out * block)  # one row of ``block`` frames per output channel
        for start in range(0, n, block):
            m = min(block, n - start)
            for i in range(m):  # constant row offsets in one buffer: LLVM vectorises this across frames
                _store_strided(work, i, block, one(*_load_columns(columns, start + i, gains)))
            for j in range(n_out):
                _stream_row(flat, j * n + start, work, j * block, m, out_gain[j], out_offset[j], affine)
        _fence()

    return kernel(batch_kernel) if AVAILABLE else batch_kernel


# The Python definitions below are the semantics; with numba, the names are bound to the intrinsics of
# riderlive.fastpath_llvm (LLVM IR) at the end of this module, for compiled callers. "Streaming" stores
# bypass the cache (x86: vmovntpd): the output is written once and not read back, so its lines need not
# be read from memory first.


def _stream_row(  # noqa: PLR0917
    dst: FloatArray, d: int, src: FloatArray, s: int, m: int, gain: float, offset: float, affine: bool
) -> None:
    """``dst[d + i] = src[s + i]`` (times ``gain`` plus ``offset`` when ``affine``) for ``i < m``, streamed:
    single values up to the first 32-byte boundary of ``dst``, then 4 values per store, then the rest."""
    head = min(m, _to_boundary(dst, d))
    body = head + (m - head) // 4 * 4
    for i in range(head):
        _store_nt(dst, d + i, src[s + i] * gain + offset if affine else src[s + i])
    for i in range(head, body, 4):
        _stream4(dst, d + i, src, s + i, gain, offset, affine)
    for i in range(body, m):
        _store_nt(dst, d + i, src[s + i] * gain + offset if affine else src[s + i])


def _load_strided(work: FloatArray, start: int, step: int, like: Sequence[Any]) -> tuple[float, ...]:
    """``(work[start], work[start + step], ...)``, as many values as ``like`` has items."""
    return tuple(float(work[start + k * step]) for k in range(len(like)))


def _load_columns(columns: Sequence[FloatArray], index: int, gains: Sequence[float]) -> tuple[float, ...]:
    """``(columns[0][index] * gains[0], columns[1][index] * gains[1], ...)``."""
    return tuple(float(c[index]) * g for c, g in zip(columns, gains, strict=True))


def _store_strided(work: FloatArray, start: int, step: int, values: Sequence[float]) -> None:
    """``work[start + j * step] = values[j]`` for every item of ``values``."""
    for j, v in enumerate(values):
        work[start + j * step] = v


def _to_boundary(array: FloatArray, index: int) -> int:
    """How many float64 items from ``array[index]`` on precede a 32-byte boundary (0-3; 2**62 when the
    array is not 8-byte aligned, so it is never reached)."""
    address = array.ctypes.data + index * 8
    return (-(address >> 3)) & 3 if address & 7 == 0 else 1 << 62


def _store_nt(array: FloatArray, index: int, value: float) -> None:
    """``array[index] = value``, streamed."""
    array[index] = value


def _stream4(  # noqa: PLR0917
    dst: FloatArray, d: int, src: FloatArray, s: int, gain: float, offset: float, affine: bool
) -> None:
    """``dst[d:d + 4] = src[s:s + 4]`` (times ``gain`` plus ``offset`` when ``affine``) in one streaming
    store; ``dst[d]`` must lie on a 32-byte boundary."""
    for k in range(4):
        dst[d + k] = src[s + k] * gain + offset if affine else src[s + k]


def _fence() -> None:
    """Order the streaming stores before whatever follows: they are weakly ordered on x86 (compiled: a full
    fence, ``lock or`` on x86)."""


if AVAILABLE:  # the compiled forms of the semantics above
    from riderlive import fastpath_llvm

    _llvm: Any = fastpath_llvm
    _fence, _load_columns, _load_strided = _llvm.fence, _llvm.load_columns, _llvm.load_strided
    _store_nt, _store_strided, _stream4, _to_boundary = (
        _llvm.store_nt,
        _llvm.store_strided,
        _llvm.stream4,
        _llvm.to_boundary,
    )
    inline(_stream_row)
