"""core.skeleton.validation's early rejection against a plain numpy check.

`_pierced_between` rejects a candidate line after casting only the part between its outer generators; it
must answer True only for lines that cross some polygon's interior (well inside it, not near its boundary)
strictly between where they meet their first and last generator. The check here intersects the line with every
polygon in numpy, no BVH, and places the generators from the geometry.
"""

import numpy as np
import pytest

from bench.scenes import SCENES as BENCH_SCENES
from bench.scenes import closed_furnished_room
from core.bvh import STACK_SIZE, build_bvh
from core.scene import EDGE_FLAT
from core.skeleton import validation
from core.skeleton.candidates import CANDIDATE_E4, NodeCandidates
from core.skeleton.enumeration import iter_candidates
from core.skeleton.topology import scene_topology
from core.skeleton.validation import (
    ARC_EEE,
    GEN_EDGE,
    GEN_VERTEX,
    _pierced_between,
    flat_regions,
    validate_candidates,
)
from tests.core.naive_enumeration import generator_masks
from tests.core.skeleton_scenes import boxes_in_room, lamp_table_scene

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



@pytest.mark.parametrize("name", ["office-84", "furnished room"])
@pytest.mark.parametrize("first_rows", [0, 5, 300])
def test_validation_does_not_depend_on_the_incidence_rows_it_starts_with(name, first_rows, monkeypatch):
    """A candidate that runs out of incidence rows is validated again with more (_validate_from). Starting with
    none or a few rows instead of the bound grows them again and again, wherever rows are written: the nodes,
    incidences and counters must be exactly those of a start with the bound."""
    scene = (BENCH_SCENES["office-84"]() if name == "office-84" else closed_furnished_room(7, n_boxes=14)).build()
    vertex_mask, edge_mask = generator_masks(scene)
    candidates = NodeCandidates.concatenate([c for c, _ in iter_candidates(scene, vertex_mask, edge_mask)])
    topology, bvh = scene_topology(scene), build_bvh(scene)
    expected = validate_candidates(scene, topology, bvh, candidates, edge_mask, workers=1)
    kernel = validation._validate_chunk
    monkeypatch.setattr(validation, "_validate_chunk", lambda *arguments: kernel(*arguments, first_rows))
    nodes, incidences, counters = validate_candidates(scene, topology, bvh, candidates, edge_mask, workers=1)
    assert len(expected[1]) > 1000, f"{name}: too few incidences to grow the rows often"
    np.testing.assert_array_equal(counters, expected[2])
    for got, wanted in ((nodes, expected[0]), (incidences, expected[1])):
        for field, column in vars(wanted).items():
            np.testing.assert_array_equal(getattr(got, field), column, err_msg=f"{name}: {field}")


def _edge_between(scene, a, b) -> int:
    """The scene edge joining points a and b (3,), either way."""
    ends = scene.vertices[scene.edges]
    joins = np.isclose(ends, [a, b]).all(axis=(1, 2)) | np.isclose(ends, [b, a]).all(axis=(1, 2))
    return int(np.flatnonzero(joins)[0])


#: tilts (radians, about a horizontal axis) of a node's line in the tests below: the rounding of a candidate line
#: computed from its generators, well within the tolerance
_TILTS = np.array([0.0, 3e-9, -3e-9, 1e-9, -1e-9, 1e-10, -1e-10, 1e-12, -1e-12])


def _eee_arcs_on_tilted_lines(scene, edges, origin, along) -> list[list[int]]:
    """Validate the E4 candidate of `edges` (4,) on the line origin + t along (horizontal) tilted by each of
    _TILTS; all must be nodes. Returns the generators (sorted codes) of every EEE incidence of theirs."""
    count = len(_TILTS)
    directions = np.asarray(along) / np.linalg.norm(along) + _TILTS[:, None] * np.array([0.0, 0.0, 1.0])
    candidates = NodeCandidates(
        np.full(count, CANDIDATE_E4, np.int8), np.full((count, 2), -1, np.int64),
        np.tile(edges, (count, 1)).astype(np.int64), np.tile(origin, (count, 1)).astype(np.float64), directions,
    )  # fmt: skip
    nodes, incidences, _ = validate_candidates(
        scene, scene_topology(scene), build_bvh(scene), candidates, scene.edge_kind != EDGE_FLAT
    )
    assert len(nodes) == count
    return [sorted(codes) for codes in incidences.codes[incidences.kind == ARC_EEE].tolist()]


