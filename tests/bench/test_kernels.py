"""Tests of the kernel profile (bench/kernels.py): the perf map names each kernel at its loaded address, and
perf's report is summed by readable name (perf itself is not run here)."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from bench.kernels import OUTSIDE, _samples_by_function, readable

ROOT = Path(__file__).resolve().parents[2]

# a fresh interpreter: numba registers its object-code hooks with the first kernel it loads, which this pytest
# process has long done
_PLACE_KERNELS = """
import json, sys
import numpy as np
from bench import kernels
kernels.keep_object_code()
from core.skeleton import enumeration
enumeration._line_cell(np.array([0.3, -0.9, 0.2]), 5)
compiled = next(iter(enumeration._line_cell.overloads.values()))
address = compiled.library.get_pointer_to_function(compiled.fndesc.llvm_func_name)
functions = kernels.kernel_functions()
print(json.dumps({
    "address": address,
    "named": [[a, kernels.readable(s)] for a, _, s in functions],
    "sizes_positive": all(size > 0 for _, size, _ in functions),
    "sorted": [a for a, _, _ in functions] == sorted(a for a, _, _ in functions),
}))
"""


@pytest.mark.skipif(shutil.which("nm") is None, reason="nm (binutils) is not installed")
def test_perf_map_names_a_kernel_at_its_loaded_address():
    result = subprocess.run([sys.executable, "-c", _PLACE_KERNELS], cwd=ROOT, capture_output=True, text=True,
                            check=True)  # fmt: skip
    placed = json.loads(result.stdout.strip().splitlines()[-1])
    names_at = {}
    for address, name in placed["named"]:
        names_at.setdefault(address, []).append(name)
    assert "core.skeleton.enumeration._line_cell" in names_at[placed["address"]]
    # numba's runtime is placed too: its reference counts are a kernel cost of their own
    assert any(name == "NRT_incref" for _, name in placed["named"])
    assert placed["sizes_positive"] and placed["sorted"]


def test_readable_names():
    symbol = "_ZN4core8skeleton10validation12_relaxed_arcB4v123B38c8tJTIeFIjxB2IKSgI4CrvQClQZ6FczSBAA_3dE5ArrayIdLi2E"
    assert readable(symbol) == "core.skeleton.validation._relaxed_arc"
    assert readable("_ZN7cpython4core3bvh9_traverseB4v9E") == "core.bvh._traverse (wrapper)"
    assert readable("NRT_decref") == "NRT_decref"
    assert readable("_ZNfoo") == "_ZNfoo"


def test_report_summed_by_name_and_the_rest_outside():
    kernel = "_ZN4core7raycast16_gather_contactsB4v1E"
    report = "\n".join([
        "# comment line",
        f" 40.00%  \t 40        \t[.] {kernel}",
        f" 10.00%  \t 10        \t[.] {kernel.replace('B4v1E', 'B4v2E')}",
        " 30.00%  \t 30        \t[.] _PyEval_EvalFrameDefault",
        " 20.00%  \t 20        \t[k] __schedule",
        "",
    ])  # fmt: skip
    samples = _samples_by_function(report, {kernel, kernel.replace("B4v1E", "B4v2E")})
    assert samples == {"core.raycast._gather_contacts": 50, OUTSIDE: 50}
