"""numba intrinsics (LLVM IR) of :mod:`riderlive.fastpath_batch`'s helpers, for compiled callers.

The Python definitions in :mod:`riderlive.fastpath_batch` are the semantics; these emit the
same operations as loads, stores and streaming (non-temporal) stores. Imported only with
numba, on the first ``batch``.
"""

from __future__ import annotations

from typing import Any

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
