"""Benchmark `skeleton`: Visibility Skeleton construction and queries on the office family (seed 003, Table 1).

Per office size (84 ... 1488 polygons, the sizes of Table 1), built --repeats times (3): the median build's seconds
(and the fastest and slowest build's), nodes and arcs by type (whatever keys skel.stats reports), skeleton bytes
(skel.stats['bytes']), the largest peak resident memory of the builds and peak above the resident memory before it
(python, numba, the scene; the C heap's free pages handed back first), and the paper's Table 1 row at that size
(time on a 195 MHz R10000, memory, thousands of nodes and arcs) with our speed-up; the median build's CPU seconds
(all threads) and its CPU microseconds per node, beside what the 30x target leaves per node on this machine's cores
(Table 1's time over 30, times the cores, over our nodes): where the target is missed, how much cheaper a node must
get; the seconds of the index vertex views read (skel.index_views(), made by the first view otherwise; its bytes
count in the skeleton's); and how many times one thread's work the cores do at once (a register-only numba loop
alone, then on every core), measured after the builds: the core count on a quiet machine, less when another job
shared the cores during the run (or vCPUs share a physical core), which makes the run's times too slow to compare
with others. Then the growth exponent of time against polygons (least squares on log-log; the paper: n^2.4), the
lazy build from one source (the first light) against the full build on the largest size (paper, 1488 polygons: 4 min
15 s against 31 min 59 s), and on that skeleton the query costs: form_factor and visible_boundary per vertex view,
discontinuities and blockers per (light, receiver) pair (paper: 1.2-1.5 ms per view, 1.3-28.6 ms per discontinuity
mesh, 4 ms for a blocker list), interactions per polygon (the paper gives no time). Targets of issue 3: at least 30x
faster than Table 1 at every size, at most 416 MB at 1488 polygons, the one-source lazy build at least 5x faster
than the full build there.

    python -m bench skeleton [--sizes 84,168,...] [--quick] [--repeats 3] [--views N] [--pairs N]
                             [--interactions N] [--seed S] [--progress]
    python -m bench skeleton --furnished 200      # issue 3: generated rooms without exception, NaN, dangling arc,
                                                  # their vertex views closed and summing to 1
    python -m bench skeleton --closed 30          # the denser closed rooms of bench.scenes (16 boxes): the same
                                                  # tallies of the builds, dangling arcs room by room
"""

import argparse
import gc
import os
import re
import sys
import time
from pathlib import Path

import numpy as np
from numba import njit

from .common import Stopwatch, peak_memory_bytes, print_table, thread_throughput, write_results
from .scenes import OFFICE_SIZES, SCENES, closed_furnished_room

#: seed 003, Table 1: polygons -> (construction seconds, memory MB, nodes x 1000, arcs x 1000)
PAPER_TABLE_1 = {
    84: (1.71, 1.8, 7, 16),
    168: (12.74, 9.0, 37, 91),
    312: (37.07, 21.0, 69, 165),
    432: (99.0, 55.0, 199, 476),
    756: (336.0, 135.0, 445, 1074),
    1056: (876.0, 242.0, 753, 1836),
    1488: (1919.0, 416.0, 1266, 3087),
}
#: seed 003, section 5: the part of the skeleton for one source of scene (g), 1488 polygons
PAPER_LAZY_SECONDS = 255.0
SPEED_UP_TARGET = 30.0
LAZY_SPEED_UP_TARGET = 5.0
MEMORY_TARGET_MB = 416.0
CORES = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
"""The cores this process may run on: what the 30x target leaves per node is counted on all of them."""

THROUGHPUT_STEPS = 5_000_000
"""Iterations of the calibration loop (about 0.1 s on one thread of a 2.6 GHz AMD EPYC)."""

MB = 2.0**20
_STATUS = Path("/proc/self/status")
_CLEAR_REFS = Path("/proc/self/clear_refs")


@njit(cache=True, nogil=True)
def _calibration_loop(steps: int) -> float:
    """Floating-point work with a data-dependent branch and a square root, in the manner of the skeleton's
    geometric tests, on registers only (no memory traffic): what the cores give, not the memory bus."""
    x, y, z = 0.3, 0.5, 0.7
    total = 0.0
    for _ in range(steps):
        cx = y * 0.7 - z * 0.5
        cy = z * 0.3 - x * 0.7
        cz = x * 0.5 - y * 0.3
        length = np.sqrt(cx * cx + cy * cy + cz * cz) + 1.0
        if cx > cy:
            total += cx / length
        else:
            total -= cy / length
        x, y, z = y, z, x + 1e-9 * total
    return total


