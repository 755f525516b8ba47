"""Benchmark `raycast`: segment occlusion and first-hit throughput of core.raycast on the office family.

    python -m bench raycast [--rays N] [--seed S]

Segments join random points on the scene's surfaces (the queries radiosity makes); first hits start at random
surface points in random directions of the front hemisphere.
"""

import argparse

import numpy as np

from core.bvh import build_bvh
from core.raycast import first_hits, segments_occluded

from .common import Stopwatch, peak_memory_bytes, print_table, write_results
from .formfactors import surface_points
from .scenes import SCENES

SIZES = ("office-84", "office-432", "office-1488")


def measure(name: str, count: int, seed: int) -> dict:
    scene = SCENES[name]().build()
    rng = np.random.default_rng(seed)
    starts, normals, _ = surface_points(scene, count, rng)
    ends, _, _ = surface_points(scene, count, rng)
    directions = rng.normal(size=(count, 3))
    directions *= np.sign(np.einsum("ij,ij->i", directions, normals))[:, None]
    with Stopwatch() as build:
        bvh = build_bvh(scene)
    segments_occluded(scene, bvh, starts[:4], ends[:4])
    first_hits(scene, bvh, starts[:4], directions[:4])
    with Stopwatch() as occlusion:
        blocked = segments_occluded(scene, bvh, starts, ends)
    with Stopwatch() as hits:
        polygon, _, _ = first_hits(scene, bvh, starts, directions)
    return {
        "scene": name,
        "polygons": scene.n_polygons,
        "bvh_ms": 1e3 * build.seconds,
        "segments": count,
        "occluded_fraction": float(blocked.mean()),
        "segments_per_s": count / occlusion.seconds,
        "first_hits_per_s": count / hits.seconds,
        "missed_fraction": float((polygon < 0).mean()),
    }


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench raycast", description=__doc__.splitlines()[0])
    parser.add_argument("--rays", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    rows = [measure(name, args.rays, args.seed) for name in SIZES]
    print_table(
        rows,
        ["scene", "polygons", "bvh_ms", "segments", "occluded_fraction", "segments_per_s", "first_hits_per_s"],
        title="Ray casting on one core (numba, float64)",
    )
    print(f"peak memory {peak_memory_bytes() / 2**20:.0f} MiB")
    write_results("raycast", rows)
    return 0
