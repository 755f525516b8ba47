"""Tests of the skeleton benchmark's per-node budget (bench/skeleton.py): a build's CPU time is counted over all
its threads, not its wall time, and what 30x Table 1 leaves per node is Table 1's time over 30, times the cores,
over the nodes built."""

import threading
import time

import pytest

from bench.skeleton import CORES, PAPER_TABLE_1, SPEED_UP_TARGET, construction

BUSY_SECONDS = 0.15
IDLE_SECONDS = 0.3
NODES = {"VV": 600, "E4": 400}


class _StubSkeleton:
    stats = {"nodes": NODES, "arcs": {"EV": 10}, "dangling_arcs": 0, "bytes": 1024, "seconds": 0.0}


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
