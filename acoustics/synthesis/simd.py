"""Eight-wide vector steps for the compiled synthesis loops, written as LLVM IR.

numba leaves LLVM's SLP vectoriser off and its loop vectoriser guards a loop of eight taps with
run-time alias checks and remainders, so the eight multiply-adds that spread one arrival onto a
delta train cost far more than their arithmetic (a kernel stored and read back, alias checks:
docs/performance.md). :func:`spread8` emits them directly: two 8-double loads from the kernel
table, one fused multiply-add for the interpolated kernel, and one load, fused multiply-add and
store per train — the same ``fma`` operations, in the same order per tap, that the compiled loops
of :func:`acoustics.synthesis.arrivals._tap_kernel` and ``_add_split`` perform on a machine with
FMA, so the sums are the same bits (checked on twelve synthesis cases when it was introduced:
docs/performance.md, "Echo synthesis against the code before issue 31").
tests/test_arrivals_simd.py checks the spread against numpy. ``llvm.fma`` is portable LLVM: a
target without vector FMA splits or emulates it, exactly.
"""
from __future__ import annotations

from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

__all__ = ["spread8", "WIDTH"]

#: taps per vector step
WIDTH = 8
_V8 = ir.VectorType(ir.DoubleType(), WIDTH)
_I32 = ir.IntType(32)


def _splat(builder, x):
    v = builder.insert_element(ir.Constant(_V8, ir.Undefined), x, ir.Constant(_I32, 0))
    return builder.shuffle_vector(v, ir.Constant(_V8, ir.Undefined),
                                  ir.Constant(ir.VectorType(_I32, WIDTH), [0] * WIDTH))


@intrinsic
def spread8(typingctx, table, dtable, row, w, rre, rim, base, ar, ai):
    """Add ``ar k`` to ``rre[base:base + 8]`` and ``ai k`` to ``rim[base:base + 8]`` with
    ``k = table[row:row + 8] + w dtable[row:row + 8]`` (fused multiply-adds throughout).

    Every array is 1-D, contiguous float64; the caller guarantees the eight elements from
    ``row`` and from ``base`` exist (no bounds check)."""
    for t in (table, dtable, rre, rim):
        if not (isinstance(t, types.Array) and t.ndim == 1 and t.dtype == types.float64
                and t.layout == "C"):
            return None
    sig = types.void(table, dtable, types.intp, types.float64, rre, rim, types.intp,
                     types.float64, types.float64)

    def codegen(context, builder, signature, args):
        tab, dtab, row_, w_, re_, im_, base_, ar_, ai_ = args
        arys = [context.make_array(signature.args[k])(context, builder, v)
                for k, v in ((0, tab), (1, dtab), (4, re_), (5, im_))]
        fma = cgutils.get_or_insert_function(builder.module, ir.FunctionType(_V8, [_V8] * 3),
                                             "llvm.fma.v8f64")

        def ptr(ary, off):
            return builder.bitcast(builder.gep(ary.data, [off]), _V8.as_pointer())

        t_v = builder.load(ptr(arys[0], row_), align=8)
        d_v = builder.load(ptr(arys[1], row_), align=8)
        k_v = builder.call(fma, [_splat(builder, w_), d_v, t_v])
        for ary, a in ((arys[2], ar_), (arys[3], ai_)):
            p = ptr(ary, base_)
            builder.store(builder.call(fma, [_splat(builder, a), k_v, builder.load(p, align=8)]),
                          p, align=8)
        return context.get_dummy_value()

    return sig, codegen