def cores_throughput(threads: int = CORES) -> float:
    """How many times one thread's work `threads` threads of this machine do at once (bench.common's
    thread_throughput on _calibration_loop): CORES when each thread has a core to itself."""
    _calibration_loop(1)
    return thread_throughput(lambda: _calibration_loop(THROUGHPUT_STEPS), threads)


def _reset_peak() -> bool:
    """Reset the kernel's resident high-water mark (Linux: 5 > clear_refs), so each build gets its own peak."""
    try:
        _CLEAR_REFS.write_text("5")
        return True
    except OSError:
        return False


def _release_free_heap() -> None:
    """Hand the C heap's free pages back to the system (glibc's malloc_trim; nothing elsewhere) before a build's
    baseline is read: the pages an earlier build freed but the allocator kept would count in the baseline, and
    the build reusing them would seem to need less (office-1488 after the smaller sizes: 350 MB above a baseline
    of 466 MB in one run, 448 MB above 331 MB in another, its peak 816 and 779 MB; 2026-11-28). The skeleton's own
    handle on malloc_trim, trimming at once, not after its growth rule."""
    from core.skeleton import skeleton as skeleton_module

    if skeleton_module._malloc_trim is not None:
        skeleton_module._malloc_trim(0)


def _status_bytes(field: str) -> int | None:
    """A size field of /proc/self/status (VmHWM, VmRSS) in bytes, or None if unreadable."""
    try:
        found = re.search(rf"^{field}:\s+(\d+) kB", _STATUS.read_text(), re.MULTILINE)
    except OSError:
        found = None
    return int(found.group(1)) * 1024 if found else None


def _peak_since_reset() -> int:
    """VmHWM of this process in bytes (the peak since the last reset), or the process peak if unreadable."""
    peak = _status_bytes("VmHWM")
    return peak_memory_bytes() if peak is None else peak


def _progress_printer(label: str):
    """A progress(stage, fraction) callback printing to stderr at most every 5 seconds."""
    last = [0.0]

    def progress(stage: str, fraction: float) -> None:
        now = time.perf_counter()
        if now - last[0] >= 5.0:
            last[0] = now
            print(f"  {label}: {stage} {100.0 * fraction:.0f} %", file=sys.stderr, flush=True)

    return progress


def _build(build_skeleton, scene, label: str, show_progress: bool, sources=None):
    """(skeleton, wall seconds, peak resident bytes: of the build when the kernel lets us reset the high-water
    mark, else of the process so far -- sizes run in increasing order, so the largest size's is still its own;
    resident bytes before the build: python, numba, the scene and what earlier sizes left; CPU seconds of the
    build, all threads).

    The previous skeleton is dropped by the caller before: its memory is not the build's."""
    progress = _progress_printer(label) if show_progress else None
    gc.collect()
    _release_free_heap()
    isolated = _reset_peak()
    before = _status_bytes("VmRSS") or 0
    cpu_before = time.process_time()
    with Stopwatch() as watch:
        skeleton = build_skeleton(scene, sources=sources, progress=progress)
    cpu_seconds = time.process_time() - cpu_before
    return skeleton, watch.seconds, _peak_since_reset() if isolated else peak_memory_bytes(), before, cpu_seconds


def _counts(stats: dict, key: str) -> dict:
    return {str(kind): int(count) for kind, count in dict(stats.get(key, {})).items()}


