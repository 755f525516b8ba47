"""Naive catalogue of the arcs leaving a skeleton node (seed 003, sections 2.1 and 2.3), for the tests.

A node is an extremal stabbing line held by four constraints: a vertex it passes through counts two, an edge
it meets one. Relaxing one constraint leaves a one-parameter family of lines:

* an edge dropped: the lines meeting the other generators, moved either way;
* a vertex loosened to one of its edges: the lines meeting the other generators and that edge, moved so that
  the contact slides from the vertex into the edge (the other way leaves the edge).

Each family is written down explicitly (the lines through a vertex and a point of an edge, or through a point
of one edge meeting two others) and followed a tiny step from the node. The moved line is a line of an arc
when it still meets its generators inside them and is free between its first and last generator: every piece
of it between two consecutive contacts with the scene lies in air (an inner generator keeps the line tangent
to its object, an outer one may also be where it stops), and it crosses no open panel. Air is told by casting
a ray: the first face met is seen from its front (normals point into the air of a closed scene).

Nothing here comes from core.skeleton: only the scene's geometry (vertices, edges, polygons, normals) is read.
Codes of generators are those of core.skeleton.graph.Arcs: vertex v -> v, edge e -> n_vertices + e.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: length of the step from the node along a family, relative to the scene's diagonal: far above rounding
#: (the moved line is built through its generators to about 1e-15) and far below the length of any arc of
#: a generic scene
STEP = 1e-7

#: how far (relative to the diagonal) beyond its outer generators a line is looked at to tell whether it goes
#: on there or stops: well below the step, within which a moved line passing a vertex's crease edge enters
#: the object (its third face is a step away), and well above MARGIN
BEYOND = 1e-2 * STEP

#: a point closer than this (relative to the diagonal) to a polygon's side is on its outline
MARGIN = 1e-10

#: a line passing closer than this (relative to the diagonal) to a generator meets it: the node lines are
#: solved to about this, the moved lines built through their generators to rounding; far below STEP, so that
#: the generator a move leaves is not met any more
MEETS = 1e-9

#: unit directions of the rays telling air from solid (see SceneGeometry.in_air)
_PROBES = np.array([[0.5377, 0.3129, 0.7832], [-0.2471, 0.8813, -0.4027], [0.6711, -0.7013, -0.2406],
                    [-0.8129, -0.1712, 0.5567], [0.1049, -0.4435, -0.8901]])  # fmt: skip
_PROBES /= np.linalg.norm(_PROBES, axis=1)[:, None]

#: a ray meeting its first face this far (relative to the diagonal) inside the outline is beyond rounding
_CLEAR = 1e-6


@dataclass(frozen=True)
class Relaxation:
    """One arc the oracle expects at a node: its generators (sorted codes) and the way it leaves the node
    along its parameter edge (the lowest edge id among its generators, coordinate 0..1 from the edge's first
    vertex): +1 towards larger coordinates, -1 towards smaller. dropped: the relaxed generator (its code) and,
    for a vertex loosened to an edge, that edge's code (else -1). pencil: two of its edges are parallel, so its
    lines lie in their plane and turn about the point where the third edge crosses it (a planar pencil, not a
    regulus; see has_parallel_edges). terminal: the moved line stops at one of its outer generators (enters
    the object there) instead of going on past it, as every line of the paper's figures does. in_face_plane:
    the family keeps to a face's plane (the moved line lies in it, or two of its edges bound a face whose plane
    holds the node's line): such lines slide over the face, where the air test cannot judge them, so the move
    is listed without being judged."""

    generators: tuple[int, ...]
    direction: int
    dropped: tuple[int, int]
    pencil: bool
    terminal: bool
    in_face_plane: bool


class SceneGeometry:
    """The scene as the oracle reads it: vertices (V, 3), edges (E, 2), each polygon's corners, unit normal and
    plane offset, and whether its object is closed (every edge of its faces shared by two of them); open
    objects (a light panel) block lines crossing them but enclose no solid."""

    def __init__(self, scene):
        self.vertices = np.asarray(scene.vertices, dtype=np.float64)
        self.edges = np.asarray(scene.edges, dtype=np.int64)
        self.n_vertices = len(self.vertices)
        self.diagonal = float(scene.diagonal)
        self.margin = MARGIN * self.diagonal
        self.normals = np.asarray(scene.normals, dtype=np.float64)
        self.offsets = np.asarray(scene.plane_offsets, dtype=np.float64)
        self.corners = [np.asarray(scene.polygon(p), dtype=np.float64) for p in range(scene.n_polygons)]
        # each polygon's sides as (P, K, 3) corners and unit inward normals in its plane, the sides of polygons
        # with fewer than K corners repeated, so that every polygon is tested at once
        k = max(len(c) for c in self.corners)
        self.side_points = np.empty((len(self.corners), k, 3))
        self.side_inward = np.empty((len(self.corners), k, 3))
        for polygon, corners in enumerate(self.corners):
            inward = np.cross(self.normals[polygon], np.roll(corners, -1, axis=0) - corners)
            inward /= np.linalg.norm(inward, axis=1)[:, None]
            pad = k - len(corners)
            self.side_points[polygon] = np.concatenate([corners, np.repeat(corners[-1:], pad, axis=0)])
            self.side_inward[polygon] = np.concatenate([inward, np.repeat(inward[-1:], pad, axis=0)])
        object_ids = np.asarray(scene.object_ids)
        faces_per_edge = np.diff(scene.edge_face_offsets)
        polygon_edges = np.split(np.asarray(scene.polygon_edge_ids), scene.polygon_offsets[1:-1])
        open_objects = {int(object_ids[p]) for p, ids in enumerate(polygon_edges) if (faces_per_edge[ids] != 2).any()}
        self.closed = np.array([int(o) not in open_objects for o in object_ids])
        self.edges_at = [np.flatnonzero((self.edges == v).any(axis=1)) for v in range(self.n_vertices)]
        self.faces_of = {
            self.n_vertices + e: {
                int(f) for f in scene.edge_faces[scene.edge_face_offsets[e] : scene.edge_face_offsets[e + 1]]
            }
            for e in range(len(self.edges))
        }
        self.elements = [
            {int(v) for v in scene.polygon_vertices(p)} | {self.n_vertices + int(e) for e in edge_ids}
            for p, edge_ids in enumerate(polygon_edges)
        ]

    # ---- elements -------------------------------------------------------------------------------------------

    def is_vertex(self, code: int) -> bool:
        return code < self.n_vertices

    def edge_ends(self, code: int) -> tuple[np.ndarray, np.ndarray]:
        """The two end points (3,) of the edge with this code, first vertex first."""
        a, b = self.edges[code - self.n_vertices]
        return self.vertices[a], self.vertices[b]

    def has_parallel_edges(self, codes) -> bool:
        """Whether two of the edges among the codes are parallel (to rounding)."""
        directions = [np.subtract(*self.edge_ends(code)) for code in codes if not self.is_vertex(code)]
        directions = [d / np.linalg.norm(d) for d in directions]
        return any(np.linalg.norm(_cross(a, b)) < 1e-12 for i, a in enumerate(directions) for b in directions[i + 1 :])

    def edge_point(self, code: int, s: float) -> np.ndarray:
        a, b = self.edge_ends(code)
        return a + s * (b - a)

    def contact(self, code: int, origin: np.ndarray, direction: np.ndarray) -> tuple[float, float, float]:
        """(tau, s, gap): where the line origin + tau direction (unit) comes closest to the element, the
        coordinate s of that point on an edge (0..1 from its first vertex; nan for a vertex), and the distance."""
        if self.is_vertex(code):
            point = self.vertices[code]
            tau = float((point - origin) @ direction)
            return tau, np.nan, float(np.linalg.norm(origin + tau * direction - point))
        a, b = self.edge_ends(code)
        along = b - a
        # closest points of two lines: the 2 x 2 normal equations, by Cramer's rule
        uu, ua, aa = direction @ direction, direction @ along, along @ along
        ru, ra = (a - origin) @ direction, (a - origin) @ along
        determinant = ua * ua - uu * aa
        tau = (ua * ra - aa * ru) / determinant
        s = (uu * ra - ua * ru) / determinant
        gap = float(np.linalg.norm(origin + tau * direction - (a + s * along)))
        return float(tau), float(s), gap

    # ---- lines and the scene --------------------------------------------------------------------------------

    def crossings(self, origin: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(tau (M,), polygon (M,), depth (M,)): where the line meets the polygons' closed outlines (depth: the
        distance from the point to the outline, negative outside; points with depth > -margin are kept). A
        line parallel to a plane meets no polygon of it."""
        rate = self.normals @ direction
        with np.errstate(divide="ignore", invalid="ignore"):
            tau = -(self.normals @ origin + self.offsets) / rate
        points = origin + tau[:, None] * direction
        depth = np.einsum("pkj,pkj->pk", points[:, None, :] - self.side_points, self.side_inward).min(axis=1)
        # a line within rounding of parallel to a plane meets it nowhere near the scene
        met = (np.abs(rate) > 1e-14) & (depth > -self.margin)
        polygons = np.flatnonzero(met)
        return tau[polygons], polygons, depth[polygons]

    def in_air(self, point: np.ndarray) -> bool:
        """Whether the point is in the air of the scene: the first closed face a ray from it meets is seen from
        its front. A ray meeting its first face well inside the outline decides; else, of several rays, the one
        meeting it deepest inside."""
        deepest, verdict = -np.inf, False
        for probe in _PROBES:
            tau, polygon, depth = self.crossings(point, probe)
            ahead = (tau > 0.0) & self.closed[polygon]
            if not ahead.any():
                return False
            first = np.flatnonzero(ahead)[np.argmin(tau[ahead])]
            if depth[first] > deepest:
                deepest, verdict = depth[first], bool(self.normals[polygon[first]] @ probe < 0.0)
            if deepest > _CLEAR * self.diagonal:
                break
        return verdict

    def free_between(self, origin: np.ndarray, direction: np.ndarray, generators, taus: np.ndarray) -> bool:
        """Whether the line origin + tau direction is free from the first to the last of its generators (codes)
        met at taus: no panel crossed inside, and air between any two consecutive contacts with the scene."""
        lo, hi = float(np.min(taus)), float(np.max(taus))
        tau, polygon, depth = self.crossings(origin, direction)
        # a line through a generator meets the planes of the faces around it there; computed, that point
        # strays from the generator as the line nears the plane, and would pass for a crossing of the face
        around = np.array([not self.elements[p].isdisjoint(generators) for p in polygon], dtype=bool)
        inside = (tau > lo) & (tau < hi) & ~around
        if (inside & ~self.closed[polygon] & (depth > self.margin)).any():
            return False
        # a line through a corner or an edge meets several faces there, at positions equal up to rounding
        events = np.sort(np.concatenate([taus, tau[inside]]))
        events = events[np.concatenate([[True], np.diff(events) > self.margin])]
        middles = 0.5 * (events[:-1] + events[1:])
        return all(self.in_air(origin + middle * direction) for middle in middles)

    def bound_a_face_holding(self, codes, origin: np.ndarray, direction: np.ndarray) -> bool:
        """Whether two of the edges among the codes bound one face whose plane holds the line: the lines meeting
        both near it lie in that plane (the others pass through the edges' common vertex, or nowhere near)."""
        faces = [self.faces_of[code] for code in codes if not self.is_vertex(code)]
        shared = set().union(*(a & b for i, a in enumerate(faces) for b in faces[i + 1 :]))
        return any(
            abs(self.normals[f] @ direction) <= MEETS
            and abs(self.normals[f] @ origin + self.offsets[f]) <= MEETS * self.diagonal
            for f in shared
        )

    def lies_along_an_edge(self, origin: np.ndarray, direction: np.ndarray) -> bool:
        """Whether the line holds a whole edge of the scene (both its ends within MEETS of the line)."""
        ends = self.vertices[self.edges] - origin
        gaps = np.linalg.norm(np.cross(ends, direction), axis=2)
        return bool((gaps.max(axis=1) <= MEETS * self.diagonal).any())

    def lies_in_a_face_plane(self, origin: np.ndarray, direction: np.ndarray) -> bool:
        """Whether the line lies in the plane of a polygon and meets its outline (it slides over the face)."""
        parallel = np.abs(self.normals @ direction) <= MEETS
        inside = np.abs(self.normals @ origin + self.offsets) <= MEETS * self.diagonal
        for polygon in np.flatnonzero(parallel & inside):
            side = (self.corners[polygon] - origin) @ _cross(self.normals[polygon], direction)
            if side.min() <= self.margin and side.max() >= -self.margin:
                return True
        return False


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The cross product of two 3-vectors (np.cross costs tens of times more on one pair)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


