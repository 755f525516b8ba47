"""Benchmark `hierarchy`: build about 100 000 leaf triangles of hierarchical triangulations (issue 4).

A room (6 quads) with boxes on the floor. Steps as in seed 000 section 6: light maxima and a regular grid,
a second grid level, then discontinuity segments (short crossing segments around the boxes' feet) and
points. Prints one row per step and writes bench/results/hierarchy.json. Target: <= 10 s in total.

usage: python -m bench hierarchy [--spacing S] [--segments N] [--seed K]
"""

import argparse

import numpy as np

from bench.common import Stopwatch, peak_memory_bytes, print_table, write_results
from core.hierarchy import GridSettings, Hierarchy
from core.tolerance import Tolerance


def box(x0, y0, x1, y1, height):
    """The five visible faces of a box resting on the floor z = 0 (counter-clockwise seen from outside)."""
    c = {
        "a": (x0, y0, 0.0), "b": (x1, y0, 0.0), "c": (x1, y1, 0.0), "d": (x0, y1, 0.0),
        "A": (x0, y0, height), "B": (x1, y0, height), "C": (x1, y1, height), "D": (x0, y1, height),
    }
    faces = ["ABCD", "abBA", "bcCB", "cdDC", "daAD"]
    return [np.array([c[k] for k in f]) for f in faces]


def room_scene():
    """A 6 x 4 x 3 room seen from inside, with three boxes: 21 convex polygons."""
    x, y, z = 6.0, 4.0, 3.0
    c = {
        "a": (0, 0, 0), "b": (x, 0, 0), "c": (x, y, 0), "d": (0, y, 0),
        "A": (0, 0, z), "B": (x, 0, z), "C": (x, y, z), "D": (0, y, z),
    }
    faces = ["abcd", "DCBA", "aABb", "bBCc", "cCDd", "dDAa"]
    polygons = [np.array([c[k] for k in f], dtype=float) for f in faces]
    polygons += box(1.0, 1.0, 2.0, 1.8, 0.8) + box(3.5, 2.0, 4.7, 3.2, 1.2) + box(2.5, 0.4, 3.0, 0.9, 0.5)
    return polygons


def floor_discontinuities(rng, count):
    """Short segments (count, 2, 3) on the floor near the boxes, as shadow boundaries would be."""
    feet = np.array([[1.5, 1.4], [4.1, 2.6], [2.75, 0.65]])
    centres = feet[rng.integers(len(feet), size=count)] + rng.normal(scale=0.6, size=(count, 2))
    centres = np.clip(centres, 0.05, [5.95, 3.95])
    angle = rng.uniform(0.0, np.pi, count)
    half = rng.uniform(0.05, 0.3, count)[:, None] * np.stack([np.cos(angle), np.sin(angle)], axis=1)
    ends = np.stack([centres - half, centres + half], axis=1)
    return np.concatenate([ends, np.zeros((count, 2, 1))], axis=2)


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench hierarchy", description=__doc__.splitlines()[0])
    parser.add_argument("--spacing", type=float, default=0.0155, help="grid step relative to the scene")
    parser.add_argument("--segments", type=int, default=900, help="discontinuity segments on the floor")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    polygons = room_scene()
    tolerance = Tolerance.for_points(np.concatenate(polygons))
    rows = []

    def record(step, seconds, report):
        rows.append({"step": step, "seconds": seconds, "subdivided": report.subdivided,
                     "anchored": report.anchored, "vertices": report.vertices, "leaves": report.leaves})

    with Stopwatch() as total:
        with Stopwatch() as sw:
            h = Hierarchy(polygons, tolerance, GridSettings(target_spacing_relative=args.spacing, max_divisions=64))
            maxima = np.array([[3.0, 2.0, 0.0], [1.2, 3.0, 0.0]])
            h.insert_points(0, maxima)
            h.queue_regular_grid(np.arange(len(polygons)))
            report = h.complete_step()
        record("maxima + grid level 1", sw.seconds, report)
        with Stopwatch() as sw:
            h.queue_regular_grid(h.leaves(), GridSettings(target_spacing_relative=0.0, max_divisions=2))
            report = h.complete_step()
        record("grid level 2", sw.seconds, report)
        with Stopwatch() as sw:
            h.insert_segments(0, floor_discontinuities(rng, args.segments))
            report = h.complete_step()
        record("discontinuities", sw.seconds, report)
    with Stopwatch() as sw:
        stats = h.statistics()
    print_table(rows, ["step", "seconds", "subdivided", "anchored", "vertices", "leaves"],
                title=f"hierarchy: {len(polygons)} polygons")
    print(f"total build {total.seconds:.2f} s for {stats.leaves} leaf triangles "
          f"({1e6 * total.seconds / stats.leaves:.1f} us per leaf); statistics {sw.seconds:.2f} s")
    print(f"hierarchy memory {stats.memory_bytes / 2**20:.1f} MiB, peak RSS {peak_memory_bytes() / 2**20:.1f} MiB")
    print(f"smallest angles: all leaves {stats.min_angle_histogram.tolist()}, "
          f"free {stats.free_min_angle_histogram.tolist()}")
    write_results("hierarchy", rows, total_seconds=total.seconds, leaves=stats.leaves, polygons=len(polygons),
                  statistics=stats.as_dict(), target_seconds=10.0)
    return 0