def test_pencil_turns_about_a_corner_lying_on_its_pivot_edge_on_every_node_line():
    """office-432: a shelf board's corner lies on the shelf side's vertical edge, in the plane of a chair seat's top.
    The lines of that plane through that point meeting the seat's edge and the board's far edge (an EEE arc whose
    two edges in the plane hold its lines there: they turn about the point, the side's contact does not move) pass
    the board's corner between those edges. The motion solved at an E4 node of these lines with a table leg's edge
    moved that contact by rounding, which decided whether the lines crossed the board's faces at its corner: on
    some lines they did not and the node had the arc, which the node at its other end, where they did, had not (it
    dangled). Held still, the contact meets the corner on every line."""
    top = 0.45
    scene = boxes_in_room(
        [((1.15, 0.8, 0.41), (1.6, 1.25, top)), ((1.15, 0.8, top), (1.6, 0.84, 0.9)),
         ((2.0, 2.0, 0.0), (2.05, 2.05, 0.7)), ((2.8, 3.8, 0.0), (2.83, 4.15, 1.8)),
         ((2.83, 3.8, top), (3.97, 4.15, 0.48))],
        size=(6.8, 4.8, 2.7),
    )  # fmt: skip
    seat = _edge_between(scene, (1.6, 0.8, top), (1.6, 1.25, top))
    leg = _edge_between(scene, (2.05, 2.0, 0.0), (2.05, 2.0, 0.7))
    side = _edge_between(scene, (2.83, 3.8, 0.0), (2.83, 3.8, 1.8))
    board = _edge_between(scene, (2.83, 4.15, top), (3.97, 4.15, top))
    named = _eee_arcs_on_tilted_lines(scene, [seat, leg, side, board], (2.05, 2.0, top), (0.78, 1.8, 0.0))
    assert sorted(scene.n_vertices + np.array([seat, side, board])) not in named


def test_no_pencil_is_parametrised_by_its_pivot_edge():
    """office-1056/1488's chairs and tables: a line of the plane of two chair seats' bottoms through the points where
    two table legs' vertical edges pierce it, meeting an edge of each seat (an E4 node). Relaxing either leg's edge
    leaves the pencil about the other's point, whose contact does not move: the system normalising the motion by
    sliding it is singular, and on the line tilted by rounding it was nearly so, giving a huge motion and an arc
    with both ends at that node, at one coordinate of the pivot (the lowest edge, which parametrises the arc):
    office-1056's 2 and 12 of office-1488's 18 dangling arcs. No arc keeps both seats' edges."""
    bottom = 0.41
    scene = boxes_in_room(
        [((6.75, 2.0, 0.0), (6.8, 2.05, 0.7)), ((6.95, 1.7, 0.0), (7.0, 1.75, 0.7)),
         ((7.15, 0.8, bottom), (7.6, 1.25, 0.45)), ((5.15, 2.8, bottom), (5.6, 3.25, 0.45))],
        size=(8.8, 8.8, 2.7),
    )  # fmt: skip
    legs = [_edge_between(scene, (x, y, 0.0), (x, y, 0.7)) for x, y in ((6.75, 2.0), (7.0, 1.75))]
    seats = [_edge_between(scene, (7.15, 1.25, bottom), (7.6, 1.25, bottom)),
             _edge_between(scene, (5.6, 2.8, bottom), (5.6, 3.25, bottom))]  # fmt: skip
    assert max(legs) < min(seats)
    named = _eee_arcs_on_tilted_lines(scene, [seats[1], *legs, seats[0]], (6.75, 2.0, bottom), (1.0, -1.0, 0.0))
    seat_codes = {scene.n_vertices + seat for seat in seats}
    assert not any(seat_codes <= set(codes) for codes in named)
    # relaxing a seat's edge leaves the two legs, parallel: the pencil of their plane about the point where the
    # other seat's edge pierces it, parametrised by a leg (not its pivot), is an arc
    assert any(set(scene.n_vertices + np.array(legs)) <= set(codes) for codes in named)


