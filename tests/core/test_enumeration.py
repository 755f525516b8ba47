"""core.skeleton.enumeration against the brute-force reference (tests/core/naive_enumeration.py).

* No node lost: validation accepts exactly the same nodes (kind and generators) from the fast candidates as
  from the exhaustive ones, on generic rooms, the team's room, a box over an open or closed floor, and the
  lamp-and-table scene (contacts, axis-aligned edges: degenerate alignments everywhere).
* Candidates are well formed: each line meets its generators, generator sets are sorted and padded, no
  candidate twice.
* Lazy construction: with sources=[p], exactly the full set's candidates whose line crosses p (crossing
  checked here, in numpy).
* Scale invariance: the scene scaled by 1e-3 and 1e4 gives the same candidates per kind.
* Chunks: chunk=7 gives the same candidates as one chunk, fractions increase to 1.0; cancel stops.
* The E4 pre-filter's Moebius map (where a line of a family meets its third edge, from s) against that line
  built from two planes.
"""

from __future__ import annotations

import os
from collections import Counter

import numpy as np
import pytest

from bench.scenes import SceneBuilder
from core.bvh import build_bvh
from core.errors import CancelledError, SceneError
from core.scene import Scene
from core.skeleton import validation
from core.skeleton.candidates import (
    CANDIDATE_E4,
    CANDIDATE_FEE,
    CANDIDATE_FXE,
    CANDIDATE_VEE,
    CANDIDATE_VV,
    NodeCandidates,
)  # fmt: skip
from core.skeleton.enumeration import iter_candidates
from core.skeleton.topology import scene_topology
from core.skeleton.validation import validate_candidates
from tests.core.naive_enumeration import generator_masks, naive_candidates, room_scene
from tests.core.skeleton_scenes import box_over_floor_scene, boxes_in_room, generic_closed_room, lamp_table_scene

SCENES = {
    "open floor": lambda: box_over_floor_scene().scene,
    "closed floor": lambda: box_over_floor_scene(closed=True).scene,
    "generic room 0": lambda: generic_closed_room(0, 2).scene,
    "generic room 1": lambda: generic_closed_room(1, 2).scene,
    "generic room 2": lambda: generic_closed_room(2, 3).scene,
    "team room": lambda: room_scene(2, 0),
}


def fast(scene: Scene, **options) -> NodeCandidates:
    vertex_mask, edge_mask = generator_masks(scene)
    return NodeCandidates.concatenate([c for c, _ in iter_candidates(scene, vertex_mask, edge_mask, **options)])


def accepted(scene: Scene, candidates: NodeCandidates) -> Counter:
    """The nodes validation keeps, canonicalised: (node kind, sorted (generator kind, id) pairs), counted."""
    _, edge_mask = generator_masks(scene)
    nodes, _, _ = validate_candidates(scene, scene_topology(scene), build_bvh(scene), candidates, edge_mask)
    return Counter(
        (int(kind), tuple(sorted((int(k), int(g)) for k, g in zip(kinds, ids, strict=True) if k)))
        for kind, kinds, ids in zip(nodes.kind, nodes.gen_kind, nodes.gen_id, strict=True)
    )


def line_keys(candidates: NodeCandidates) -> Counter:
    """Candidates as (kind, vertices, edges, direction up to sign, rounded), counted."""
    direction = candidates.direction * np.where(candidates.direction[np.arange(len(candidates)), np.argmax(
        np.abs(candidates.direction), axis=1)] < 0.0, -1.0, 1.0)[:, None]  # fmt: skip
    return Counter(
        (int(k), tuple(v.tolist()), tuple(e.tolist()), tuple(np.round(d, 7).tolist()))
        for k, v, e, d in zip(candidates.kind, candidates.vertices, candidates.edges, direction, strict=True)
    )


def counts(candidates: NodeCandidates) -> list[int]:
    return np.bincount(candidates.kind, minlength=4).tolist()


# ---------------------------------------------------------------------------------------------------------
# no node lost


@pytest.mark.parametrize("name", list(SCENES))
def test_fast_enumeration_loses_no_node(name):
    scene = SCENES[name]()
    reference = accepted(scene, naive_candidates(scene))
    found = accepted(scene, fast(scene))
    assert sum(reference.values()) > 100
    assert {kind for kind, _ in reference} >= {0, 1, 2}, "the scene should have VV, VEE and EVE nodes"
    lost = reference - found
    extra = found - reference
    assert not lost, f"{name}: {sum(lost.values())} nodes lost, e.g. {list(lost)[:3]}"
    assert not extra, f"{name}: {sum(extra.values())} nodes the reference does not have, e.g. {list(extra)[:3]}"


def contact_scene() -> Scene:
    """A smaller lamp-and-table: a closed room, a lamp, a table top on one leg, a box standing on the top and a
    box on the floor against the leg -- all axis-aligned."""
    b = SceneBuilder("contacts")
    b.room("room", (0.0, 0.0, 0.0), (4.0, 3.0, 2.5))
    b.light("lamp", (1.8, 1.5, 2.45), (0.0, 0.0, -1.0), 0.3, 0.2, (50.0, 50.0, 50.0))
    b.box("top", (1.0, 1.0, 0.7), (2.6, 2.0, 0.75), (0.5, 0.4, 0.3))
    b.box("leg", (1.1, 1.1, 0.0), (1.16, 1.16, 0.7), (0.5, 0.4, 0.3))
    b.box("on top", (1.5, 1.3, 0.75), (1.8, 1.6, 1.0), (0.3, 0.4, 0.6))
    b.box("on floor", (1.16, 1.2, 0.0), (1.5, 1.5, 0.3), (0.6, 0.5, 0.3))
    return b.spec().build()