def construction(build_skeleton, sizes, show_progress: bool, repeats: int = 1):
    """One row per office size, and the (scene, skeleton, seconds) of the largest. Each size is built `repeats`
    times: its seconds and CPU seconds are the medians of the builds (a shared machine's speed moves a single
    build by 10-25 %), with the fastest and slowest build beside them; its memory the largest of their peaks."""
    if repeats < 1:
        raise ValueError(f"repeats must be at least 1, got {repeats}")
    rows = []
    largest = None
    for n in sizes:
        scene = SCENES[f"office-{n}"]().build()
        largest = skeleton = None  # the previous size's skeleton is not part of this build's memory
        builds = []
        for _ in range(repeats):
            skeleton = None
            skeleton, seconds, peak, before, cpu_seconds = _build(build_skeleton, scene, f"office-{n}", show_progress)
            builds.append((seconds, peak, before, cpu_seconds))
        walls = [b[0] for b in builds]
        seconds = float(np.median(walls))
        cpu_seconds = float(np.median([b[3] for b in builds]))
        peak = max(b[1] for b in builds)
        above = max(b[1] - b[2] for b in builds)
        # what vertex views read is made by the first view, not by the build: timed apart, and in the bytes
        with Stopwatch() as indexing:
            skeleton.index_views()
        stats = skeleton.stats
        paper_seconds, paper_mb, paper_nodes, paper_arcs = PAPER_TABLE_1[n]
        nodes, arcs = _counts(stats, "nodes"), _counts(stats, "arcs")
        rows.append(
            {
                "polygons": scene.n_polygons,
                "seconds": seconds,
                "builds": repeats,
                "seconds_min": min(walls),
                "seconds_max": max(walls),
                "stats_seconds": float(stats.get("seconds", float("nan"))),
                "nodes": nodes,
                "arcs": arcs,
                "nodes_total": sum(nodes.values()),
                "arcs_total": sum(arcs.values()),
                "dangling_arcs": int(stats.get("dangling_arcs", 0)),
                "skeleton_mb": float(stats.get("bytes", 0)) / MB,
                "peak_mb": peak / MB,
                "peak_above_baseline_mb": above / MB,
                "paper_seconds": paper_seconds,
                "paper_mb": paper_mb,
                "paper_nodes_k": paper_nodes,
                "paper_arcs_k": paper_arcs,
                "speed_up": paper_seconds / seconds,
                "views_seconds": indexing.seconds,
                "cpu_seconds": cpu_seconds,
                "cpu_us_per_node": 1e6 * cpu_seconds / max(1, sum(nodes.values())),
                "target_cpu_us_per_node": 1e6 * paper_seconds / SPEED_UP_TARGET * CORES / max(1, sum(nodes.values())),
            }
        )
        largest = (n, scene, skeleton, seconds)
    return rows, largest


def growth_exponent(rows) -> float:
    """Least-squares slope of log(seconds) against log(polygons); nan with fewer than two sizes."""
    if len(rows) < 2:
        return float("nan")
    polygons = np.log([r["polygons"] for r in rows])
    seconds = np.log([r["seconds"] for r in rows])
    return float(np.polyfit(polygons, seconds, 1)[0])


def lazy_against_full(build_skeleton, largest, show_progress: bool) -> dict:
    n, scene, _, full_seconds = largest
    light = int(scene.lights[0])
    skeleton, seconds, peak, before, _ = _build(build_skeleton, scene, f"office-{n} lazy", show_progress,
                                                sources=[light])
    return {
        "polygons": scene.n_polygons,
        "source": light,
        "lazy_seconds": seconds,
        "full_seconds": full_seconds,
        "speed_up": full_seconds / seconds,
        "lazy_nodes_total": sum(_counts(skeleton.stats, "nodes").values()),
        "lazy_peak_mb": peak / MB,
        "lazy_peak_above_baseline_mb": (peak - before) / MB,
        "paper_lazy_seconds": PAPER_LAZY_SECONDS if n == 1488 else None,
        "paper_full_seconds": PAPER_TABLE_1[n][0],
    }


def _mean_ms(call, arguments) -> tuple[float, float, int, list[int]]:
    """Mean and largest milliseconds of call(*a) over the argument tuples, how many calls the skeleton refused
    (VisradError: a view that does not close in a degenerate scene; timed all the same), and the length of
    each answer (segments, polygons; -1 when refused or not a sequence)."""
    from core.errors import VisradError

    times = []
    refused = 0
    lengths = []
    for a in arguments:
        start = time.perf_counter()
        try:
            answer = call(*a)
        except VisradError:
            refused += 1
            answer = None
        times.append(time.perf_counter() - start)
        lengths.append(len(answer) if hasattr(answer, "__len__") else -1)
    return 1e3 * float(np.mean(times)), 1e3 * float(np.max(times)), refused, lengths


