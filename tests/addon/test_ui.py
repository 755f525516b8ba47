"""The panel's statistics lines (visrad_addon/ui.py stats_lines): what a user reads after each stage."""

import pytest

pytest.importorskip("bpy")

from visrad.visrad_addon.ui import stats_lines  # noqa: E402

SOLVED = {
    "lit": True, "iterations": 3, "converged": False, "links": 12345, "vertices": 678, "leaf_triangles": 1234,
    "skeleton": {"nodes": {"VV": 10, "VEE": 5}, "arcs": {"EV": 30}},
    "discontinuities_inserted": 40, "discontinuities_available": 90,
}  # fmt: skip


def test_refined_solution_lines():
    lines = stats_lines(SOLVED, max_iterations=10)
    assert lines[0] == "Refinement: 3 of 10 iterations, not converged"
    assert "Skeleton: 15 nodes, 30 arcs" in lines
    assert "Discontinuities: 40 inserted of 90 found" in lines
    assert "Links: 12,345" in lines


def test_indirect_discontinuities_are_said_when_there_are_some():
    lines = stats_lines({**SOLVED, "discontinuities_indirect": 7}, max_iterations=10)
    assert "Discontinuities: 40 inserted of 90 found (7 indirect)" in lines
    assert "Discontinuities: 40 inserted of 90 found" in stats_lines({**SOLVED, "discontinuities_indirect": 0})