@pytest.mark.parametrize(
    "make, slow", [(contact_scene, False), (lambda: lamp_table_scene().scene, True)], ids=["contacts", "lamp table"]
)
def test_contacts_lose_no_node(make, slow):
    """Boxes resting on boxes, axis-aligned edges: lines through vertices of other objects, coplanar and
    parallel edges, lines through solids between touching objects. The lamp-and-table scene takes half a
    minute (the exhaustive E4 enumeration of 124 edges): set VISRAD_SLOW_TESTS=1 to run it."""
    if slow and not os.environ.get("VISRAD_SLOW_TESTS"):
        pytest.skip("slow reference; set VISRAD_SLOW_TESTS=1")
    scene = make()
    reference = accepted(scene, naive_candidates(scene))
    found = accepted(scene, fast(scene))
    assert any(kind == 3 for kind, _ in reference), "E4 nodes expected"
    assert reference == found, f"lost {sum((reference - found).values())}, extra {sum((found - reference).values())}"


def test_fast_enumeration_prunes():
    """The point of the module: far fewer candidates than the exhaustive enumeration."""
    scene = generic_closed_room(2, 3).scene
    naive, quick = counts(naive_candidates(scene)), counts(fast(scene))
    assert quick[CANDIDATE_VEE] < naive[CANDIDATE_VEE] / 4
    assert quick[CANDIDATE_E4] < naive[CANDIDATE_E4] / 2
    assert quick[CANDIDATE_VV] <= naive[CANDIDATE_VV]
    assert 0 < quick[CANDIDATE_FEE] <= naive[CANDIDATE_FEE]


# ---------------------------------------------------------------------------------------------------------
# well-formed candidates


def _segment_gap(scene: Scene, origin, direction, edge) -> float:
    """How far the line misses the segment (0 when it crosses it)."""
    a, b = scene.vertices[scene.edges[edge]]
    along = b - a
    normal = np.cross(direction, along)
    w = a - origin
    s = np.dot(np.cross(w, direction), normal) / np.dot(normal, normal)
    closest = a + np.clip(s, 0.0, 1.0) * along
    offset = closest - origin
    return float(np.linalg.norm(offset - np.dot(offset, direction) * direction))


def test_candidates_are_well_formed():
    scene = generic_closed_room(0, 2).scene
    c = fast(scene)
    tol = scene.tol.length
    assert np.allclose(np.linalg.norm(c.direction, axis=1), 1.0)
    assert c.vertices.dtype == np.int64 and c.edges.dtype == np.int64 and c.kind.dtype == np.int8
    wanted_vertices = {CANDIDATE_VV: 2, CANDIDATE_VEE: 1, CANDIDATE_E4: 0, CANDIDATE_FEE: 0}
    wanted_edges = {CANDIDATE_VV: 0, CANDIDATE_VEE: 2, CANDIDATE_E4: 4, CANDIDATE_FEE: 4}
    for i in range(len(c)):
        kind = int(c.kind[i])
        vertices = c.vertices[i][c.vertices[i] >= 0]
        edges = c.edges[i][c.edges[i] >= 0]
        assert len(vertices) == wanted_vertices[kind] and len(edges) == wanted_edges[kind]
        assert np.all(c.vertices[i, len(vertices) :] == -1) and np.all(c.edges[i, len(edges) :] == -1)
        assert np.all(np.diff(edges) > 0)
        for v in vertices:
            offset = scene.vertices[v] - c.origin[i]
            assert np.linalg.norm(offset - np.dot(offset, c.direction[i]) * c.direction[i]) <= 4 * tol
            assert not np.any(scene.edges[edges] == v), "a VEE edge incident to its vertex"
        for e in edges:
            assert _segment_gap(scene, c.origin[i], c.direction[i], e) <= 4 * tol
        if kind == CANDIDATE_E4:
            assert len(np.unique(scene.edges[edges])) == 8
        if kind == CANDIDATE_FEE:
            # two of the edges bound one polygon, whose plane holds the line
            faces = [set(scene.edge_faces[scene.edge_face_offsets[e] : scene.edge_face_offsets[e + 1]]) for e in edges]
            shared = [p for j in range(4) for k in range(j + 1, 4) for p in faces[j] & faces[k]]
            assert len(shared) == 1
            normal = scene.normals[shared[0]]
            assert abs(normal @ c.direction[i]) <= scene.tol.cosine
            assert abs(normal @ c.origin[i] + scene.plane_offsets[shared[0]]) <= 4 * tol
    assert max(line_keys(c).values()) == 1, "a candidate proposed twice"


def _overhanging_boxes() -> Scene:
    """The upper box overhangs the lower one on two sides: its bottom edges cross the lower box's top edges."""
    return boxes_in_room([((1.0, 1.0, 0.0), (2.0, 2.0, 0.6)), ((1.5, 0.8, 0.6), (2.3, 1.6, 1.0))])


def _edge_crossings(scene: Scene, edge_mask: np.ndarray) -> list[tuple[int, int, np.ndarray, np.ndarray]]:
    """(e, f, crossing point (3,), unit normal of their plane (3,)) for the masked edges e < f whose interiors
    cross at one point."""
    tol = scene.tol.length
    found = []
    edge_ids = np.flatnonzero(edge_mask)
    for i, e in enumerate(edge_ids):
        for f in edge_ids[i + 1 :]:
            if set(scene.edges[e]) & set(scene.edges[f]):
                continue
            a, b = scene.vertices[scene.edges[e]]
            p, q = scene.vertices[scene.edges[f]]
            normal = np.cross(b - a, q - p)
            if np.linalg.norm(normal) < 1e-9 or abs((p - a) @ normal) > tol * np.linalg.norm(normal):
                continue
            (s, t), *_ = np.linalg.lstsq(np.stack([b - a, p - q], axis=1), p - a, rcond=None)
            if not (1e-6 < s < 1 - 1e-6 and 1e-6 < t < 1 - 1e-6):
                continue
            found.append((int(e), int(f), a + s * (b - a), normal / np.linalg.norm(normal)))
    return found


