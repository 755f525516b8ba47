"""Tests of bench/common.py's thread_throughput: threads that wait on nothing shared do `threads` times the work
of one in the same wall time; threads serialised by one lock (as by the GIL) do the work of one."""

import threading
import time

import pytest

from bench.common import thread_throughput

NAP_SECONDS = 0.05


def _nap():
    """Wall time without CPU and without the GIL: as many threads as wanted run it side by side."""
    time.sleep(NAP_SECONDS)


_SERIAL = threading.Lock()


def _nap_holding_a_lock():
    """Wall time spent holding one lock, as pure Python holds the GIL: threads running it take turns. (Counting
    in pure Python was the first stand-in: on this shared VM two threads of it measured anywhere from 0.6 to 1.9
    times one thread's work, the single thread's time as noisy as the pair's.)"""
    with _SERIAL:
        time.sleep(NAP_SECONDS)


def test_work_released_from_the_gil_scales_with_the_threads():
    assert thread_throughput(_nap, 2) == pytest.approx(2.0, rel=0.1)
    assert thread_throughput(_nap, 3) == pytest.approx(3.0, rel=0.1)


def test_serialised_work_is_done_by_one_thread_at_a_time():
    assert thread_throughput(_nap_holding_a_lock, 2) == pytest.approx(1.0, rel=0.1)
    assert thread_throughput(_nap_holding_a_lock, 3) == pytest.approx(1.0, rel=0.1)


def test_threads_must_be_positive():
    with pytest.raises(ValueError, match="threads must be >= 1, got 0"):
        thread_throughput(_nap, 0)
