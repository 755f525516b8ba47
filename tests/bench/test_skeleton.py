"""Tests of the skeleton benchmark (bench/skeleton.py): a build's CPU time is counted over all its threads, not its
wall time, and what 30x Table 1 leaves per node is Table 1's time over 30, times the cores, over the nodes built;
query timings exclude first calls (index building, numba compiling) whichever argument needs them."""

import threading
import time

import pytest

from bench.skeleton import CORES, PAPER_TABLE_1, SPEED_UP_TARGET, construction

BUSY_SECONDS = 0.15
IDLE_SECONDS = 0.3
NODES = {"VV": 600, "E4": 400}


class _StubSkeleton:
    stats = {"nodes": NODES, "arcs": {"EV": 10}, "dangling_arcs": 0, "bytes": 1024, "seconds": 0.0}

    def index_views(self):
        return self


def _busy(seconds: float) -> None:
    start = time.thread_time()
    while time.thread_time() - start < seconds:
        pass


def _stub_build(scene, sources=None, progress=None):
    """Idles, and keeps two threads busy for BUSY_SECONDS of CPU each: a build of 2 x BUSY_SECONDS of CPU."""
    worker = threading.Thread(target=_busy, args=(BUSY_SECONDS,))
    worker.start()
    _busy(BUSY_SECONDS)
    worker.join()
    time.sleep(IDLE_SECONDS)
    return _StubSkeleton()


def test_cpu_per_node_counts_every_thread_and_the_budget_follows_table_1():
    rows, _ = construction(_stub_build, [84], show_progress=False)
    row = rows[0]
    assert row["seconds"] >= IDLE_SECONDS
    # both threads' CPU, and not the idle wall time
    assert 2 * BUSY_SECONDS * 0.95 <= row["cpu_seconds"] < 2 * BUSY_SECONDS + IDLE_SECONDS / 2
    nodes = sum(NODES.values())
    assert row["cpu_us_per_node"] == pytest.approx(1e6 * row["cpu_seconds"] / nodes)
    assert row["target_cpu_us_per_node"] == pytest.approx(1e6 * PAPER_TABLE_1[84][0] / SPEED_UP_TARGET * CORES / nodes)


def test_repeated_builds_report_the_median_build_and_the_largest_peak():
    """Three builds of one size idling 0.05, 0.9 and 0.2 s: the row's seconds are the middle one's (not the
    mean, not the first), the fastest and slowest are kept, and a bad repeat count is refused."""
    idles = iter([0.05, 0.9, 0.2])

    def varying_build(scene, sources=None, progress=None):
        time.sleep(next(idles))
        return _StubSkeleton()

    rows, (_, _, _, largest_seconds) = construction(varying_build, [84], show_progress=False, repeats=3)
    row = rows[0]
    assert row["builds"] == 3
    assert 0.2 <= row["seconds"] < 0.3 and largest_seconds == row["seconds"]
    assert 0.05 <= row["seconds_min"] < 0.15 and 0.9 <= row["seconds_max"] < 1.0
    assert row["speed_up"] == pytest.approx(PAPER_TABLE_1[84][0] / row["seconds"])
    with pytest.raises(ValueError, match="repeats"):
        construction(varying_build, [84], show_progress=False, repeats=0)


FIRST_CALL_SECONDS = 0.03


class _CompilingSkeleton:
    """A skeleton whose query pays FIRST_CALL_SECONDS the first time it sees each argument tuple (as a numba
    kernel compiles on the first call that needs it), then answers at once."""

    def __init__(self):
        self.seen = set()

    def _answer(self, name, *args):
        if (name, args) not in self.seen:
            self.seen.add((name, args))
            time.sleep(FIRST_CALL_SECONDS)
        return [args]

    def form_factor(self, *args):
        return self._answer("form_factor", *args)

    def visible_boundary(self, *args):
        return self._answer("visible_boundary", *args)

    def discontinuities(self, *args):
        return self._answer("discontinuities", *args)

    def blockers(self, *args):
        return self._answer("blockers", *args)

    def interactions(self, *args):
        return self._answer("interactions", *args)


def test_query_timings_exclude_every_first_call():
    """Each query is called once on every one of its arguments before it is timed: no timed call pays for a
    first call, whichever argument needs it (EEE traces compile only for the pairs that have EEE arcs)."""
    from bench.scenes import SCENES
    from bench.skeleton import query_costs

    scene = SCENES["cornell-box"]().build()
    skeleton = _CompilingSkeleton()
    costs = query_costs((scene.n_polygons, scene, skeleton, None), views=12, pairs=8, interactions=1, seed=3)
    assert costs["views"] == 12 and costs["pairs"] == 8
    for query in ("form_factor", "visible_boundary", "discontinuities", "blockers", "interactions"):
        assert costs[f"{query}_max_ms"] < 1e3 * FIRST_CALL_SECONDS / 3, query
    assert len({args for name, args in skeleton.seen if name == "discontinuities"}) == 8


def test_the_baseline_of_a_build_is_read_after_the_free_heap_is_handed_back(monkeypatch):
    import bench.skeleton as benchmark

    events = []
    status = benchmark._status_bytes
    monkeypatch.setattr(benchmark, "_release_free_heap", lambda: events.append("release"))
    monkeypatch.setattr(benchmark, "_status_bytes", lambda field: events.append(field) or status(field))
    construction(lambda scene, sources=None, progress=None: _StubSkeleton(), [84], show_progress=False)
    assert "VmRSS" in events
    assert "release" in events[: events.index("VmRSS")]
