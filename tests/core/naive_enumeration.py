"""Brute-force node enumeration of the Visibility Skeleton: the reference for core.skeleton.enumeration.

Every candidate line of seed 003 sections 3.2.1-3.2.2, by exhaustive loops with no pruning at all (no
occlusion, no local visibility, no grids), for scenes of a few dozen polygons:

* VV: every pair of generator vertices (coincident ones define no line);
* VEE: every generator vertex v and every pair of generator edges not incident to v, the line through v in
  the two planes (v, edge), kept when it meets both segments (within tol);
* E4: every 4-set of generator edges with 8 distinct vertices; the transversals of their four lines are the
  lines of the 2-dimensional null space of the Pluecker incidence system that lie on the Klein quadric (a
  quadratic), kept when they meet all four segments (within tol). This is a different computation from
  core's (a bilinear elimination on two of the edges), so the two do not share mistakes;
* FEE (section 3.2.3): every polygon, every pair of generator edges crossing its plane and every pair of its
  own generator edges, the line through the two crossings kept when it crosses both own edges inside them
  (core clips the line against the polygon instead).

Thresholds come from scene.tol (tol.length for lengths, tol.cosine for relative degeneracy). Plain numpy;
nothing from core.skeleton but the NodeCandidates record and its kind codes.
"""

from __future__ import annotations

import itertools

import numpy as np

from core.scene import EDGE_FLAT, VERTEX_SILHOUETTE, Scene
from core.skeleton.candidates import CANDIDATE_E4, CANDIDATE_FEE, CANDIDATE_VEE, CANDIDATE_VV, NodeCandidates


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


def naive_fee(scene: Scene, edge_mask: np.ndarray) -> NodeCandidates:
    """For every polygon f, every pair of masked edges crossing f's plane strictly (both ends farther than tol
    from it, on either side) and bounding no common polygon, and every pair of masked edges of f: the line
    through the two crossing points,
    kept when it passes through the inside of both edges of f (farther than tol from their ends)."""
    tol = scene.tol.length
    a_all = scene.vertices[scene.edges[:, 0]]
    b_all = scene.vertices[scene.edges[:, 1]]
    parts = []
    for f in range(scene.n_polygons):
        height_a = a_all @ scene.normals[f] + scene.plane_offsets[f]
        height_b = b_all @ scene.normals[f] + scene.plane_offsets[f]
        strict = (np.abs(height_a) > tol) & (np.abs(height_b) > tol)
        across = np.flatnonzero(edge_mask & strict & (np.sign(height_a) * np.sign(height_b) < 0))
        own = scene.polygon_edge_ids[scene.polygon_offsets[f] : scene.polygon_offsets[f + 1]]
        own = own[edge_mask[own]]
        if len(across) < 2 or len(own) < 2:
            continue
        share = (height_a[across] / (height_a[across] - height_b[across]))[:, None]
        crossing = a_all[across] + share * (b_all[across] - a_all[across])
        # two edges of one face cross f's plane where the two planes meet (FF lines, not EEE swath ends)
        pairs = np.array(
            [(i, j) for i, j in itertools.combinations(range(len(across)), 2)
             if not _share_face(scene, across[i], across[j])],
            dtype=np.int64,
        ).reshape(-1, 2)
        origin = crossing[pairs[:, 0]]
        d = crossing[pairs[:, 1]] - origin
        length = np.linalg.norm(d, axis=1)
        keep = length > tol
        pairs, origin, d = pairs[keep], origin[keep], d[keep] / length[keep, None]
        for g, h in itertools.combinations(own, 2):
            inside = _meets_inside(scene, origin, d, g) & _meets_inside(scene, origin, d, h)
            count = int(inside.sum())
            edges = np.stack(
                [across[pairs[inside, 0]], across[pairs[inside, 1]], np.full(count, g), np.full(count, h)], axis=1
            )
            parts.append(
                NodeCandidates(
                    kind=np.full(count, CANDIDATE_FEE, dtype=np.int8),
                    vertices=np.full((count, 2), -1, dtype=np.int64),
                    edges=np.sort(edges, axis=1).astype(np.int64),
                    origin=origin[inside],
                    direction=d[inside],
                )
            )
    return NodeCandidates.concatenate(parts)


def _share_face(scene: Scene, e: int, f: int) -> bool:
    faces = scene.edge_faces[scene.edge_face_offsets[e] : scene.edge_face_offsets[e + 1]]
    return bool(np.isin(faces, scene.edge_faces[scene.edge_face_offsets[f] : scene.edge_face_offsets[f + 1]]).any())


def _meets_inside(scene: Scene, origins: np.ndarray, directions: np.ndarray, edge: int) -> np.ndarray:
    """(N,) bool: whether each line, lying in a plane with the segment, crosses it farther than tol from its
    ends (a 2-D line intersection in that plane)."""
    tol = scene.tol.length
    a, b = scene.vertices[scene.edges[edge]]
    along = b - a
    length = np.linalg.norm(along)
    # origin + t d = a + s along: the component across d of (a - origin) + s along vanishes
    w = a - origins
    across_w = w - np.einsum("ij,ij->i", w, directions)[:, None] * directions
    across_e = along - (directions @ along)[:, None] * directions
    ee = np.einsum("ij,ij->i", across_e, across_e)
    ok = ee > (scene.tol.cosine * length) ** 2
    s = -np.einsum("ij,ij->i", across_w, across_e) / np.where(ok, ee, 1.0)
    return ok & (s * length > tol) & ((1.0 - s) * length > tol)


def naive_candidates(scene: Scene, vertex_mask=None, edge_mask=None) -> NodeCandidates:
    """VV, VEE, E4 and FEE candidates of the scene by exhaustive enumeration (masks default to the
    skeleton's)."""
    default_v, default_e = generator_masks(scene)
    vertex_mask = default_v if vertex_mask is None else vertex_mask
    edge_mask = default_e if edge_mask is None else edge_mask
    return NodeCandidates.concatenate(
        [
            naive_vv(scene, vertex_mask),
            naive_vee(scene, vertex_mask, edge_mask),
            naive_e4(scene, edge_mask),
            naive_fee(scene, edge_mask),
        ]
    )
