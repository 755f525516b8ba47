"""Benchmark `solve`: the radiosity pipeline end to end on the scenes of seed 000 section 7.2 (issue 5).

For each scene (Desk, Many Lights, Indirect bedroom, Village, Cornell box): total and per-stage seconds, peak
memory, links, leaf triangles, iterations and convergence, discontinuities inserted (and how many of them are
indirect: events of the brightest reflectors). Then the seed 000 Table 1 analogue on one scene:
the final meshing of the exact solve re-gathered with 16, 36 and 64 jittered rays per form factor, time and
error against the exact solution (mean relative error at the vertices brighter than one JND, share of vertices
whose Ward display value differs by more than the JND). Paper figures (195 MHz R10000): Desk 4 min, Many
Lights 10 min 23 s, Bedroom 11 min 10 s. Writes bench/results/solve.json.

usage: python -m bench solve [--scenes desk,many_lights,...] [--max-iterations N] [--rays 16,36,64]
                             [--table1-scene NAME]
"""

import argparse
import time

import numpy as np

from bench import scenes
from bench.common import peak_memory_bytes, print_table, write_results
from core.pipeline import Settings, Solver
from core.pipeline.links import LinkSet
from core.pipeline.perception import luminance, ward_scale_factor

ALL_SCENES = ("cornell_box", "desk", "many_lights", "indirect_bedroom", "village")
PAPER_SECONDS = {"desk": 240.0, "many_lights": 623.0, "indirect_bedroom": 670.0}


def solve_scene(name: str, max_iterations: int) -> tuple[dict, Solver]:
    scene = getattr(scenes, name)().build()
    solver = Solver(scene, Settings(max_iterations=max_iterations))
    started = time.perf_counter()
    result = solver.solve()
    total = time.perf_counter() - started
    stats = result.stats
    row = {
        "scene": name,
        "polygons": scene.n_polygons,
        "lights": len(scene.lights),
        "total_s": total,
        "visibility_s": stats["seconds"].get("build_skeleton", 0.0),
        "coarse_s": stats["seconds"].get("coarse_lighting", 0.0),
        "refine_s": stats["seconds"].get("refine", 0.0),
        "iterations": stats["iterations"],
        "converged": stats["converged"],
        "links": stats["links"],
        "leaf_triangles": stats["leaf_triangles"],
        "discontinuities": stats["discontinuities_inserted"],
        "indirect_disc": stats["discontinuities_indirect"],
        "peak_MiB": peak_memory_bytes() / 2**20,
        "paper_s": PAPER_SECONDS.get(name, ""),
    }
    return row, solver


def rays_against_exact(solver: Solver, ray_counts: list[int]) -> list[dict]:
    """Re-gather the exact solve's final mesh with jittered-ray form factors; error against exact."""
    state = solver.lighting
    exact = state.radiosity[0::2]
    average = luminance(state.sources[0::2].mean(axis=0), solver.settings.luminous_efficacy)
    sf = ward_scale_factor(float(average), solver.settings.display_max_luminance)
    # relative errors where the radiosity is perceptible: below one JND (contact-hidden vertices, points on a
    # shadow boundary seeing a sliver of the light) a relative error says nothing
    lit = exact @ np.array([0.2126, 0.7152, 0.0722]) > state.threshold
    rows = []
    for rays in ray_counts:
        other = Solver(solver.scene, Settings(max_iterations=0, form_factors=rays))
        other.build_skeleton()
        parts: list[LinkSet] = []
        started = time.perf_counter()
        for _ in other._link_new_vertices(state.hierarchy, parts, 0):
            pass
        lighting = other._gathered(state.hierarchy, LinkSet.concatenate(parts))
        seconds = time.perf_counter() - started
        approx = lighting.radiosity[0::2]
        relative = np.abs(approx[lit] - exact[lit]).max(axis=1) / exact[lit].max(axis=1)
        display = sf * np.abs(
            luminance(approx, solver.settings.luminous_efficacy) - luminance(exact, solver.settings.luminous_efficacy)
        )
        rows.append({
            "form_factors": f"{rays} rays",
            "seconds": seconds,
            "mean_relative_error": float(relative.mean()),
            "beyond_jnd": float(np.mean(display > solver.settings.jnd)),
        })  # fmt: skip
    return rows


def main(argv) -> int:
    parser = argparse.ArgumentParser(prog="bench solve", description=__doc__.split("\n\n")[0])
    parser.add_argument("--scenes", default=",".join(ALL_SCENES))
    parser.add_argument("--max-iterations", type=int, default=4)
    parser.add_argument("--rays", default="16,36,64")
    parser.add_argument("--table1-scene", default="cornell_box")
    args = parser.parse_args(argv)
    names = [n for n in args.scenes.split(",") if n]
    unknown = [n for n in names if n not in ALL_SCENES]
    if unknown:
        parser.error(f"unknown scenes {unknown}; choose among {', '.join(ALL_SCENES)}")
    rows = []
    table1 = []
    for name in names:
        row, solver = solve_scene(name, args.max_iterations)
        rows.append(row)
        print_table([row], list(row), title=f"solve-{name}")
        if name == args.table1_scene and args.rays:
            exact_row = {"form_factors": "exact", "seconds": row["coarse_s"] + row["refine_s"],
                         "mean_relative_error": 0.0, "beyond_jnd": 0.0}  # fmt: skip
            table1 = [exact_row] + rays_against_exact(solver, [int(r) for r in args.rays.split(",")])
    print_table(rows, list(rows[0]), title="solve: the pipeline per scene")
    if table1:
        print_table(table1, list(table1[0]), title=f"exact vs jittered rays on the {args.table1_scene} meshing")
    write_results("solve", rows, table1=table1, table1_scene=args.table1_scene, max_iterations=args.max_iterations)
    return 0