def test_lines_from_a_vertex_through_a_crossing_of_edges_are_proposed():
    scene = _overhanging_boxes()
    vertex_mask, edge_mask = generator_masks(scene)
    tol = scene.tol.length
    expected = set()
    for e, f, crossing, normal in _edge_crossings(scene, edge_mask):
        for v in np.flatnonzero(vertex_mask):
            in_plane = abs((scene.vertices[v] - crossing) @ normal) <= tol
            if in_plane and v not in scene.edges[[e, f]] and np.linalg.norm(scene.vertices[v] - crossing) > tol:
                expected.add((int(v), e, f))
    assert len(expected) >= 8
    candidates = fast(scene)
    vee = {
        (int(v[0]), int(e[0]), int(e[1]))
        for k, v, e in zip(candidates.kind, candidates.vertices, candidates.edges, strict=True)
        if k == CANDIDATE_VEE
    }
    assert expected <= vee
    assert max(line_keys(candidates).values()) == 1, "a candidate proposed twice"
    nodes = accepted(scene, candidates)
    through_crossings = [
        key for key in nodes
        if any(key[1] == tuple(sorted([(1, v), (2, e), (2, f)])) for v, e, f in expected)
    ]  # fmt: skip
    assert through_crossings


@pytest.mark.parametrize("cells", [1, 3, 5])
def test_lines_through_a_crossing_are_proposed_once(monkeypatch, cells):
    """An E4 line through the crossing of two of its edges may be kept from either crossing edge (they meet it
    at one point): whatever the cube-map cells, it is proposed once, and the lines validation keeps from the
    candidates are those it keeps from every candidate found from every source edge."""
    from core.skeleton import enumeration as E

    monkeypatch.setattr(E, "_cells_per_side", lambda n_edges: cells)
    scene = _overhanging_boxes()
    candidates = fast(scene)
    assert max(line_keys(candidates).values()) == 1, "a candidate proposed twice"
    crossings = _edge_crossings(scene, generator_masks(scene)[1])
    tol = scene.tol.length
    e4 = np.flatnonzero(candidates.kind == CANDIDATE_E4)
    through = [
        c for c in e4 for e, f, point, _ in crossings
        if {e, f} <= set(candidates.edges[c].tolist()) and np.linalg.norm(
            np.cross(point - candidates.origin[c], candidates.direction[c])) <= 4.0 * tol
    ]  # fmt: skip
    assert through, "no E4 line through a crossing: the scene tests nothing"
    with_duplicates = E._once_through_crossings
    monkeypatch.setattr(E, "_once_through_crossings", lambda found, *args: found)
    everything = fast(scene)
    monkeypatch.setattr(E, "_once_through_crossings", with_duplicates)
    assert len(everything) >= len(candidates)
    assert set(accepted(scene, everything)) == set(accepted(scene, candidates))


def test_lines_in_the_plane_of_a_crossing_through_an_edge_across_it_are_proposed():
    """FXE candidates (seed 003's FvE node, the crossing of two edges standing for the vertex): for each crossing
    and each edge strictly across the two edges' plane, the line in that plane through the crossing and the
    point where the edge crosses it; validation keeps some of them as FXE nodes."""
    scene = _overhanging_boxes()
    _, edge_mask = generator_masks(scene)
    tol = scene.tol.length
    expected = {}
    for e, f, crossing, normal in _edge_crossings(scene, edge_mask):
        for g in np.flatnonzero(edge_mask):
            heights = (scene.vertices[scene.edges[g]] - crossing) @ normal
            if g not in (e, f) and heights[0] * heights[1] < 0.0 and np.abs(heights).min() > tol:
                expected[tuple(sorted((e, f, int(g))))] = (crossing, normal)
    assert len(expected) >= 8
    candidates = fast(scene)
    fxe = np.flatnonzero(candidates.kind == CANDIDATE_FXE)
    assert {tuple(candidates.edges[i, :3].tolist()) for i in fxe} == set(expected)
    assert (candidates.edges[fxe, 3] == -1).all()
    for i in fxe:
        crossing, normal = expected[tuple(candidates.edges[i, :3].tolist())]
        offset = crossing - candidates.origin[i]
        assert np.linalg.norm(offset - (offset @ candidates.direction[i]) * candidates.direction[i]) <= 4 * tol
        assert abs(candidates.direction[i] @ normal) <= 1e-9
    assert max(line_keys(candidates).values()) == 1, "a candidate proposed twice"
    assert any(kind == validation.NODE_FXE for kind, _ in accepted(scene, candidates))


# ---------------------------------------------------------------------------------------------------------
# lazy construction


def crosses(scene: Scene, origins: np.ndarray, directions: np.ndarray, polygon: int) -> np.ndarray:
    """(N,) bool: the lines meet the polygon within tol, or lie in its plane within tol."""
    tol = scene.tol.length
    normal = scene.normals[polygon]
    along = directions @ normal
    height = origins @ normal + scene.plane_offsets[polygon]
    flat = np.abs(along) <= scene.tol.cosine
    safe = np.where(flat, 1.0, along)
    hits = origins - (height / safe)[:, None] * directions
    corners = scene.polygon(polygon)
    inside = np.ones(len(origins), dtype=bool)
    for k in range(len(corners)):
        edge = corners[(k + 1) % len(corners)] - corners[k]
        outward = np.cross(edge, normal)
        outward /= np.linalg.norm(outward)
        inside &= (hits - corners[k]) @ outward <= tol
    return np.where(flat, np.abs(height) <= tol, inside)


@pytest.mark.parametrize("name", ["closed floor", "generic room 1"])
def test_lazy_sources_keep_exactly_the_lines_through_them(name):
    scene = SCENES[name]()
    full = fast(scene)
    light = int(scene.lights[0])
    box_face = scene.n_polygons - 1
    for polygon in (light, 0, box_face):
        lazy = fast(scene, sources=[polygon])
        through = crosses(scene, full.origin, full.direction, polygon)
        expected = NodeCandidates(*(a[through] for a in (full.kind, full.vertices, full.edges, full.origin,
                                                          full.direction)))  # fmt: skip
        assert 0 < len(lazy) < len(full)
        assert line_keys(lazy) == line_keys(expected), f"polygon {polygon}"
    both = fast(scene, sources=[light, box_face])
    either = crosses(scene, full.origin, full.direction, light) | crosses(scene, full.origin, full.direction, box_face)
    assert len(both) == int(either.sum())


