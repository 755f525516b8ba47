"""core.skeleton.validation's early rejection against a plain numpy check.

`_pierced_between` rejects a candidate line after casting only the part between its outer generators; it
must answer True only for lines that cross some polygon's interior (well inside it, not near its boundary)
strictly between where they meet their first and last generator. The check here intersects the line with every
polygon in numpy, no BVH, and places the generators from the geometry.
"""

import numpy as np
import pytest

from bench.scenes import SCENES as BENCH_SCENES
from core.bvh import STACK_SIZE, build_bvh
from core.skeleton.candidates import NodeCandidates
from core.skeleton.enumeration import iter_candidates
from core.skeleton.validation import GEN_EDGE, GEN_VERTEX, _pierced_between
from tests.core.naive_enumeration import generator_masks
from tests.core.skeleton_scenes import lamp_table_scene

SCENES = {
    "lamp table": lambda: lamp_table_scene().scene,
    "office-84": lambda: BENCH_SCENES["office-84"]().build(),
}


def _generator_positions(scene, origin, direction, vertices, edges) -> np.ndarray:
    """Where the line origin + t direction (unit) passes nearest to each of its generators: t values."""
    positions = [float((scene.vertices[v] - origin) @ direction) for v in vertices if v >= 0]
    for e in edges:
        if e < 0:
            continue
        a, b = scene.vertices[scene.edges[e]]
        # the point of the line nearest to the edge's line: least squares in (t, s)
        system = np.stack([direction, a - b], axis=1)
        (t, _), *_ = np.linalg.lstsq(system, a - origin, rcond=None)
        positions.append(float(t))
    return np.array(positions)


def _crossed_inside(scene, origin, direction, lo: float, hi: float, inset: float) -> bool:
    """Whether the line crosses some polygon's plane at t in (lo, hi), at a point inside the polygon by more
    than `inset` from each of its sides."""
    for p in range(scene.n_polygons):
        normal = scene.normals[p]
        rate = normal @ direction
        if abs(rate) < 1e-9:
            continue
        t = -(normal @ origin + scene.plane_offsets[p]) / rate
        if not lo < t < hi:
            continue
        point = origin + t * direction
        corners = scene.polygon(p)
        inside = True
        for k in range(len(corners)):
            side = np.cross(corners[(k + 1) % len(corners)] - corners[k], normal)
            side /= np.linalg.norm(side)
            if (point - corners[k]) @ side > -inset:
                inside = False
                break
        if inside:
            return True
    return False


@pytest.mark.parametrize("name", list(SCENES))
def test_early_rejection_only_rejects_lines_blocked_between_their_generators(name):
    scene = SCENES[name]()
    vertex_mask, edge_mask = generator_masks(scene)
    candidates = NodeCandidates.concatenate([c for c, _ in iter_candidates(scene, vertex_mask, edge_mask)])
    bvh = build_bvh(scene)
    tol = scene.tol.length
    rng = np.random.default_rng(3)
    sample = rng.choice(len(candidates), size=min(3000, len(candidates)), replace=False)
    capacity = 4096
    scratch = (np.empty(capacity, np.int64), np.empty(capacity), np.empty(capacity, np.int8),
               np.empty(capacity, np.int64), np.empty(STACK_SIZE, np.int64), np.empty(3), np.empty(3))  # fmt: skip
    rejected = 0
    for c in sample:
        direction = candidates.direction[c] / np.linalg.norm(candidates.direction[c])
        start = candidates.origin[c] - 2.0 * scene.diagonal * direction
        vertices = [v for v in candidates.vertices[c] if v >= 0]
        edges = [e for e in candidates.edges[c] if e >= 0]
        kinds = [GEN_VERTEX] * len(vertices) + [GEN_EDGE] * len(edges)
        ids = vertices + edges
        gk = np.zeros(4, np.int8)
        gid = np.zeros(4, np.int64)
        gk[: len(kinds)] = kinds
        gid[: len(ids)] = ids
        if not _pierced_between(
            scene.polygon_points, scene.polygon_offsets, scene.normals, scene.plane_offsets, *bvh.arrays,
            scene.vertices, scene.edges, gk, gid, len(ids), start, direction, tol, *scratch,
        ):  # fmt: skip
            continue
        rejected += 1
        positions = _generator_positions(scene, start, direction, candidates.vertices[c], candidates.edges[c])
        # a crossing near a generator could be the generator's own contact: require it well inside the span
        assert _crossed_inside(scene, start, direction, positions.min() + 8 * tol, positions.max() - 8 * tol, tol), (
            f"{name}: candidate {c} rejected early, but nothing is crossed between its generators"
        )
    assert rejected > len(sample) // 10, f"{name}: only {rejected} of {len(sample)} rejected early"