# ---- families of lines ----------------------------------------------------------------------------------------


def family_line(geometry: SceneGeometry, kept: tuple[int, ...], s: float) -> tuple[np.ndarray, np.ndarray] | None:
    """The line (origin (3,), unit direction (3,)) of the family meeting the kept generators (a vertex and an
    edge, or three edges) whose contact with the family's parameter edge (its lowest edge code) is at s; None
    when the third edge lies in the plane of that point and the second edge (two edges of one face)."""
    edges = sorted(code for code in kept if not geometry.is_vertex(code))
    vertices = [code for code in kept if geometry.is_vertex(code)]
    p = geometry.edge_point(edges[0], s)
    if vertices:
        q = geometry.vertices[vertices[0]]
    else:
        # the line through p meeting the second edge lies in the plane of p and that edge; it meets the third
        # edge's line where that line crosses the plane
        b0, b1 = geometry.edge_ends(edges[1])
        c0, c1 = geometry.edge_ends(edges[2])
        normal = _cross(b0 - p, b1 - b0)
        if float(normal @ (c1 - c0)) == 0.0:
            return None
        t = float(normal @ (p - c0)) / float(normal @ (c1 - c0))
        q = c0 + t * (c1 - c0)
    direction = q - p
    return p, direction / np.linalg.norm(direction)