def test_lazy_source_whose_plane_holds_far_edges():
    """A box's bottom face on the floor: lines lying in the floor's plane count as crossing it wherever they run
    (within tol of its plane), so lines along the floor far from the box must be kept, however far from the
    face the lazy construction's culling is."""
    scene = contact_scene()
    full = fast(scene)
    floor_plane = (np.abs(scene.normals[:, 2]) > 0.999) & (np.abs(scene.plane_offsets) <= scene.tol.length)
    box_bottom = int(np.flatnonzero(floor_plane & (scene.object_ids == scene.object_ids.max()))[0])
    lazy = fast(scene, sources=[box_bottom])
    through = crosses(scene, full.origin, full.direction, box_bottom)
    expected = NodeCandidates(*(a[through] for a in (full.kind, full.vertices, full.edges, full.origin,
                                                      full.direction)))  # fmt: skip
    along_floor = np.abs(expected.direction[:, 2]) <= scene.tol.cosine
    far = np.linalg.norm(expected.origin[:, :2] - scene.centroids[box_bottom, :2], axis=1) > 1.0
    assert (along_floor & far).sum() > 10, "the scene should have lines along the floor far from the box"
    assert line_keys(lazy) == line_keys(expected)


# ---------------------------------------------------------------------------------------------------------
# scale invariance


def scaled(scene: Scene, factor: float) -> Scene:
    return Scene.from_polygons(
        scene.vertices * factor,
        [scene.polygon_vertices(i).tolist() for i in range(scene.n_polygons)],
        scene.reflectance,
        scene.emission,
        object_ids=scene.object_ids,
        two_sided=scene.two_sided,
    )


@pytest.mark.parametrize("name", ["closed floor", "generic room 2"])
def test_scale_invariance(name):
    scene = SCENES[name]()
    reference = counts(fast(scene))
    for factor in (1e-3, 1e4):
        assert counts(fast(scaled(scene, factor))) == reference, f"scale {factor}"


# ---------------------------------------------------------------------------------------------------------
# chunks, progress and cancellation


def test_chunks_and_fractions():
    scene = generic_closed_room(0, 2).scene
    vertex_mask, edge_mask = generator_masks(scene)
    whole = list(iter_candidates(scene, vertex_mask, edge_mask, chunk=10**9))
    small = list(iter_candidates(scene, vertex_mask, edge_mask, chunk=7))
    assert len(whole) == 1 and whole[0][1] == 1.0
    assert all(0 < len(c) <= 7 for c, _ in small)
    fractions = [f for _, f in small]
    assert all(0.0 < f <= 1.0 for f in fractions) and fractions[-1] == 1.0
    assert all(b > a for a, b in zip(fractions, fractions[1:], strict=False))
    merged = NodeCandidates.concatenate([c for c, _ in small])
    assert line_keys(merged) == line_keys(whole[0][0])


def test_threads_change_no_candidate_and_no_node(monkeypatch):
    monkeypatch.setattr(validation, "_MIN_SLICE", 100)
    scene = generic_closed_room(2, 3).scene
    vertex_mask, edge_mask = generator_masks(scene)
    topology, bvh = scene_topology(scene), build_bvh(scene)
    results = []
    for workers in (1, 2):
        candidates = NodeCandidates.concatenate(
            [c for c, _ in iter_candidates(scene, vertex_mask, edge_mask, chunk=500, workers=workers)]
        )
        assert len(candidates) >= 200
        nodes, incidences, counters = validate_candidates(scene, topology, bvh, candidates, edge_mask, workers)
        results.append([*vars(candidates).values(), *vars(nodes).values(), *vars(incidences).values(), counters])
    assert len(results[1][-5]) > 0
    for serial, threaded in zip(*results, strict=True):
        assert np.array_equal(serial, threaded)


def test_cancel_stops_after_the_first_chunk():
    scene = generic_closed_room(0, 2).scene
    vertex_mask, edge_mask = generator_masks(scene)
    received = []
    generator = iter_candidates(scene, vertex_mask, edge_mask, chunk=7, cancel=lambda: len(received) > 0)
    with pytest.raises(CancelledError):
        for chunk, _ in generator:
            received.append(chunk)
    assert len(received) == 1


def test_bad_arguments_name_the_culprit():
    scene = box_over_floor_scene().scene
    vertex_mask, edge_mask = generator_masks(scene)
    with pytest.raises(SceneError, match="vertex_mask"):
        next(iter_candidates(scene, vertex_mask[:-1], edge_mask))
    with pytest.raises(SceneError, match="edge_mask"):
        next(iter_candidates(scene, vertex_mask, edge_mask.astype(int)))
    with pytest.raises(SceneError, match="source 99"):
        next(iter_candidates(scene, vertex_mask, edge_mask, sources=[0, 99]))
    with pytest.raises(ValueError, match="chunk"):
        next(iter_candidates(scene, vertex_mask, edge_mask, chunk=0))
    with pytest.raises(SceneError, match="scene"):
        next(iter_candidates("scene", vertex_mask, edge_mask))


def test_no_generators_no_candidates():
    scene = box_over_floor_scene().scene
    vertex_mask, edge_mask = generator_masks(scene)
    assert list(iter_candidates(scene, np.zeros_like(vertex_mask), np.zeros_like(edge_mask))) == []
    parts = [c for c, _ in iter_candidates(scene, vertex_mask, np.zeros_like(edge_mask))]
    assert set(NodeCandidates.concatenate(parts).kind.tolist()) == {CANDIDATE_VV}


# ---------------------------------------------------------------------------------------------------------
# where a line of an E4 family meets its third edge, from s alone


def _line_through_point_meeting(point, x, y):
    """The line through `point` meeting the lines x and y ((2, 3) each): the planes (point, x) and (point, y)
    intersect in it. Returns its direction (unit)."""
    normal_x = np.cross(x[0] - point, x[1] - point)
    normal_y = np.cross(y[0] - point, y[1] - point)
    direction = np.cross(normal_x, normal_y)
    return direction / np.linalg.norm(direction)


def _closest_parameter(origin, direction, segment):
    """Parameter along segment (2, 3) of its point closest to the line origin + t direction."""
    along = segment[1] - segment[0]
    normal = np.cross(direction, along)
    return float(np.dot(np.cross(segment[0] - origin, direction), normal) / np.dot(normal, normal))


