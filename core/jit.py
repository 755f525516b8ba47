"""numba compilation flavours shared by the core kernels.

`njit_leaf` compiles a kernel that reads arrays and returns only numbers, booleans or tuples of them, without
numba's runtime (NRT) and hence without reference counting. numba counts a reference to every array argument
of a compiled function at its entry and releases it at each exit, both atomic operations; its pruning pass
removes such pairs only in simple control flow, and in the branchy geometric tests of the skeleton they were a
fifth of a build's CPU time (perf on office-432, 2026-11-24). Without the runtime the pairs are not emitted.

numba itself keeps this safe: a leaf kernel cannot allocate an array, call a function that does, or return a
new array or a view (compiling it fails), and the functions it calls are compiled without the runtime too. It
may still write into the arrays it is given.

`by_reference` and `dereferenced` hand a named tuple of arrays to a kernel as one address instead of member by
member (numba's calling convention copies every machine word of every array on the stack at each call).
"""

from __future__ import annotations

from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic, models, register_model

njit_leaf = njit(cache=True, _nrt=False)
"""Decorator: a cached nopython kernel without reference counting (see the module docstring)."""


class Reference(types.Type):
    """The address of a value held by a calling kernel (numba type; see `by_reference`)."""

    def __init__(self, dtype):
        self.dtype = dtype
        super().__init__(name=f"Reference({dtype})")


register_model(Reference)(models.PointerModel)


@intrinsic
def by_reference(typingctx, value):
    """The address of a copy of `value` in the calling kernel's frame, handed to a leaf kernel in one argument.

    numba passes a named tuple of arrays member by member (an array is 7 to 9 machine words), so a call
    with the skeleton's geometry, line, scratch and incidence tuples copied 408 words on the stack; the
    callee reads only the members it uses through the address (`dereferenced`). Valid while the calling
    kernel runs, with the value as it was when taken (take it again after rebinding the value). The address
    holds no reference: the arrays must stay held elsewhere while it is used. numba releases a variable after
    its last use, so a tuple built in the kernel and then used only through its address frees the arrays
    only it held; take addresses of the kernel's arguments (held by its caller) or of tuples whose arrays
    the kernel's own variables keep using."""

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[value]
        slot = cgutils.alloca_once(builder, model.get_data_type())
        builder.store(model.as_data(builder, args[0]), slot)
        return slot

    return Reference(value)(value), codegen


@intrinsic
def dereferenced(typingctx, reference):
    """The value at a `by_reference` address (its arrays borrowed from the kernel that took the address)."""

    def codegen(context, builder, signature, args):
        model = context.data_model_manager[reference.dtype]
        value = model.from_data(builder, builder.load(args[0]))
        if context.enable_nrt:
            context.nrt.incref(builder, reference.dtype, value)
        return value

    return reference.dtype(reference), codegen
