"""Brute-force node enumeration of the Visibility Skeleton: the reference for core.skeleton.enumeration.

Every candidate line of seed 003 sections 3.2.1-3.2.2, by exhaustive loops with no pruning at all (no
occlusion, no local visibility, no grids), for scenes of a few dozen polygons:

* VV: every pair of generator vertices (coincident ones define no line);
* VEE: every generator vertex v and every pair of generator edges not incident to v, the line through v in
  the two planes (v, edge), kept when it meets both segments (within tol);
* E4: every 4-set of generator edges with 8 distinct vertices; the transversals of their four lines are the
  lines of the 2-dimensional null space of the Pluecker incidence system that lie on the Klein quadric (a
  quadratic), kept when they meet all four segments (within tol). This is a different computation from
  core's (a bilinear elimination on two of the edges), so the two do not share mistakes.

Thresholds come from scene.tol (tol.length for lengths, tol.cosine for relative degeneracy). Plain numpy;
nothing from core.skeleton but the NodeCandidates record and its kind codes.
"""

from __future__ import annotations

import itertools

import numpy as np

from core.scene import EDGE_FLAT, VERTEX_SILHOUETTE, Scene
from core.skeleton.candidates import CANDIDATE_E4, CANDIDATE_VEE, CANDIDATE_VV, NodeCandidates


def room_scene(n_boxes: int = 1, seed: int = 0, closed: bool = True) -> Scene:
    """The team's development scene: a 4.3 x 3.7 x 2.9 room (closed, inward faces; or only its floor), a
    0.7 x 0.6 light facing down under the ceiling, and `n_boxes` boxes turned by random yaw and pitch."""
    rng = np.random.default_rng(seed)
    vertices: list[np.ndarray] = []
    polygons: list[list[int]] = []
    emission: list[float] = []
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]

    def corners(lo, hi):
        return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])

    def add(points, faces, exitance=0.0):
        base = sum(len(v) for v in vertices)
        vertices.append(np.asarray(points, dtype=np.float64))
        polygons.extend([[base + i for i in face] for face in faces])
        emission.extend([exitance] * len(faces))

    room = corners(np.zeros(3), np.array([4.3, 3.7, 2.9]))
    if closed:
        add(room, [face[::-1] for face in quads])
    else:
        add(room, [[0, 4, 6, 2]])
    add([[1.4, 1.9, 2.8], [2.1, 1.9, 2.8], [2.1, 2.5, 2.8], [1.4, 2.5, 2.8]], [[0, 3, 2, 1]], 10.0)
    for _ in range(n_boxes):
        centre = np.array([rng.uniform(1, 3), rng.uniform(1, 3), rng.uniform(0.8, 2.0)])
        half = rng.uniform(0.3, 0.8, 3) / 2.0
        yaw, pitch = rng.uniform(0, 6.28), rng.uniform(-0.5, 0.5)
        cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
        turn = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cp, -sp], [0, sp, cp]])
        add(corners(-half, half) @ turn.T + centre, quads)
    count = len(polygons)
    return Scene.from_polygons(
        np.concatenate(vertices), polygons, np.full((count, 3), 0.5), np.repeat(np.array(emission)[:, None], 3, 1)
    )