def test_where_a_family_line_meets_its_third_edge_follows_from_s():
    """_along_from_s's Moebius map gives, for each s, the point of y the line through E(s) meeting x and y
    passes: checked against that line built from two planes, on random edges. _far_past_ends refuses exactly
    the s whose point lies further than the margin beyond y's ends, and never refuses when x, y and E(s) lie in
    one plane (the map means nothing there)."""
    from core.skeleton.enumeration import _along_from_s, _far_past_ends

    rng = np.random.default_rng(7)
    margin = 1e-3
    checked = refused = 0
    for _ in range(200):
        e, x, y = rng.uniform(-1.0, 1.0, (3, 2, 3))
        rel, along = np.array([x[0] - e[0], y[0] - e[0]]), np.array([x[1] - x[0], y[1] - y[0]])
        moebius = np.empty((1, 7))
        _along_from_s(rel, along, 0, 1, e[1] - e[0], margin, 1e-8, moebius, 0)
        assert np.isfinite(moebius[0, 5])
        for s in rng.uniform(0.0, 1.0, 5):
            point = e[0] + s * (e[1] - e[0])
            u = _closest_parameter(point, _line_through_point_meeting(point, x, y), y)
            from_s = (moebius[0, 0] - s * moebius[0, 2]) / (s * moebius[0, 3] - moebius[0, 1])
            assert from_s == pytest.approx(u, rel=1e-6, abs=1e-6)
            reach = margin / np.linalg.norm(y[1] - y[0])
            if -reach + 1e-6 < u < 1.0 + reach - 1e-6:
                assert not _far_past_ends(moebius, 0, s)
            elif u < -reach - 1e-6 or u > 1.0 + reach + 1e-6:
                assert _far_past_ends(moebius, 0, s)
                refused += 1
            checked += 1
    assert refused > checked // 4
    # y in the plane of x and E(s) for every s: x and y on one face, e crossing it
    x = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    y = np.array([[0.0, 1.0, 0.0], [1.0, 2.0, 0.0]])
    e = np.array([[0.5, 0.5, -1.0], [0.5, 0.5, 1.0]])
    rel, along = np.array([x[0] - e[0], y[0] - e[0]]), np.array([x[1] - x[0], y[1] - y[0]])
    moebius = np.empty((1, 7))
    _along_from_s(rel, along, 0, 1, e[1] - e[0], margin, 1e-8, moebius, 0)
    assert not any(_far_past_ends(moebius, 0, s) for s in np.linspace(0.0, 1.0, 11))


# ---------------------------------------------------------------------------------------------------------
# occlusion-map culls: each skips only what could lower no bound


def test_polygon_widths_are_the_least_extent_across():
    """_polygon_widths against widths known in closed form, on polygons placed at random in space: a w x h
    rectangle is min(w, h) wide, a triangle its least altitude (twice its area over its longest side)."""
    from core.skeleton.enumeration import _polygon_widths

    rng = np.random.default_rng(3)
    polygons, expected = [], []
    for _ in range(40):
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        shift = rng.uniform(-5.0, 5.0, 3)
        if rng.uniform() < 0.5:
            w, h = rng.uniform(0.01, 3.0, 2)
            flat = np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])
            expected.append(min(w, h))
        else:
            flat = np.column_stack([rng.uniform(-2.0, 2.0, (3, 2)), np.zeros(3)])
            if np.cross(flat[1] - flat[0], flat[2] - flat[0])[2] < 0.0:
                flat = flat[::-1].copy()
            area = 0.5 * np.cross(flat[1] - flat[0], flat[2] - flat[0])[2]
            longest = max(np.linalg.norm(flat[k] - flat[k - 1]) for k in range(3))
            expected.append(2.0 * area / longest)
        polygons.append(flat @ rotation.T + shift)
    points = np.concatenate(polygons)
    offsets = np.concatenate([[0], np.cumsum([len(p) for p in polygons])])
    out = []
    for p in polygons:
        normal = np.cross(p[1] - p[0], p[2] - p[0])
        along = np.roll(p, -1, axis=0) - p
        outward = np.cross(along, normal)
        out.append(outward / np.linalg.norm(outward, axis=1)[:, None])
    widths = _polygon_widths(points, offsets, np.concatenate(out))
    np.testing.assert_allclose(widths, expected, rtol=1e-9)


@pytest.mark.parametrize("n", [5, 7, 11, 15])
def test_every_direction_near_a_cells_middle_lies_in_the_cell(n):
    """_cell_half_sine: random directions within the claimed half angle of each cell's middle direction fall in
    that cell (_line_cell, the cell the skeleton files a line under); and the bound is the least such angle
    over the cells to 1 %: just beyond it, some direction of some cell falls out."""
    from core.skeleton.enumeration import _cell_half_sine, _line_cell

    sine = _cell_half_sine(n)
    rng = np.random.default_rng(n)
    ticks = -1.0 + 2.0 * np.arange(n + 1) / n
    middle = 0.5 * (ticks[:-1] + ticks[1:])
    escaped = False
    for a in range(3):
        for i in range(n):
            for j in range(n):
                centre = np.zeros(3)
                centre[a], centre[(a + 1) % 3], centre[(a + 2) % 3] = 1.0, middle[i], middle[j]
                centre /= np.linalg.norm(centre)
                frame = np.linalg.svd(centre[None, :])[2][1:]
                for angle_scale, must_stay in ((0.999, True), (1.01, False)):
                    angle = np.arcsin(sine) * angle_scale
                    for turn in rng.uniform(0.0, 2.0 * np.pi, 24):
                        d = np.cos(angle) * centre + np.sin(angle) * (np.cos(turn) * frame[0] + np.sin(turn) * frame[1])
                        ca, ci, cj, flipped = _line_cell(d, n)
                        inside = (ca, ci, cj, flipped) == (a, i, j, False)
                        if must_stay:
                            assert inside, (a, i, j, d)
                        escaped = escaped or not inside
    assert escaped, "the bound is not the least half angle: no direction just beyond it left its cell"