def query_costs(largest, views: int, pairs: int, interactions: int, seed: int) -> dict:
    """Query times on the largest skeleton: vertex views of every light, (light, receiver) pairs, the
    interactions of `interactions` polygons (the lights first)."""
    n, scene, skeleton, _ = largest
    rng = np.random.default_rng(seed)
    lights = scene.lights
    is_light = np.zeros(scene.n_polygons, dtype=bool)
    is_light[lights] = True
    owner = np.repeat(np.arange(scene.n_polygons), np.diff(scene.polygon_offsets))
    receiving = ~is_light[owner]
    # one receiving polygon per vertex: the first one that uses it
    vertices, first = np.unique(scene.polygon_vertex_ids[receiving], return_index=True)
    receivers_of_vertex = owner[receiving][first]
    chosen = rng.choice(len(vertices), size=min(views, len(vertices)), replace=False)
    view_args = [(int(vertices[i]), int(rng.choice(lights)), int(receivers_of_vertex[i])) for i in chosen]
    receivers = np.flatnonzero(~is_light)
    sampled = rng.choice(receivers, size=min(pairs, len(receivers)), replace=False)
    pair_args = [(int(rng.choice(lights)), int(r)) for r in sampled]
    others = rng.choice(receivers, size=min(max(0, interactions - len(lights)), len(receivers)), replace=False)
    interaction_args = [(int(p),) for p in [*lights[:interactions], *others]]
    # first calls build per-skeleton indexes and compile (or load) the numba kernels of their path, and which
    # kernels a call needs depends on its arguments (EEE traces only where a pair has EEE arcs): one untimed pass
    # over every argument first, so that the timings are the queries' own
    _mean_ms(skeleton.form_factor, view_args)
    _mean_ms(skeleton.visible_boundary, [a[:2] for a in view_args])
    _mean_ms(skeleton.discontinuities, pair_args)
    _mean_ms(skeleton.blockers, pair_args)
    _mean_ms(skeleton.interactions, interaction_args[:1])
    form_factor = _mean_ms(skeleton.form_factor, view_args)
    boundary = _mean_ms(skeleton.visible_boundary, [a[:2] for a in view_args])
    discontinuities = _mean_ms(skeleton.discontinuities, pair_args)
    blockers = _mean_ms(skeleton.blockers, pair_args)
    segments = [k for k in discontinuities[3] if k >= 0]
    interacting = _mean_ms(skeleton.interactions, interaction_args)
    listed = [k for k in interacting[3] if k >= 0]
    return {
        "polygons": scene.n_polygons,
        "views": len(view_args),
        "pairs": len(pair_args),
        "form_factor_ms": form_factor[0],
        "form_factor_max_ms": form_factor[1],
        "form_factor_refused": form_factor[2],
        "visible_boundary_ms": boundary[0],
        "visible_boundary_max_ms": boundary[1],
        "visible_boundary_refused": boundary[2],
        "discontinuities_ms": discontinuities[0],
        "discontinuities_max_ms": discontinuities[1],
        "discontinuity_segments_mean": float(np.mean(segments)) if segments else float("nan"),
        "blockers_ms": blockers[0],
        "blockers_max_ms": blockers[1],
        "interaction_polygons": len(interaction_args),
        "interactions_ms": interacting[0],
        "interactions_max_ms": interacting[1],
        "interactions_listed_mean": float(np.mean(listed)) if listed else float("nan"),
        "paper_view_ms": "1.2-1.5",
        "paper_discontinuities_ms": "1.3-28.6",
        "paper_blockers_ms": 4.0,
    }


