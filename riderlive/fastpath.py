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

import hashlib
import inspect
import types
from collections.abc import Callable, Iterator, Sequence
from functools import cache
from importlib.util import find_spec
from pathlib import Path
from typing import Any, TypeVar, cast

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]
F = TypeVar("F", bound=Callable[..., Any])

AVAILABLE = find_spec("numba") is not None
"""numba is installed."""
BLOCK = 1000
"""Frames per block of :func:`batch`: the block's outputs stay in L2 (~300 KB for 37 channels), and each
output run is 8 KB. Not a power of two, so the rows do not compete for cache sets. 250-1000 measure alike;
2000 and 4000 were ~7% slower (one sweep, N = 10^6)."""
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

    dispatcher = numba.njit(**OPTIONS)(fn)
    dispatcher._cache = _cache_for(dispatcher.py_func)  # numba's cache, stamped with every source compiled in
    return cast(F, dispatcher)


# ----------------------------------------------------------------------------- batch


def batch(
    fn: Callable[..., tuple[float, ...]], n_in: int, n_out: int, helpers: Sequence[Any] = (), block: int = BLOCK
) -> BatchKernel:
    """A kernel applying scalar ``fn`` (``n_in`` floats -> tuple of ``n_out`` floats) to every frame of columns.

    ``helpers``: the plain Python functions ``fn`` calls (such as the rules' ``Ops``),
    compiled with it (:func:`inline`).
    """
    for helper in helpers:
        inline(helper)
    return BatchKernel(fn, n_in, n_out, block)


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
    if AVAILABLE:
        _define_intrinsics()

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


# The Python definitions below are the semantics; :func:`_define_intrinsics` replaces them by numba
# intrinsics (LLVM IR) for compiled callers. "Streaming" stores bypass the cache (x86: vmovntpd): the
# output is written once and not read back, so its lines need not be read from memory first.


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