def test_a_ball_off_a_face_is_seen_through_none_of_it():
    """_sphere_off_face: wherever it says a ball is off the faces of an axis, no point sampled in the ball
    (inside and on its surface) is seen through them, grown by eps; and it says so for most balls far off."""
    from core.skeleton.enumeration import _sphere_off_face

    rng = np.random.default_rng(11)
    eps = 1e-6
    origin = np.zeros(3)
    said_off = 0
    for _ in range(3000):
        centre = rng.uniform(-3.0, 3.0, 3)
        radius = rng.uniform(0.0, 1.0)
        a = int(rng.integers(3))
        if not _sphere_off_face(centre, radius, origin, a, eps):
            continue
        said_off += 1
        sample = rng.normal(size=(400, 3))
        sample *= (radius * rng.uniform(0.0, 1.0, 400) ** (1 / 3) / np.linalg.norm(sample, axis=1))[:, None]
        sample[:100] *= radius / np.linalg.norm(sample[:100], axis=1)[:, None]
        x = centre + sample
        b, c = (a + 1) % 3, (a + 2) % 3
        through = (np.abs(x[:, b]) <= (1 + eps) * np.abs(x[:, a])) & (np.abs(x[:, c]) <= (1 + eps) * np.abs(x[:, a]))
        assert not through.any(), (centre, radius, a)
    assert said_off > 600


def test_clip_to_face_equals_clipping_every_polygon():
    """_clip_to_face skips the clips for polygons wholly behind the apex or wholly inside the face's cone: on
    random polygons of all three kinds its result is the clipped polygon, point for point."""
    from core.skeleton.enumeration import _CLIP, _clip, _clip_pyramid, _clip_to_face

    rng = np.random.default_rng(5)
    eps = 1e-9
    kinds = Counter()
    for _ in range(3000):
        count = int(rng.integers(3, 7))
        turn = np.sort(rng.uniform(0.0, 2.0 * np.pi, count))
        centre = rng.uniform(-2.0, 2.0, 3)
        centre[0] = rng.uniform(-1.0, 3.0)
        size = rng.uniform(0.01, 1.5)
        polygon = centre + size * np.column_stack([np.zeros(count), np.cos(turn), np.sin(turn)]) @ np.linalg.qr(
            rng.normal(size=(3, 3)))[0].T  # fmt: skip
        buf_a = np.zeros((_CLIP, 3))
        buf_a[:count] = polygon
        expected_a = buf_a.copy()
        scratch = np.zeros((_CLIP, 3))
        m = _clip(expected_a, count, 1.0, 0.0, 0.0, scratch)
        expected_a[:m] = scratch[:m]
        m = _clip_pyramid(expected_a, m, -1.0 - eps, 1.0 + eps, -1.0 - eps, 1.0 + eps, scratch)
        got = _clip_to_face(buf_a, count, eps, np.zeros((_CLIP, 3)))
        assert got == m
        np.testing.assert_array_equal(buf_a[:m], expected_a[:m])
        kinds["behind" if m == 0 and polygon[:, 0].max() < 0 else "kept whole" if m == count and np.array_equal(
            expected_a[:m], polygon) else "clipped"] += 1  # fmt: skip
    assert min(kinds.values()) > 100, kinds


@pytest.mark.parametrize("name", ["generic room 2", "team room"])
@pytest.mark.parametrize("cells", [1, 3, 7])
def test_depth_map_culls_lose_no_bound(name, cells):
    """The polygons and objects _depth_map skips (narrower than any cell's patch, seen under less than a cell,
    off an axis's faces) would have lowered no bound: the maps of every vertex, and of every edge cut in four
    bins, equal those made with every cull off (infinite widths and object radii, a zero half angle). With the
    cells of small scenes (one per cube face: these rooms get that) and finer ones."""
    from core.skeleton import enumeration as E

    scene = SCENES[name]()
    g = E._Geometry(scene, cells, scene_topology(scene))
    n_cells = 3 * cells * cells
    none = np.empty(0, dtype=np.int64)
    culls = (g.widths, g.cell_sine, g.objects[0], g.objects[1], g.objects[2], g.objects[3])
    no_culls = (np.full_like(g.widths, np.inf), 0.0, g.objects[0], g.objects[1], g.objects[2],
                np.full_like(g.objects[3], np.inf))  # fmt: skip
    maps = []
    for widths, sine, o_off, o_poly, o_centres, o_radii in (culls, no_culls):
        out = np.full((scene.n_vertices, 2, n_cells), np.inf)
        E._vertex_maps(np.arange(scene.n_vertices), g.vertices, g.points, g.offsets, g.normals, g.plane_offsets,
                       g.edge_out, g.centres, g.radii, widths, sine, o_off, o_poly, o_centres, o_radii, g.grid, cells,
                       g.margin, g.delta, g.eps, False, none, g.tol, out)  # fmt: skip
        edge_maps = []
        for e in range(len(scene.edges)):
            ends = scene.vertices[scene.edges[e]]
            q = ends[0] + np.linspace(0.0, 1.0, 5)[:, None] * (ends[1] - ends[0])
            depth = np.full((4, 2, n_cells), np.inf)
            E._depth_map(q, 4, g.points, g.offsets, g.normals, g.plane_offsets, g.edge_out, g.centres, g.radii,
                         widths, sine, o_off, o_poly, o_centres, o_radii, g.grid, cells, g.margin, g.delta, g.eps,
                         np.ones((4, n_cells), dtype=np.bool_), depth, False, none, g.tol)  # fmt: skip
            edge_maps.append(depth)
        maps.append((out, np.array(edge_maps)))
    (vertex_culled, edge_culled), (vertex_all, edge_all) = maps
    assert np.isfinite(vertex_all).mean() > 0.1 and np.isfinite(edge_all).mean() > 0.1
    np.testing.assert_array_equal(vertex_culled, vertex_all)
    np.testing.assert_array_equal(edge_culled, edge_all)


# E4 pivots coplanar with the source edge: their lines stay near the common plane


