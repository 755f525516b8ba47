"""Tests of bench/common.py's thread_throughput: threads that wait on nothing shared do `threads` times the work
of one in the same wall time; threads serialised by the GIL do the work of one."""

import time

import pytest

from bench.common import thread_throughput

NAP_SECONDS = 0.05


def _nap():
    """Wall time without CPU and without the GIL: as many threads as wanted run it side by side."""
    time.sleep(NAP_SECONDS)


def _count_under_the_gil():
    """Pure Python: two threads of it take turns on the GIL."""
    total = 0
    for i in range(300_000):
        total += i
    return total


def test_work_released_from_the_gil_scales_with_the_threads():
    assert thread_throughput(_nap, 2) == pytest.approx(2.0, rel=0.1)
    assert thread_throughput(_nap, 3) == pytest.approx(3.0, rel=0.1)


def test_work_holding_the_gil_is_done_by_one_thread_at_a_time():
    assert thread_throughput(_count_under_the_gil, 2) == pytest.approx(1.0, abs=0.25)


def test_threads_must_be_positive():
    with pytest.raises(ValueError, match="threads must be >= 1, got 0"):
        thread_throughput(_nap, 0)
