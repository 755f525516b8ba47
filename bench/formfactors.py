"""Benchmark `formfactors`: what exactness buys (Durand et al. 1999, section 4.2.1, Fig. 10).

Part 1, accuracy: on the Desk scene, form factors from points spread over every receiving surface to both large
lights, exact (visible-region Lambert sum) against jittered ray casting with 4, 16, 36, 64 and 256 rays:
mean and max relative error, microseconds per form factor, and the fitted convergence order of the mean error
(the paper reports about 10 % at 36 rays and O(n^-3/4)).
Part 2, throughput: exact form factors from 10 000 points to one light of the 1488-polygon office, blockers from
the whole scene; numba compile (or cache load) time is reported separately from the steady-state rate.

    python -m bench formfactors [--points N] [--throughput-points N] [--seed S]
"""

import argparse
import time

import numpy as np

from core.raycast import jittered_form_factors
from core.visibility import exact_form_factors, scene_bvh

from .common import Stopwatch, peak_memory_bytes, print_table, write_results
from .scenes import SCENES

RAYS = (4, 16, 36, 64, 256)


def surface_points(scene, count: int, rng, exclude=()):
    """Area-weighted random points on the scene's polygons (excluding `exclude`), with their normals."""
    weights = scene.areas.copy()
    weights[list(exclude)] = 0.0
    chosen = rng.choice(scene.n_polygons, size=count, p=weights / weights.sum())
    points = np.empty((count, 3))
    for i, polygon in enumerate(chosen):
        corners = scene.polygon(polygon)
        # uniform in a fan triangle picked by area
        a = corners[0]
        b, c = corners[1:-1], corners[2:]
        areas = np.linalg.norm(np.cross(b - a, c - a), axis=1)
        t = rng.choice(len(areas), p=areas / areas.sum())
        r1, r2 = rng.random(2)
        if r1 + r2 > 1.0:
            r1, r2 = 1.0 - r1, 1.0 - r2
        points[i] = a + r1 * (b[t] - a) + r2 * (c[t] - a)
    return points, scene.normals[chosen].copy(), chosen


def accuracy(points_count: int, seed: int):
    spec = SCENES["desk"]()
    scene = spec.build()
    bvh = scene_bvh(scene)
    lights = [int(i) for i in np.argsort(-scene.areas[scene.lights])[:2]]
    lights = [int(scene.lights[i]) for i in lights]
    rng = np.random.default_rng(seed)
    points, normals, _ = surface_points(scene, points_count, rng, exclude=scene.lights)

    # the first calls compile the numba kernels (or load them from numba's cache)
    with Stopwatch() as exact_compile:
        exact_form_factors(scene, points[:2], normals[:2], lights[0], bvh=bvh)
    with Stopwatch() as jittered_compile:
        for rays in RAYS:
            jittered_form_factors(scene, bvh, points[:2], normals[:2], lights[0], rays, seed=seed)

    exact = []
    with Stopwatch() as exact_time:
        for light in lights:
            exact.append(exact_form_factors(scene, points, normals, light, bvh=bvh))
    exact = np.concatenate(exact)
    seen = exact > 1e-6 * exact.max()
    rows = [
        {
            "method": "exact",
            "rays": 0,
            "mean_rel_error": 0.0,
            "max_rel_error": 0.0,
            "us_per_ff": 1e6 * exact_time.seconds / len(exact),
        }
    ]
    for rays in RAYS:
        estimates = []
        with Stopwatch() as ray_time:
            for light in lights:
                estimates.append(jittered_form_factors(scene, bvh, points, normals, light, rays, seed=seed + rays))
        estimates = np.concatenate(estimates)
        relative = np.abs(estimates[seen] - exact[seen]) / exact[seen]
        rows.append(
            {
                "method": "jittered",
                "rays": rays,
                "mean_rel_error": float(relative.mean()),
                "max_rel_error": float(relative.max()),
                "us_per_ff": 1e6 * ray_time.seconds / len(estimates),
            }
        )
    errors = np.array([r["mean_rel_error"] for r in rows[1:]])
    slope = float(np.polyfit(np.log(RAYS), np.log(errors), 1)[0])
    meta = {
        "scene": "desk",
        "polygons": scene.n_polygons,
        "lights": lights,
        "points": points_count,
        "pairs": int(len(exact)),
        "pairs_with_light": int(seen.sum()),
        "convergence_order": slope,
        "exact_compile_or_cache_seconds": exact_compile.seconds,
        "jittered_compile_or_cache_seconds": jittered_compile.seconds,
    }
    return rows, meta


def throughput(points_count: int, seed: int):
    spec = SCENES["office-1488"]()
    scene = spec.build()
    light = int(scene.lights[np.argmax(scene.areas[scene.lights])])
    rng = np.random.default_rng(seed)
    points, normals, _ = surface_points(scene, points_count, rng, exclude=scene.lights)
    with Stopwatch() as bvh_time:
        bvh = scene_bvh(scene)
    with Stopwatch() as run:
        values = exact_form_factors(scene, points, normals, light, bvh=bvh)
    return {
        "scene": "office-1488",
        "polygons": scene.n_polygons,
        "light": light,
        "points": points_count,
        "nonzero": int(np.count_nonzero(values)),
        "bvh_seconds": bvh_time.seconds,
        "seconds": run.seconds,
        "form_factors_per_second": points_count / run.seconds,
    }


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench formfactors", description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=2000, help="receiver points on the Desk scene")
    parser.add_argument("--throughput-points", type=int, default=10000, help="points for the office-1488 run")
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)

    started = time.perf_counter()
    rows, meta = accuracy(args.points, args.seed)
    print_table(
        rows,
        ["method", "rays", "mean_rel_error", "max_rel_error", "us_per_ff"],
        title=f"Desk ({meta['polygons']} polygons), {meta['pairs_with_light']} lit point-light pairs "
        f"of {meta['pairs']}: exact vs jittered ray casting",
    )
    print(f"fitted convergence order of the mean error: n^{meta['convergence_order']:.2f}")
    print(
        f"numba compile (or cache load) at first call: exact {meta['exact_compile_or_cache_seconds']:.2f} s, "
        f"jittered {meta['jittered_compile_or_cache_seconds']:.2f} s"
    )
    speed = throughput(args.throughput_points, args.seed)
    print()
    print_table(
        [speed],
        ["scene", "polygons", "points", "nonzero", "bvh_seconds", "seconds", "form_factors_per_second"],
        title="Exact form factors to one light, blockers from the whole scene",
    )
    print(f"peak memory {peak_memory_bytes() / 2**20:.0f} MiB, total {time.perf_counter() - started:.1f} s")
    write_results("formfactors", rows, accuracy=meta, throughput=speed)
    return 0
