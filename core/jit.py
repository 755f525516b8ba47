"""numba compilation flavours shared by the core kernels.

`njit_leaf` compiles a kernel that reads arrays and returns only numbers, booleans or tuples of them, without
numba's runtime (NRT) and hence without reference counting. numba counts a reference to every array argument
of a compiled function at its entry and releases it at each exit, both atomic operations; its pruning pass
removes such pairs only in simple control flow, and in the branchy geometric tests of the skeleton they were a
fifth of a build's CPU time (perf on office-432, 2026-11-24). Without the runtime the pairs are not emitted.

numba itself keeps this safe: a leaf kernel cannot allocate an array, call a function that does, or return a
new array or a view (compiling it fails), and the functions it calls are compiled without the runtime too. It
may still write into the arrays it is given.
"""

from __future__ import annotations

from numba import njit

njit_leaf = njit(cache=True, _nrt=False)
"""Decorator: a cached nopython kernel without reference counting (see the module docstring)."""