@pytest.mark.parametrize("size", [1e-3, 1.0, 1e4])
def test_plane_reach_keeps_every_target_a_pivot_line_meets(size):
    """_plane_reach's bound, by construction of the worst lines: e and x cross at P (x lifted off e's plane by
    `lift`, the rounding of a real scene and far more); the lines E X with E on e and X on x a little over tol
    apart near P tilt the most, by lift over their length. A target is laid through a point of such a line,
    anywhere in the scene's box, tilted at random: the prune (both ends of the target, grown by tol, beyond the
    reach on one side) never drops it. And it bites: with x in e's plane, targets 1e-3 of the scene off the
    plane are dropped; with x well off the plane, nothing is bounded."""
    from core.skeleton.enumeration import _plane_reach

    rng = np.random.default_rng(11)
    scale = np.sqrt(3.0) * size  # the box [0, size]^3
    tol = 1e-9 * scale
    kept = dropped = 0
    for trial in range(400):
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        centre = np.full(3, 0.5 * size)
        along_e = rotation[0]
        along_x = np.cos(rng.uniform(0.01, 3.13)) * rotation[0] + np.sin(rng.uniform(0.01, 3.13)) * rotation[1]
        along_x /= np.linalg.norm(along_x)
        normal = rotation[2]
        lift = (0.0, 1e-15, 1e-13, 1e-11)[trial % 4] * scale
        half_e, half_x = rng.uniform(0.05, 0.4, 2) * size
        e_a, e_b = centre - half_e * along_e, centre + half_e * along_e
        x_a, x_b = centre + lift * normal - half_x * along_x, centre + lift * normal + half_x * along_x
        reach = _plane_reach(e_b - e_a, *(x_a - e_a), *(x_b - x_a), scale, tol)
        plane = np.array(reach[:3])
        assert abs(abs(plane @ normal) - 1.0) < 1e-9
        assert reach[3] < scale
        for _ in range(20):
            # E and X near the crossing, |X - E| between tol and 3 tol: the steepest lines of the family
            length = rng.uniform(1.001, 3.0) * tol
            angle = rng.uniform(0.0, 2.0 * np.pi)
            point_e = centre + (length * np.cos(angle)) * along_e
            point_x = x_a + ((centre - x_a) @ along_x + length * np.sin(angle)) * along_x
            direction = point_x - point_e
            if np.linalg.norm(direction) <= tol:
                continue
            direction /= np.linalg.norm(direction)
            # a point of the line in the box, and a target through a point within tol of it
            exits = [(0.0 - point_e) / direction, (size - point_e) / direction]
            far = np.min(np.abs(np.max(exits, axis=0)))
            near = -np.min(np.abs(np.min(exits, axis=0)))
            on_line = point_e + rng.uniform(near, far) * direction
            met = on_line + rng.normal(size=3) * (0.5 * tol / np.sqrt(3.0))
            spread = rng.normal(size=3)
            spread *= rng.uniform(0.0, 0.3) * size / np.linalg.norm(spread)
            y_a, y_b = met - rng.uniform(0.0, 1.0) * spread, met + rng.uniform(0.0, 1.0) * spread
            height = plane @ (y_a - e_a)
            rise = plane @ (y_b - y_a)
            assert not (min(height, height + rise) > reach[3] or max(height, height + rise) < -reach[3]), (
                trial, lift, length, reach[3], height, rise)
            kept += 1
        if lift == 0.0:
            off = plane * (2e-3 * scale + rng.uniform(0.0, 0.3) * size) * rng.choice([-1.0, 1.0])
            y_a = centre + off + rng.uniform(-0.2, 0.2, 3) * size * (1.0 - np.abs(normal))
            height = plane @ (y_a - e_a)
            dropped += abs(height) > reach[3]
        far_x = x_a + 0.01 * size * normal
        assert _plane_reach(e_b - e_a, *(far_x - e_a), *(x_b - x_a), scale, tol)[3] >= scale
    assert kept > 7000
    assert dropped == 100


@pytest.mark.parametrize("size", [1e-3, 1.0, 1e4])
def test_vee_pairs_off_a_plane_are_those_no_line_meets(size):
    """_off_plane as _vertex_candidates uses it: edges f and g are laid within tol of two points of a line
    through v (at any angle; a third of them nearly pointing at v, where the plane through v and the edge is
    barely defined; a third of the g edges along f's plane, as high over it as their offset from the line). The
    kernel's line, where the two planes meet as it computes them, is tested against both edges as it tests
    them (_meets_segment): whenever it meets both, neither edge is off the other's plane. An edge moved wholly
    to one side of the plane, 1e-5 of the scene or more, always is."""
    from core.skeleton.enumeration import _meets_segment, _off_plane

    rng = np.random.default_rng(5)
    scale = np.sqrt(3.0) * size
    tol = 1e-9 * scale
    delta = 16.0 * tol / scale
    reach = 2.0 * tol + 1e-6 * scale
    no_faces = (np.zeros((0, 3)), np.zeros(0), np.zeros(3, dtype=np.int64), np.zeros(0, dtype=np.int64))
    met = off = tried = 0
    for trial in range(3000):
        p = rng.uniform(0.0, size, 3)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        ends = np.empty((2, 2, 3))
        tilts = np.empty((2, 3))
        for k in range(2):
            # within tol of the line, which _meets_segment accepts
            aside = np.cross(d, rng.normal(size=3))
            aside *= rng.uniform(0.0, 0.95) * tol / np.linalg.norm(aside)
            on_line = p + rng.uniform(0.01, 0.8) * size * rng.choice([-1.0, 1.0]) * d + aside
            tilt = rng.normal(size=3)
            tilt /= np.linalg.norm(tilt)
            if trial % 3 == 0:
                tilt = d + 10.0 ** rng.uniform(-12.0, -4.0) * tilt
                tilt /= np.linalg.norm(tilt)
            if trial % 3 == 1 and k == 1:
                tilt = rng.normal() * d + rng.normal() * tilts[0]
                tilt /= np.linalg.norm(tilt)
            tilts[k] = tilt
            lengths = rng.uniform(0.01, 0.5, 2) * size
            ends[k, 0] = on_line - lengths[0] * tilt
            ends[k, 1] = on_line + lengths[1] * tilt
        planes = np.cross(ends[:, 0] - p, ends[:, 1] - p)
        unit = planes / np.linalg.norm(planes, axis=1)[:, None]
        line = np.cross(planes[0], planes[1])
        if np.linalg.norm(line) <= delta * np.linalg.norm(planes[0]) * np.linalg.norm(planes[1]):
            continue
        line /= np.linalg.norm(line)
        vertices = ends.reshape(4, 3)
        edges = np.array([[0, 1], [2, 3]], dtype=np.int64)
        meets = [_meets_segment(p, line, vertices, edges, no_faces[0], no_faces[1], no_faces[2], no_faces[3], k, tol,
                                delta)[0] for k in range(2)]  # fmt: skip
        if all(meets):
            met += 1
            assert not _off_plane(unit, ends, p, 0, 1, reach), trial
            assert not _off_plane(unit, ends, p, 1, 0, reach), trial
        moved = ends.copy()
        heights = (ends[1] - p) @ unit[0]
        lift = np.abs(heights).max() + 1e-5 * scale + rng.uniform(0.0, 0.3) * size
        moved[1] += lift * rng.choice([-1.0, 1.0]) * unit[0]
        off += _off_plane(unit, moved, p, 0, 1, reach)
        tried += 1
    assert met > 1000
    assert off == tried > 2000


