"""core.jit: kernels compiled without reference counting (njit_leaf) must never hand an array to a caller
that counts references (the caller would release a reference the leaf never took). numba refuses a leaf
that allocates or returns a view; returning an array argument it allows, so that is checked here. A tuple
handed by address (by_reference) reads and writes the caller's arrays and leaves their counts as they were."""

import ast
import inspect
import sys
from collections import namedtuple

import numba
import numpy as np
import pytest
from numba import njit

import core.bvh
import core.formfactor
import core.raycast
import core.skeleton.enumeration
import core.skeleton.skeleton
import core.skeleton.validation
import core.visibility
from core.jit import by_reference, dereferenced, njit_leaf

MODULES = (
    core.bvh, core.formfactor, core.raycast, core.visibility, core.skeleton.enumeration, core.skeleton.validation,
    core.skeleton.skeleton,
)


def leaf_definitions() -> dict[str, ast.FunctionDef]:
    found = {}
    for module in MODULES:
        for node in ast.parse(inspect.getsource(module)).body:
            if isinstance(node, ast.FunctionDef) and any(
                isinstance(d, ast.Name) and d.id == "njit_leaf" for d in node.decorator_list
            ):
                found[f"{module.__name__}.{node.name}"] = node
    return found


def array_parameters(function: ast.FunctionDef) -> set[str]:
    """Parameters the function indexes or asks the shape of: arrays (or tuples of them)."""
    names = {a.arg for a in function.args.args}
    used = set()
    for node in ast.walk(function):
        if isinstance(node, ast.Subscript) and isinstance(node.value, ast.Name):
            used.add(node.value.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.attr == "shape":
            used.add(node.value.id)
    return names & used


def returned_names(function: ast.FunctionDef) -> set[str]:
    """Names returned as such, alone or as members of a returned tuple."""
    names = set()
    for node in ast.walk(function):
        if isinstance(node, ast.Return) and node.value is not None:
            members = node.value.elts if isinstance(node.value, ast.Tuple) else [node.value]
            names.update(m.id for m in members if isinstance(m, ast.Name))
    return names


@njit_leaf
def _allocating_leaf(n):
    return np.zeros(n).sum()


def test_leaf_kernels_return_no_array_argument():
    leaves = leaf_definitions()
    # the skeleton's hot geometric tests are leaves
    assert len(leaves) >= 50, len(leaves)
    offenders = {name: returned_names(f) & array_parameters(f) for name, f in leaves.items()}
    assert not {name: found for name, found in offenders.items() if found}


def test_the_check_sees_a_returned_array_argument():
    function = ast.parse("def f(a, i):\n    a[i] = 0.0\n    return a, i\n").body[0]
    assert returned_names(function) & array_parameters(function) == {"a"}


def test_a_leaf_kernel_cannot_allocate():
    with pytest.raises(numba.core.errors.TypingError):
        _allocating_leaf(3)


_Pair = namedtuple("_Pair", "values counts scale")


@njit_leaf
def _sum_and_count(pair_ref, i):
    """Through the address: adds values[i] * scale into counts[0] and returns values[i]."""
    pair = dereferenced(pair_ref)
    pair.counts[0] += pair.values[i] * pair.scale
    return pair.values[i]


@njit(cache=False)
def _through_address(values, counts, scale):
    pair = _Pair(values, counts, scale)
    pair_ref = by_reference(pair)
    read = 0.0
    for i in range(values.shape[0]):
        read += _sum_and_count(pair_ref, i)
    return read


@njit(cache=False)
def _dereferenced_where_counted(values, counts):
    pair_ref = by_reference(_Pair(values, counts, 1.0))
    return dereferenced(pair_ref).values.sum()


def test_a_tuple_by_address_reads_and_writes_the_callers_arrays():
    values = np.array([1.0, 2.0, 4.0])
    counts = np.zeros(1)
    assert _through_address(values, counts, 0.5) == 7.0
    assert counts[0] == 3.5


def test_a_tuple_by_address_keeps_reference_counts():
    values = np.arange(5.0)
    counts = np.zeros(1)
    before = sys.getrefcount(values), sys.getrefcount(counts)
    for _ in range(3):
        _through_address(values, counts, 1.0)
        assert _dereferenced_where_counted(values, counts) == 10.0
    assert (sys.getrefcount(values), sys.getrefcount(counts)) == before