@cache
def _define_intrinsics() -> None:
    """Replace the helpers above by numba intrinsics (on first compile: importing numba takes ~0.5 s)."""
    from llvmlite import ir
    from numba import types as nbtypes
    from numba.core import cgutils
    from numba.extending import intrinsic

    def pointer(context: Any, builder: Any, aryty: Any, ary: Any, index: Any) -> Any:
        array = context.make_array(aryty)(context, builder, ary)
        return cgutils.get_item_pointer(context, builder, aryty, array, [index])  # type: ignore[no-untyped-call]

    def pointers(context: Any, builder: Any, signature: Any, args: Any, count: int) -> list[Any]:
        """Pointers to ``array[start + k * step]``, k < count, for an intrinsic's (array, start, step, ...)."""
        step = [builder.mul(args[2], context.get_constant(nbtypes.intp, k)) for k in range(count)]
        return [pointer(context, builder, signature.args[0], args[0], builder.add(args[1], s)) for s in step]

    i64, quad = ir.IntType(64), ir.VectorType(ir.DoubleType(), 4)

    def streamed(store: Any) -> None:
        """Mark a store as streaming (LLVM ``!nontemporal``)."""
        store.set_metadata("nontemporal", store.module.add_metadata([ir.Constant(ir.IntType(32), 1)]))

    @intrinsic
    def load_strided(typingctx: Any, array: Any, start: Any, step: Any, like: Any) -> Any:
        result = nbtypes.UniTuple(array.dtype, like.count)  # type: ignore[no-untyped-call]

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            values = [builder.load(p) for p in pointers(context, builder, signature, args, like.count)]
            return context.make_tuple(builder, result, values)

        return result(array, start, step, like), codegen

    @intrinsic
    def load_columns(typingctx: Any, columns: Any, index: Any, gains: Any) -> Any:
        result = nbtypes.UniTuple(columns.dtype.dtype, columns.count)  # type: ignore[no-untyped-call]

        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            values = []
            for k in range(columns.count):
                column = builder.extract_value(args[0], k)
                value = builder.load(pointer(context, builder, columns.dtype, column, args[1]))
                values.append(builder.fmul(value, builder.extract_value(args[2], k)))
            return context.make_tuple(builder, result, values)

        return result(columns, index, gains), codegen

    @intrinsic
    def store_strided(typingctx: Any, array: Any, start: Any, step: Any, values: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> None:
            for j, p in enumerate(pointers(context, builder, signature, args, values.count)):
                builder.store(builder.extract_value(args[3], j), p)

        return nbtypes.void(array, start, step, values), codegen

    @intrinsic
    def to_boundary(typingctx: Any, array: Any, index: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            address = builder.ptrtoint(pointer(context, builder, signature.args[0], args[0], args[1]), i64)
            items = builder.and_(builder.neg(builder.lshr(address, i64(3))), i64(3))
            aligned = builder.icmp_unsigned("==", builder.and_(address, i64(7)), i64(0))
            return builder.select(aligned, items, i64(1 << 62))

        return nbtypes.intp(array, index), codegen

    @intrinsic
    def store_nt(typingctx: Any, array: Any, index: Any, value: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            target = pointer(context, builder, signature.args[0], args[0], args[1])
            streamed(builder.store(context.cast(builder, args[2], signature.args[2], array.dtype), target))
            return context.get_dummy_value()

        return nbtypes.void(array, index, value), codegen

    @intrinsic
    def stream4(typingctx: Any, dst: Any, d: Any, src: Any, s: Any, gain: Any, offset: Any, affine: Any) -> Any:  # noqa: PLR0917
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            source, target = (
                builder.bitcast(pointer(context, builder, signature.args[k], args[k], args[k + 1]), quad.as_pointer())
                for k in (2, 0)
            )
            values = builder.load(source, align=8)
            g, o = (builder.insert_element(quad(ir.Undefined), x, i64(0)) for x in args[4:6])
            spread = ir.Constant(ir.VectorType(ir.IntType(32), 4), [0] * 4)  # lane 0 into all four
            g, o = (builder.shuffle_vector(x, quad(ir.Undefined), spread) for x in (g, o))
            scaled = builder.fadd(builder.fmul(values, g), o)
            streamed(builder.store(builder.select(args[6], scaled, values), target, align=32))
            return context.get_dummy_value()

        return nbtypes.void(dst, d, src, s, nbtypes.float64, nbtypes.float64, nbtypes.boolean), codegen

    @intrinsic
    def fence(typingctx: Any) -> Any:
        def codegen(context: Any, builder: Any, signature: Any, args: Any) -> Any:
            builder.fence("seq_cst")
            return context.get_dummy_value()

        return nbtypes.void(), codegen

    globals().update(
        _load_strided=load_strided,
        _load_columns=load_columns,
        _store_strided=store_strided,
        _to_boundary=to_boundary,
        _store_nt=store_nt,
        _stream4=stream4,
        _fence=fence,
    )
    inline(_stream_row)


# ----------------------------------------------------------------------------- the disk cache


def _cache_for(py_func: Callable[..., Any]) -> Any:
    """numba's per-function disk cache whose freshness stamp also covers every source compiled in."""
    from numba.core.caching import FunctionCache

    class SourcesCache(FunctionCache):  # type: ignore[misc]
        stamped = False

        def _stamp(self) -> None:
            if not self.stamped:  # on first use: by then every module the kernel calls is imported
                own = self._cache_file._source_stamp
                self._cache_file._source_stamp = (own, sources_stamp(py_func))
                self.stamped = True

        def load_overload(self, sig: Any, target_context: Any) -> Any:
            self._stamp()
            return super().load_overload(sig, target_context)  # type: ignore[no-untyped-call]

        def save_overload(self, sig: Any, data: Any) -> None:
            self._stamp()
            super().save_overload(sig, data)  # type: ignore[no-untyped-call]

    return SourcesCache(py_func)  # type: ignore[no-untyped-call]


def sources_stamp(fn: Callable[..., Any]) -> str:
    """A digest of the source files and module constants ``fn`` compiles in (kernels and helpers it calls,
    transitively). Closure values are left out: numba's cache keys entries on them already, and one index
    file holds the entries of every closure made by the same code (the rules of every preset)."""
    files: set[str] = {__file__}
    constants: list[str] = []
    seen: set[int] = set()
    pending = [fn]
    while pending:
        f = cast(types.FunctionType, pending.pop())
        if id(f) in seen:
            continue
        seen.add(id(f))
        files.add(inspect.getfile(f))
        for name, value, is_global in _referenced(f):
            target = getattr(value, "py_func", value)
            if isinstance(target, types.FunctionType):
                pending.append(target)
            elif not is_global:
                continue
            elif isinstance(value, int | float | bool | str | tuple):
                constants.append(f"{name}={value!r}")
            elif isinstance(value, np.ndarray):
                constants.append(f"{name}={hashlib.sha256(value.tobytes()).hexdigest()}")
    digest = hashlib.sha256()
    for path in sorted(files):
        digest.update(path.encode() + _file_digest(path))
    digest.update("\n".join(sorted(constants)).encode())
    return digest.hexdigest()


def _referenced(fn: types.FunctionType) -> Iterator[tuple[str, Any, bool]]:
    """The globals and closure values ``fn``'s code reads (nested code objects included): name, value, global."""
    codes = [fn.__code__]
    names: set[str] = set()
    while codes:
        code = codes.pop()
        names.update(code.co_names)
        codes.extend(c for c in code.co_consts if isinstance(c, types.CodeType))
    for name in sorted(names):
        if name in fn.__globals__:
            yield name, fn.__globals__[name], True
    for name, cell in zip(fn.__code__.co_freevars, fn.__closure__ or (), strict=True):
        yield name, cell.cell_contents, False


@cache
def _file_digest(path: str) -> bytes:
    try:
        return hashlib.sha256(Path(path).read_bytes()).digest()
    except OSError:
        return b""