# E4 targets across the source edge from its faces: every line through both pierces it


@pytest.mark.parametrize("size", [1e-3, 1.0, 1e4])
def test_targets_declared_pierced_meet_only_lines_that_pierce_the_source(size):
    """_target_pierces against _edge_pierced on sampled lines. Edge e has two faces at a random dihedral angle
    (every seventh edge a third face); target f lies anywhere around it: at random, parallel to e, passing within
    1e-9 to 1e-5 of the scene from e's line, with both ends a few tol to 1e-6 of the scene across the plane of e
    and one face, or beyond an end of e nearly on its line (1e-9 to 3e-7 of the scene off it, in the wedge
    across e from its faces: lines from e to it run nearly along e). Whenever f is declared pierced, every line
    through a point of e (ends included) and a point within 2 tol of f (its ends grown by 2 tol) pierces e as
    _edge_pierced decides. And it bites: a short target in the wedge across e from both faces always is
    declared pierced."""
    from core.skeleton.enumeration import _edge_pierced, _target_pierces

    rng = np.random.default_rng(17)
    scale = np.sqrt(3.0) * size
    tol = 1e-9 * scale
    delta = 16.0 * tol / scale
    edges = np.array([[0, 1], [2, 3]], dtype=np.int64)
    declared = lines = across = 0
    for trial in range(1500):
        frame, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        along, side_a, side_b = frame
        centre = np.full(3, 0.5 * size)
        half = rng.uniform(0.02, 0.3) * size
        first = rng.uniform(0.0, 2.0 * np.pi)
        dihedral = rng.uniform(0.05, np.pi - 0.05)
        angles = [first, first + dihedral] + ([rng.uniform(0.0, 2.0 * np.pi)] if trial % 7 == 0 else [])
        inward = np.array([np.cos(t) * side_a + np.sin(t) * side_b for t in angles])
        ef_off = np.array([0, len(angles), len(angles)], dtype=np.int64)
        mode = trial % 5
        away = -(inward[0] + inward[1])
        away /= np.linalg.norm(away)
        if mode == 0:
            ends = centre + rng.uniform(-0.5, 0.5, (2, 3)) * size
        elif mode == 1:
            middle = centre + rng.uniform(-0.4, 0.4, 3) * size
            length = rng.uniform(0.01, 0.3) * size
            ends = np.array([middle - length * along, middle + length * along])
        elif mode == 2:
            aside = np.cross(along, rng.normal(size=3))
            aside *= 10.0 ** rng.uniform(-9.0, -5.0) * scale / np.linalg.norm(aside)
            through = centre + rng.uniform(-2.0, 2.0) * half * along + aside
            tilt = rng.normal(size=3)
            tilt /= np.linalg.norm(tilt)
            reach = rng.uniform(0.0, 0.3, 2) * size
            ends = np.array([through - reach[0] * tilt, through + reach[1] * tilt])
        elif mode == 3:
            start = centre + rng.choice([-1.0, 1.0]) * (half + rng.uniform(0.0, 0.2) * size) * along
            start += 10.0 ** rng.uniform(-9.0, -6.5) * scale * away
            tilt = along + 10.0 ** rng.uniform(-9.0, -6.0) * away
            ends = np.array([start, start + rng.uniform(0.01, 0.3) * size * tilt / np.linalg.norm(tilt)])
        else:
            # both ends just across the plane of e and face 0, on the side away from the face's inside
            normal = np.cross(along, inward[0])
            normal *= -np.sign(normal @ inward[1]) if abs(normal @ inward[1]) > 1e-3 else 1.0
            lifts = 10.0 ** rng.uniform(0.0, 3.0, 2) * tol
            in_plane = rng.uniform(-0.4, 0.4, (2, 2)) * size
            ends = centre + in_plane[:, :1] * along + in_plane[:, 1:] * inward[0] + lifts[:, None] * normal
        vertices = np.array([centre - half * along, centre + half * along, *ends])
        if _target_pierces(0, 1, vertices, edges, ef_off, inward, delta, tol):
            declared += 1
            target = ends[1] - ends[0]
            grown = 2.0 * tol / max(np.linalg.norm(target), tol)
            for k in range(40):
                s = (0.0, 1.0)[k % 2] if k < 8 else rng.uniform(0.0, 1.0)
                w = (-grown, 1.0 + grown)[(k // 2) % 2] if k < 8 else rng.uniform(-grown, 1.0 + grown)
                offset = rng.normal(size=3)
                offset *= rng.uniform(0.0, 1.0) * 2.0 * tol / np.linalg.norm(offset)
                point = ends[0] + w * target + offset
                direction = point - vertices[0] - s * (vertices[1] - vertices[0])
                direction /= np.linalg.norm(direction)
                assert _edge_pierced(0, direction, vertices, edges, ef_off, inward, delta), (trial, mode, k)
                lines += 1
        if len(angles) == 2 and dihedral < np.pi - 0.3:
            middle = centre + rng.uniform(-0.5, 0.5) * half * along + rng.uniform(0.1, 0.4) * size * away
            spread = rng.normal(size=3)
            spread *= 1e-3 * size / np.linalg.norm(spread)
            vertices[2:] = [middle - spread, middle + spread]
            assert _target_pierces(0, 1, vertices, edges, ef_off, inward, delta, tol), trial
            across += 1
    assert declared > 300
    assert lines == 40 * declared
    assert across > 1000
