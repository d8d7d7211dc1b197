"""A hint to the CPU to bring a cache line in early, for compiled loops over random rows."""

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def prefetch(typingctx, address):
    """Ask for the cache line at ``address`` (an integer) ahead of its read (llvm.prefetch: a read,
    kept in every level of cache): no effect on any value."""

    def codegen(context, builder, signature, llargs):
        bytes_ = ir.IntType(8).as_pointer()
        word = ir.IntType(32)
        name = "llvm.prefetch.p0i8"
        fn = builder.module.globals.get(name) or ir.Function(
            builder.module, ir.FunctionType(ir.VoidType(), [bytes_, word, word, word]), name=name
        )
        builder.call(fn, [builder.inttoptr(llargs[0], bytes_), word(0), word(3), word(1)])
        return context.get_dummy_value()

    return types.void(types.intp), codegen