def furnished_rooms(build_skeleton, count: int) -> dict:
    """Build the first `count` generated furnished rooms (tests/core/furnished_rooms.py: boxes resting,
    stacked, floating, side by side, against a wall) and query every vertex's view of every polygon in each;
    issue 3 asks for 200 without exception, NaN or dangling arc, and for vertex form factors summing to 1.
    Returns the tallies and the rooms with dangling arcs or refused views."""
    from core.scene import Scene
    from tests.core.furnished_rooms import furnished_room

    failed, with_nan, dangling, refused = {}, [], {}, {}
    seconds, query_seconds = [], []
    queries, worst_sum = 0, 0.0
    for seed in range(count):
        vertices, polygons, _, _ = furnished_room(seed)
        n = len(polygons)
        start = time.perf_counter()
        try:
            scene = Scene.from_polygons(vertices, polygons, np.full((n, 3), 0.5), np.zeros((n, 3)))
            skeleton = build_skeleton(scene)
        except Exception as error:  # noqa: BLE001 -- every failure is what this check counts
            failed[seed] = f"{type(error).__name__}: {error}"
            continue
        seconds.append(time.perf_counter() - start)
        if _has_nan(skeleton):
            with_nan.append(seed)
        if skeleton.stats["dangling_arcs"]:
            dangling[seed] = skeleton.stats["dangling_arcs"]
        start = time.perf_counter()
        asked, not_closed, off_one = _views_in_room(scene, skeleton)
        query_seconds.append(time.perf_counter() - start)
        queries += asked
        worst_sum = max(worst_sum, off_one)
        if not_closed:
            refused[seed] = not_closed
    return {
        "rooms": count,
        "exceptions": len(failed),
        "with_nan": len(with_nan),
        "rooms_with_dangling_arcs": len(dangling),
        "dangling_arcs_total": int(sum(dangling.values())),
        "seconds_mean": float(np.mean(seconds)) if seconds else float("nan"),
        "seconds_total": float(np.sum(seconds)),
        "view_queries": queries,
        "rooms_with_refused_views": len(refused),
        "refused_views_total": int(sum(refused.values())),
        "sum_to_one_worst": worst_sum,
        "query_ms_mean": 1e3 * float(np.sum(query_seconds)) / max(queries, 1),
        "failed": failed,
        "dangling": dangling,
        "refused": refused,
    }


def _has_nan(skeleton) -> bool:
    """Whether a node's line or a linked arc end's coordinate is not finite."""
    linked = skeleton.arcs.node >= 0
    finite = np.isfinite(skeleton.nodes.start).all() and np.isfinite(skeleton.nodes.direction).all()
    return not (finite and np.isfinite(skeleton.arcs.s[linked]).all())


def closed_rooms(build_skeleton, count: int) -> dict:
    """Build `bench.scenes.closed_furnished_room(seed)` for the first `count` seeds (16 boxes on a 5 cm grid:
    denser than the furnished rooms, with more corners meeting on edges and at corners of other boxes) and
    tally exceptions, NaN and dangling arcs, the last room by room."""
    failed, with_nan, dangling = {}, [], {}
    seconds, arcs = [], 0
    for seed in range(count):
        start = time.perf_counter()
        try:
            skeleton = build_skeleton(closed_furnished_room(seed).build())
        except Exception as error:  # noqa: BLE001 -- every failure is what this check counts
            failed[seed] = f"{type(error).__name__}: {error}"
            continue
        seconds.append(time.perf_counter() - start)
        arcs += len(skeleton.arcs)
        if _has_nan(skeleton):
            with_nan.append(seed)
        if skeleton.stats["dangling_arcs"]:
            dangling[seed] = skeleton.stats["dangling_arcs"]
    return {
        "rooms": count,
        "exceptions": len(failed),
        "with_nan": len(with_nan),
        "arcs_total": arcs,
        "rooms_with_dangling_arcs": len(dangling),
        "dangling_arcs_total": int(sum(dangling.values())),
        "seconds_mean": float(np.mean(seconds)) if seconds else float("nan"),
        "failed": failed,
        "dangling": dangling,
    }


def _views_in_room(scene, skeleton) -> tuple[int, int, float]:
    """(queries, refused, worst |sum - 1|): every vertex's view of every polygon, with one polygon using the
    vertex as receiver (whether a view closes does not depend on the receiver), and at the free convex corners
    (tests/core/skeleton_scenes.free_convex_corners) the form factors to all polygons summed, with each face
    of the corner as receiver (DESIGN.md section 5.2)."""
    from core.errors import VisradError
    from tests.core.skeleton_scenes import free_convex_corners

    faces_at = [[] for _ in range(scene.n_vertices)]
    for polygon in range(scene.n_polygons):
        for vertex in scene.polygon_vertices(polygon):
            faces_at[int(vertex)].append(polygon)
    free = free_convex_corners(scene)
    queries, refused, worst = 0, 0, 0.0
    for vertex, faces in enumerate(faces_at):
        for receiver in faces if free[vertex] else faces[:1]:
            total = 0.0
            for source in range(scene.n_polygons):
                queries += 1
                try:
                    total += skeleton.form_factor(vertex, source, receiver)
                except VisradError:
                    refused += 1
                    total = np.nan
            if free[vertex] and np.isfinite(total):
                worst = max(worst, abs(total - 1.0))
    return queries, refused, worst