def test_flat_regions_join_coplanar_faces_of_different_objects_along_a_shared_side():
    """A box, one beside it of its height and one stacked on it with its footprint, and a smaller box on the stacked
    one: flat_regions puts two faces in one region exactly when a chain of pairs joins them, each pair faces of
    different objects in one plane (either way round) with sides on one line overlapping by more than tol,
    against a check of every pair of faces written here. The smaller box's bottom lies inside the top it stands
    on, touching no side of it: a region of its own."""
    scene = boxes_in_room(
        [((0.5, 0.5, 0.0), (1.0, 1.0, 0.5)), ((1.0, 0.5, 0.0), (1.5, 1.0, 0.5)), ((0.5, 0.5, 0.5), (1.0, 1.0, 1.0)),
         ((0.6, 0.6, 1.0), (0.9, 0.9, 1.2))],
    )  # fmt: skip
    region = flat_regions(scene)
    n = scene.n_polygons
    sides = []
    for p in range(n):
        corners = scene.polygon_points[scene.polygon_offsets[p] : scene.polygon_offsets[p + 1]]
        sides.append([(corners[k], corners[(k + 1) % len(corners)]) for k in range(len(corners))])

    def one_plane(a, b):
        normal, point = scene.normals[a], scene.polygon_points[scene.polygon_offsets[a]]
        corners = scene.polygon_points[scene.polygon_offsets[b] : scene.polygon_offsets[b + 1]]
        return np.abs((corners - point) @ normal).max() < 1e-9

    def sides_overlap(a, b):
        for p0, p1 in sides[a]:
            u = (p1 - p0) / np.linalg.norm(p1 - p0)
            for q0, q1 in sides[b]:
                off0, off1 = q0 - p0, q1 - p0
                if np.linalg.norm(np.cross(off0, u)) > 1e-9 or np.linalg.norm(np.cross(off1, u)) > 1e-9:
                    continue
                t0, t1 = sorted([off0 @ u, off1 @ u])
                if min(t1, np.linalg.norm(p1 - p0)) - max(t0, 0.0) > 1e-9:
                    return True
        return False

    label = list(range(n))

    def root(x):
        while label[x] != x:
            x = label[x]
        return x

    joined = 0
    for a in range(n):
        for b in range(a + 1, n):
            if scene.object_ids[a] != scene.object_ids[b] and one_plane(a, b) and sides_overlap(a, b):
                label[root(a)] = root(b)
                joined += 1
    assert joined >= 4
    for a in range(n):
        for b in range(n):
            assert (region[a] == region[b]) == (root(a) == root(b))


def _half_planes_cover(scene, faces, locals_, direction) -> bool:
    """Whether the half-planes of the faces touched along their edges (face, local edge) cover every direction
    around a line of this direction: sampled angles, those within a milliradian of an edge's projection left out."""
    e1 = np.cross(direction, [1.0, 0.0, 0.0] if abs(direction[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(direction, e1)
    sides = []
    for face, local in zip(faces, locals_, strict=True):
        loop = scene.polygon(int(face))
        edge = loop[(local + 1) % len(loop)] - loop[local]
        inward = np.cross(scene.normals[face], edge)
        along = np.array([edge @ e1, edge @ e2])
        across = np.array([inward @ e1, inward @ e2])
        sides.append((along / np.linalg.norm(along), np.sign(along[0] * across[1] - along[1] * across[0])))
    for angle in np.linspace(0.0, 2.0 * np.pi, 720, endpoint=False):
        x = np.array([np.cos(angle), np.sin(angle)])
        seen = [sign * (along[0] * x[1] - along[1] * x[0]) for along, sign in sides]
        if min(abs(s) for s in seen) < 1e-3:
            continue
        if max(seen) < 0.0:
            return False
    return True


def test_two_faces_along_one_edge_close_around_a_line_as_their_half_planes_do():
    """_group_blocked decides two faces touched along one edge by the signs of their normals along the line
    (_faces_along_one_edge_cover): for every edge of office-84 between two faces, random directions and
    directions within 1e-9 and 1e-6 of a face's plane, the answer is that of the half-planes themselves."""
    scene = BENCH_SCENES["office-84"]().build()
    topology = scene_topology(scene)
    rng = np.random.default_rng(5)
    polys = np.empty(2, dtype=np.int64)
    kinds = np.full(2, validation.CONTACT_EDGE, dtype=np.int8)
    locals_ = np.empty(2, dtype=np.int64)
    work = np.empty(4), np.empty(4), np.empty(8)
    decided = {True: 0, False: 0}
    for edge in range(len(scene.edges)):
        lo, hi = scene.edge_face_offsets[edge], scene.edge_face_offsets[edge + 1]
        if hi - lo != 2:
            continue
        polys[:] = scene.edge_faces[lo:hi]
        locals_[:] = topology.edge_face_local[lo:hi]
        directions = list(rng.normal(size=(6, 3)))
        for face in polys:
            normal = scene.normals[face]
            flat = np.cross(normal, rng.normal(size=3))
            for lean in (1e-9, -1e-9, 1e-6, -1e-6):
                directions.append(flat / np.linalg.norm(flat) + lean * normal)
        for direction in directions:
            direction = direction / np.linalg.norm(direction)
            if min(abs(scene.normals[polys] @ direction)) <= scene.tol.cosine:
                continue
            assert validation._faces_along_one_edge_cover(
                scene.polygon_points, scene.polygon_offsets, scene.normals, polys, locals_, 0, 1, direction
            ) >= 0
            expected = _half_planes_cover(scene, polys, locals_, direction)
            got = validation._group_blocked(
                scene.polygon_points, scene.polygon_offsets, scene.normals, polys, kinds, locals_, 0, 2, direction,
                scene.tol.cosine, *work,
            )  # fmt: skip
            assert got == expected, (edge, direction)
            decided[expected] += 1
    assert min(decided.values()) > 100