def generator_masks(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """(vertex_mask (V,), edge_mask (E,)): the vertices and edges that may generate nodes (as the skeleton)."""
    return scene.vertex_kind == VERTEX_SILHOUETTE, scene.edge_kind != EDGE_FLAT


def _meets(scene: Scene, origins: np.ndarray, directions: np.ndarray, edge_ids: np.ndarray) -> np.ndarray:
    """(N,) bool: whether each line origins[i] + t directions[i] passes within tol of segment edge_ids[i]."""
    tol = scene.tol.length
    a = scene.vertices[scene.edges[edge_ids, 0]]
    b = scene.vertices[scene.edges[edge_ids, 1]]
    along = b - a
    normal = np.cross(directions, along)
    nn = np.einsum("ij,ij->i", normal, normal)
    ok = nn > 0.0
    safe = np.where(ok, nn, 1.0)
    w = a - origins
    gap = np.abs(np.einsum("ij,ij->i", w, normal)) / np.sqrt(safe)
    s = np.einsum("ij,ij->i", np.cross(w, directions), normal) / safe
    length = np.linalg.norm(along, axis=1)
    return ok & (gap <= tol) & (s * length >= -tol) & ((s - 1.0) * length <= tol)


def naive_vv(scene: Scene, vertex_mask: np.ndarray) -> NodeCandidates:
    """Every pair v < w of masked vertices at distinct positions."""
    ids = np.flatnonzero(vertex_mask)
    pairs = np.array(list(itertools.combinations(ids, 2)), dtype=np.int64).reshape(-1, 2)
    d = scene.vertices[pairs[:, 1]] - scene.vertices[pairs[:, 0]]
    length = np.linalg.norm(d, axis=1)
    keep = length > scene.tol.length
    pairs, d, length = pairs[keep], d[keep], length[keep]
    count = len(pairs)
    return NodeCandidates(
        kind=np.full(count, CANDIDATE_VV, dtype=np.int8),
        vertices=pairs,
        edges=np.full((count, 4), -1, dtype=np.int64),
        origin=scene.vertices[pairs[:, 0]].copy(),
        direction=d / length[:, None],
    )


def naive_vee(scene: Scene, vertex_mask: np.ndarray, edge_mask: np.ndarray) -> NodeCandidates:
    """For every masked vertex v, every pair of masked edges not incident to v whose planes through v cut in a
    line meeting both segments."""
    edges = np.flatnonzero(edge_mask)
    pairs = np.array(list(itertools.combinations(edges, 2)), dtype=np.int64).reshape(-1, 2)
    parts = []
    for v in np.flatnonzero(vertex_mask):
        incident = np.any(scene.edges[pairs] == v, axis=(1, 2))
        chosen = pairs[~incident]
        p = scene.vertices[v]
        planes = []
        for k in range(2):
            a = scene.vertices[scene.edges[chosen[:, k], 0]] - p
            b = scene.vertices[scene.edges[chosen[:, k], 1]] - p
            planes.append(np.cross(a, b))
        d = np.cross(planes[0], planes[1])
        size = np.linalg.norm(d, axis=1)
        scale = np.linalg.norm(planes[0], axis=1) * np.linalg.norm(planes[1], axis=1)
        keep = size > scene.tol.cosine * scale
        chosen, d = chosen[keep], d[keep] / size[keep, None]
        origins = np.repeat(p[None], len(chosen), axis=0)
        keep = _meets(scene, origins, d, chosen[:, 0]) & _meets(scene, origins, d, chosen[:, 1])
        count = int(keep.sum())
        parts.append(
            NodeCandidates(
                kind=np.full(count, CANDIDATE_VEE, dtype=np.int8),
                vertices=np.stack([np.full(count, v, dtype=np.int64), np.full(count, -1, dtype=np.int64)], axis=1),
                edges=np.concatenate([chosen[keep], np.full((count, 2), -1, dtype=np.int64)], axis=1),
                origin=origins[keep],
                direction=d[keep],
            )
        )
    return NodeCandidates.concatenate(parts)


def naive_e4(scene: Scene, edge_mask: np.ndarray, batch: int = 100_000) -> NodeCandidates:
    """Every 4-set of masked edges with 8 distinct vertices and each transversal line meeting the 4 segments."""
    edges = np.flatnonzero(edge_mask)
    # Pluecker coordinates in a frame centred on the scene and scaled by its diagonal (well conditioned)
    centre = 0.5 * (scene.bbox_min + scene.bbox_max)
    a = (scene.vertices[scene.edges[:, 0]] - centre) / scene.diagonal
    b = (scene.vertices[scene.edges[:, 1]] - centre) / scene.diagonal
    direction = b - a
    moment = np.cross(a, direction)
    # a line (d, m) meets edge line i when d . m_i + m . d_i = 0
    rows = np.concatenate([moment, direction], axis=1)
    combos = itertools.combinations(edges, 4)
    parts = []
    while True:
        quads = np.array(list(itertools.islice(combos, batch)), dtype=np.int64).reshape(-1, 4)
        if len(quads) == 0:
            break
        ends = np.sort(scene.edges[quads].reshape(len(quads), 8), axis=1)
        quads = quads[np.all(ends[:, 1:] != ends[:, :-1], axis=1)]
        if len(quads):
            parts.append(_transversal_candidates(scene, quads, rows[quads], centre))
    return NodeCandidates.concatenate(parts)


def _transversal_candidates(scene: Scene, quads: np.ndarray, system: np.ndarray, centre: np.ndarray):
    _, sigma, vt = np.linalg.svd(system)
    # rank 4 exactly: a pencil of solutions (rank 3 or less: infinitely many transversals, no node)
    full = sigma[:, 3] > scene.tol.cosine * sigma[:, 0]
    quads, vt = quads[full], vt[full]
    p = vt[:, 4]
    q = vt[:, 5]

    def klein(x, y):
        return 0.5 * (np.einsum("ij,ij->i", x[:, :3], y[:, 3:]) + np.einsum("ij,ij->i", y[:, :3], x[:, 3:]))

    qa, qb, qc = klein(q, q), 2.0 * klein(p, q), klein(p, p)
    scale = np.maximum.reduce([np.abs(qa), np.abs(qb), np.abs(qc)])
    # the whole pencil on the quadric: infinitely many transversals
    pencil = scale > scene.tol.cosine
    disc = qb * qb - 4.0 * qa * qc
    results = []
    root = np.sqrt(np.maximum(disc, 0.0))
    use_mu = np.abs(qa) >= np.abs(qc)
    lead = np.where(use_mu, qa, qc)
    for sign in (1.0, -1.0):
        # homogeneous roots mu p + nu q of qc mu^2 + qb mu nu + qa nu^2 = 0: with mu = 1 when |qa| >= |qc|
        # (nu = (-qb +- root) / (2 qa)), else nu = 1 (mu = (-qb +- root) / (2 qc))
        valid = pencil & (disc >= 0.0) & (lead != 0.0)
        if sign < 0.0:
            valid &= disc > 0.0  # a double root is one line
        ratio = np.zeros(len(quads))
        ratio[valid] = (-qb[valid] + sign * root[valid]) / (2.0 * lead[valid])
        mu = np.where(use_mu, 1.0, ratio)
        nu = np.where(use_mu, ratio, 1.0)
        line = mu[:, None] * p + nu[:, None] * q
        d = line[:, :3]
        m = line[:, 3:]
        dd = np.einsum("ij,ij->i", d, d)
        valid &= dd > 0.0
        safe = np.where(valid, dd, 1.0)
        origin = np.cross(d, m) / safe[:, None] * scene.diagonal + centre
        unit = d / np.sqrt(safe)[:, None]
        keep = valid.copy()
        for k in range(4):
            keep[keep] = _meets(scene, origin[keep], unit[keep], quads[keep, k])
        count = int(keep.sum())
        results.append(
            NodeCandidates(
                kind=np.full(count, CANDIDATE_E4, dtype=np.int8),
                vertices=np.full((count, 2), -1, dtype=np.int64),
                edges=np.sort(quads[keep], axis=1),
                origin=origin[keep],
                direction=unit[keep],
            )
        )
    return NodeCandidates.concatenate(results)


def naive_candidates(scene: Scene, vertex_mask=None, edge_mask=None) -> NodeCandidates:
    """VV, VEE and E4 candidates of the scene by exhaustive enumeration (masks default to the skeleton's)."""
    default_v, default_e = generator_masks(scene)
    vertex_mask = default_v if vertex_mask is None else vertex_mask
    edge_mask = default_e if edge_mask is None else edge_mask
    return NodeCandidates.concatenate(
        [naive_vv(scene, vertex_mask), naive_vee(scene, vertex_mask, edge_mask), naive_e4(scene, edge_mask)]
    )