def _parse_sizes(text: str) -> list[int]:
    try:
        sizes = sorted({int(s) for s in text.split(",") if s.strip()})
    except ValueError:
        raise argparse.ArgumentTypeError(f"--sizes takes comma-separated integers, not {text!r}") from None
    unknown = [s for s in sizes if s not in OFFICE_SIZES]
    if unknown or not sizes:
        raise argparse.ArgumentTypeError(f"office sizes are {', '.join(map(str, OFFICE_SIZES))}; got {text!r}")
    return sizes


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench skeleton", description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=_parse_sizes, default=list(OFFICE_SIZES),
                        help="comma-separated office sizes (default: all seven of Table 1)")
    parser.add_argument("--quick", action="store_true", help="only the first three sizes (84, 168, 312)")
    parser.add_argument("--views", type=int, default=500, help="vertex views timed on the largest size")
    parser.add_argument("--pairs", type=int, default=200, help="(light, receiver) pairs timed on the largest size")
    parser.add_argument("--interactions", type=int, default=10,
                        help="polygons whose interactions are timed on the largest size (the lights first)")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--progress", action="store_true", help="print build progress to stderr")
    parser.add_argument("--repeats", type=int, default=3,
                        help="builds per size: the times are their medians (default 3)")
    parser.add_argument("--furnished", type=int, default=0, metavar="N",
                        help="instead: build N generated furnished rooms, count exceptions, NaN, dangling arcs, "
                             "refused vertex views, and the worst sum of form factors off 1")
    parser.add_argument("--closed", type=int, default=0, metavar="N",
                        help="instead: build the first N closed rooms of bench.scenes.closed_furnished_room, count "
                             "exceptions, NaN and dangling arcs")
    args = parser.parse_args(argv)
    sizes = list(OFFICE_SIZES[:3]) if args.quick else args.sizes

    # imported here: `--help` works before (and without) the skeleton
    try:
        from core.skeleton import build_skeleton
    except ImportError as error:
        print(f"core.skeleton.build_skeleton is not available: {error}", file=sys.stderr)
        return 2

    if args.furnished > 0:
        report = furnished_rooms(build_skeleton, args.furnished)
        print_table([report], ["rooms", "exceptions", "with_nan", "rooms_with_dangling_arcs", "dangling_arcs_total",
                               "seconds_mean", "seconds_total"],
                    title="Generated furnished rooms (touching, stacked, coplanar boxes)")
        print()
        print_table([report], ["view_queries", "rooms_with_refused_views", "refused_views_total", "sum_to_one_worst",
                               "query_ms_mean"],
                    title="Their vertex views (every vertex x every polygon; sums at free convex corners)")
        for seed, message in report["failed"].items():
            print(f"  room {seed}: {message}")
        write_results("skeleton-furnished", [report])
        return 0

    if args.closed > 0:
        report = closed_rooms(build_skeleton, args.closed)
        print_table([report], ["rooms", "exceptions", "with_nan", "arcs_total", "rooms_with_dangling_arcs",
                               "dangling_arcs_total", "seconds_mean"],
                    title="Closed rooms of bench.scenes.closed_furnished_room (16 boxes)")
        for seed, message in report["failed"].items():
            print(f"  room {seed}: {message}")
        print("  dangling arcs by room:", ", ".join(f"{seed}: {n}" for seed, n in report["dangling"].items()) or "none")
        write_results("skeleton-closed", [report])
        return 0

    started = time.perf_counter()
    # the first build and view index compile the numba kernels (or load them from numba's cache)
    with Stopwatch() as warm_up:
        build_skeleton(SCENES["cornell-box"]().build()).index_views()
    if args.repeats < 1:
        print(f"--repeats must be at least 1, got {args.repeats}", file=sys.stderr)
        return 2
    rows, largest = construction(build_skeleton, sizes, args.progress, args.repeats)
    node_kinds = sorted({k for r in rows for k in r["nodes"]})
    arc_kinds = sorted({k for r in rows for k in r["arcs"]})
    table = []
    for r in rows:
        by_kind = {f"node {k}": r["nodes"].get(k, 0) for k in node_kinds}
        by_kind.update({f"arc {k}": r["arcs"].get(k, 0) for k in arc_kinds})
        table.append({**r, **by_kind})
    print_table(
        table,
        ["polygons", "seconds", *[f"node {k}" for k in node_kinds], "nodes_total", *[f"arc {k}" for k in arc_kinds],
         "arcs_total", "dangling_arcs", "skeleton_mb", "peak_mb", "peak_above_baseline_mb", "paper_seconds",
         "paper_mb", "paper_nodes_k", "paper_arcs_k", "speed_up"],
        title="Visibility Skeleton construction on the office family (paper: seed 003 Table 1, 195 MHz R10000)",
    )
    print()
    print_table(table, ["polygons", "builds", "seconds", "seconds_min", "seconds_max", "cpu_seconds", "nodes_total",
                        "cpu_us_per_node", "target_cpu_us_per_node", "speed_up", "views_seconds"],
                title=f"CPU per node, and what {SPEED_UP_TARGET:.0f}x Table 1 leaves per node on {CORES} cores "
                      f"(seconds: the median build)")
    throughput = cores_throughput()
    print(f"{CORES} threads of this machine do {throughput:.2f}x the work of one (a nogil numba loop on registers"
          f"{'' if throughput > 0.9 * CORES else ': another job shares the cores, these times are too slow'})")
    exponent = growth_exponent(rows)
    print(f"growth of construction time: n^{exponent:.2f} (paper: n^2.4); numba warm-up {warm_up.seconds:.1f} s")

    lazy = lazy_against_full(build_skeleton, largest, args.progress)
    print()
    print_table([lazy], ["polygons", "source", "lazy_seconds", "full_seconds", "speed_up", "lazy_nodes_total",
                         "lazy_peak_mb", "lazy_peak_above_baseline_mb", "paper_lazy_seconds", "paper_full_seconds"],
                title="Lazy construction from one source (the first light) against the full build")
    queries = query_costs(largest, args.views, args.pairs, args.interactions, args.seed)
    print()
    print_table([queries], ["polygons", "views", "form_factor_ms", "form_factor_refused", "visible_boundary_ms",
                            "pairs", "discontinuities_ms", "discontinuities_max_ms", "discontinuity_segments_mean",
                            "blockers_ms", "interaction_polygons", "interactions_ms", "interactions_max_ms",
                            "interactions_listed_mean", "paper_view_ms", "paper_discontinuities_ms",
                            "paper_blockers_ms"],
                title="Query costs on the largest skeleton")

    targets = {
        "speed_up_at_every_size": all(r["speed_up"] >= SPEED_UP_TARGET for r in rows),
        "memory_at_1488": next((r["skeleton_mb"] <= MEMORY_TARGET_MB for r in rows if r["polygons"] == 1488), None),
        "build_peak_above_baseline_at_1488": next(
            (r["peak_above_baseline_mb"] <= MEMORY_TARGET_MB for r in rows if r["polygons"] == 1488), None
        ),
        "lazy_speed_up": lazy["speed_up"] >= LAZY_SPEED_UP_TARGET,
    }
    print()
    print(f"targets (issue 3): >= {SPEED_UP_TARGET:.0f}x Table 1 at every size: {targets['speed_up_at_every_size']}; "
          f"skeleton <= {MEMORY_TARGET_MB:.0f} MB at 1488: {targets['memory_at_1488']} (build peak above baseline: "
          f"{targets['build_peak_above_baseline_at_1488']}); lazy >= {LAZY_SPEED_UP_TARGET:.0f}x "
          f"full: {targets['lazy_speed_up']}")
    print(f"process peak memory {peak_memory_bytes() / MB:.0f} MiB, total {time.perf_counter() - started:.1f} s")
    write_results(
        "skeleton", rows, growth_exponent=exponent, lazy=lazy, queries=queries, targets=targets,
        warm_up_seconds=warm_up.seconds, paper_table_1=PAPER_TABLE_1, per_build_peak=_reset_peak(),
        cores=CORES, cores_throughput=throughput,
    )
    return 0