def _relaxed_families(geometry: SceneGeometry, generators: tuple[int, ...]):
    """[(kept generators, dropped (code, loosened-to edge code or -1))] of a node's generators (codes)."""
    families = []
    for code in generators:
        others = tuple(c for c in generators if c != code)
        if geometry.is_vertex(code):
            for edge in geometry.edges_at[code]:
                families.append((others + (geometry.n_vertices + int(edge),), (code, geometry.n_vertices + int(edge))))
        else:
            families.append((others, (code, -1)))
    return families


def is_critical(geometry: SceneGeometry, origin, direction, generators) -> bool:
    """Whether the line meets every generator (codes) inside it and is free between the first and the last."""
    taus = []
    for code in generators:
        tau, s, gap = geometry.contact(code, origin, direction)
        if gap > MEETS * geometry.diagonal:
            return False
        if not geometry.is_vertex(code) and not 0.0 < s < 1.0:
            return False
        taus.append(tau)
    return geometry.free_between(origin, direction, generators, np.array(taus))


def goes_on_past_its_ends(geometry: SceneGeometry, origin, direction, generators) -> bool:
    """Whether the line (origin (3,), unit direction (3,)) is in air just beyond its first and its last
    generator (codes): tangent there rather than stopping."""
    taus = np.array([geometry.contact(code, origin, direction)[0] for code in generators])
    beyond = BEYOND * geometry.diagonal
    before, after = origin + (taus.min() - beyond) * direction, origin + (taus.max() + beyond) * direction
    return geometry.in_air(before) and geometry.in_air(after)


