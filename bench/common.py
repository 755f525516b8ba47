"""Shared benchmark helpers: machine facts, peak memory, a printed table and JSON results."""

import json
import os
import platform
import resource
import threading
import time
from collections.abc import Callable
from pathlib import Path

RESULTS = Path(__file__).parent / "results"


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "python": platform.python_version(),
        "system": platform.platform(),
    }


def thread_throughput(work: Callable[[], object], threads: int, repeats: int = 3) -> float:
    """How many times the work of one thread `threads` threads get done in the same wall time: `work` timed
    alone, then `threads` copies of it started together (best of `repeats` each), threads x alone / together.
    `work` must release the GIL (a nogil numba kernel) to measure the cores: 2.0 from two cores of their own,
    less where two vCPUs share one core's execution units, 1.0 for work serialised by the GIL."""
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")

    def wall(copies: int) -> float:
        runners = [threading.Thread(target=work) for _ in range(copies)]
        start = time.perf_counter()
        for runner in runners:
            runner.start()
        for runner in runners:
            runner.join()
        return time.perf_counter() - start

    alone = min(wall(1) for _ in range(repeats))
    together = min(wall(threads) for _ in range(repeats))
    return threads * alone / together


def peak_memory_bytes() -> int:
    """Peak resident set size of this process so far (Linux reports kilobytes)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


class Stopwatch:
    """`with Stopwatch() as sw: ...` then sw.seconds."""

    def __enter__(self):
        self._start = time.perf_counter()
        self.seconds = 0.0
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self._start
        return False


def print_table(rows: list[dict], columns: list[str], title: str = "") -> None:
    def cell(value):
        if isinstance(value, float):
            return f"{value:.4g}"
        return str(value)

    text = [[cell(r.get(c, "")) for c in columns] for r in rows]
    widths = [max([len(c)] + [len(t[i]) for t in text]) for i, c in enumerate(columns)]
    if title:
        print(title)
    print("  ".join(c.rjust(w) for c, w in zip(columns, widths, strict=True)))
    print("  ".join("-" * w for w in widths))
    for t in text:
        print("  ".join(v.rjust(w) for v, w in zip(t, widths, strict=True)))


def write_results(name: str, rows: list[dict], **extra) -> Path:
    """Write bench/results/<name>.json with the rows, the machine and the peak memory; return the path."""
    RESULTS.mkdir(parents=True, exist_ok=True)
    path = RESULTS / f"{name}.json"
    payload = {
        "benchmark": name,
        "date": time.strftime("%Y-%m-%d %H:%M:%S"),
        "machine": machine(),
        "peak_memory_bytes": peak_memory_bytes(),
        "rows": rows,
        **extra,
    }
    path.write_text(json.dumps(payload, indent=2, default=float) + "\n")
    print(f"results: {path}")
    return path