def node_relaxations(geometry: SceneGeometry, generators, origin, direction) -> list[Relaxation]:
    """The arcs a node must have: generators, the node's generator codes; origin (3,), direction (3,) its line.
    For each relaxed constraint and each way along the family, the line a step away is tested by is_critical;
    the moves keeping to a face's plane are listed unjudged (Relaxation.in_face_plane). Raises AssertionError
    when a family's line does not move continuously off the node (the oracle could not follow it)."""
    direction = np.asarray(direction, dtype=np.float64) / np.linalg.norm(direction)
    origin = np.asarray(origin, dtype=np.float64)
    found = []
    for kept, dropped in _relaxed_families(geometry, tuple(int(c) for c in generators)):
        parameter_edge = min(code for code in kept if not geometry.is_vertex(code))
        _, s_node, _ = geometry.contact(parameter_edge, origin, direction)
        a, b = geometry.edge_ends(parameter_edge)
        step = STEP * geometry.diagonal / float(np.linalg.norm(b - a))
        pencil = geometry.has_parallel_edges(kept)
        confined = geometry.bound_a_face_holding(kept, origin, direction)
        for way in (1, -1):
            moved = None if confined else family_line(geometry, kept, s_node + way * step)
            if moved is None or geometry.lies_in_a_face_plane(*moved):
                found.append(Relaxation(tuple(sorted(kept)), way, dropped, pencil, False, True))
                continue
            if not _follows(geometry, kept, s_node, way * step, origin, direction):
                raise AssertionError(f"the family {kept} jumps away from the line {origin} + t {direction}")
            if is_critical(geometry, *moved, kept):
                terminal = not goes_on_past_its_ends(geometry, *moved, kept)
                found.append(Relaxation(tuple(sorted(kept)), way, dropped, pencil, terminal, False))
    return found


def _follows(geometry: SceneGeometry, kept, s_node: float, step: float, origin, direction) -> bool:
    """Whether the family's line moves continuously off the node: a tenth of the step moves it a tenth as far
    (lines solved elsewhere, through a vertex the family's edges share, would not come nearer)."""

    def moved_by(fraction: float) -> float:
        moved_origin, moved_direction = family_line(geometry, kept, s_node + fraction * step)
        turned = np.linalg.norm(_cross(moved_direction, direction))
        shifted = np.linalg.norm(_cross(moved_origin - origin, direction)) / geometry.diagonal
        return turned + shifted

    return moved_by(0.1) < 0.2 * moved_by(1.0)
