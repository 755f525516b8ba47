"""Node enumeration of the Visibility Skeleton: the candidate extremal stabbing lines that validation casts.

Durand, Drettakis & Puech 1997 (seed 003), sections 3.2.1-3.2.3 and 5. Every node is a line through a set
of generators (VV: two vertices; VEE / EVE: a vertex and two edges; E4: four edges; FEE / EFE: a face's
plane and two edges crossing it, the face's two crossed edges standing for the face) on which the part
between the outer generators is free. This module proposes such lines; `core.skeleton.validation` casts
each through the scene and keeps the nodes. It must propose every line validation would accept (a lost
candidate is a lost node) and as few others as it can, since validation costs a ray cast per candidate.

What prunes, and why each prune is safe (validation rejects every line pruned here):

* Occlusion maps (the role of the paper's grid acceleration and double wedges, section 3.2.2). Around a
  source (a vertex, or a short piece -- a *bin* -- of an edge) the directions are cut into the cells of a
  cube map. A polygon whose interior (shrunk by a margin) is crossed by every line leaving the source
  through a cell gives that cell a depth bound: every such line hits the polygon's interior within it, and
  a polygon interior strictly between the outer generators of a line makes validation reject it. A line's
  generators must therefore lie within the depth bound of its cell, on both sides of the source.
* Restriction (section 3.2.2). Target edges are registered in the cells their directions from the source
  cross, only where they lie within the cell's depth bound; lines are solved only for generators sharing a
  cell, and each line is kept by the one cell (and bin) that contains it, so none is proposed twice.
* Local visibility (section 3.2, "the negative half-space of a face is locally invisible"). A generator
  between two others on the line must be grazed, not pierced: when the faces around it close around the
  line (the test validation applies to inner generators), the line is dropped. Only decisions clear by an
  angular margin prune; near-sliding faces keep the line. The source edge of an E4 line is inner: a target
  edge lying wholly where the lines from e pierce e's faces (across e from both, or inside them) is dropped
  from e's targets before any registration (_target_pierces: a tenth to a fifth of the E4 time in the offices).
* Sub-cells. Each registration also records which of an 8 x 8 split of its cell the directions from the
  source to the target reach (grown by the snap margin over the target's distance, the turn of a line that
  validation still lets meet it). The generators of one line share the sub-cell of its direction, so curves
  and pairs that share none are not solved.
* Coplanar pivots. The lines E(s) X(t) of a pivot x lying in one plane with the source edge stay within a height
  of that plane bounded by x's height over it and tol (_plane_reach): a target lying beyond that height on one
  side is met by none of them and is not paired.
* Planes through the vertex. A VEE line through v meets edges f and g on the line where the planes (v, f)
  and (v, g) meet: a pair whose edge lies wholly on one side of the other's plane (beyond what _meets_segment
  tolerates, and rounding) is not solved (_off_plane).
* One line, one source edge. An E4 line is kept from its inner edge of lowest id, and the other inner edge
  is one of the two generators on the side holding two: pairs whose two generators there both have lower
  ids than the source edge are not solved (their line is kept from a lower edge).
* Lazy construction (section 5): with `sources`, cells whose lines cannot cross a source polygon are skipped
  and every proposed line crosses one (within tol, a line in a source's plane counting as crossing, as for
  the skeleton's record of built sources). An E4 pivot is dropped before its curves are tested when none
  of its lines E(s) X(t) can pass on one side of all the edges of a source: for each source, over the whole
  (s, t) region, the Pluecker side against one edge is strictly negative and against another strictly
  positive. Before any clipping, a target (or an occluder of the depth maps) is skipped when no line through
  the source bin and a source's bounding sphere passes through the target's bounding sphere (the double
  cones of directions from the bin's middle, both spheres grown by the bin's half length).

Outer generators get no local test: validation lets a line stop on its outer generators (a line leaving a
floor corner), so a VV pair is never culled by the faces at its vertices, only by occlusion.

Candidates: VV pairs of masked vertices; VEE lines through a masked vertex meeting two masked edges not
incident to it (and not sharing a vertex: such a line passes through the shared vertex, where validation
finds no edge contact); E4 transversals of four masked edges with pairwise distinct vertices, the roots of a
quadratic (section 3.2.2 finds them by a binary search; the closed form is exact); FEE lines in the plane of
a polygon through the crossings of two masked edges with it, crossing the polygon through two masked edges
(section 3.2.3; pruned by local visibility only: a face's plane holds few crossings). Edges with one face
(boundaries) and vertices of open surfaces are handled by the same tests.

Every threshold comes from scene.tol: lengths are multiples of tol.length (`tol.snap` is the occlusion
margin), angles are tol.snap / tol.scale (the angle under which tol.snap is seen across the scene).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from numba import njit

from ..errors import CancelledError, SceneError
from ..jit import njit_leaf
from ..raycast import CONTACT_VERTEX, _arcs_cover_circle_with, _contact_arc, _perpendicular_frame
from ..scene import Scene
from .candidates import CANDIDATE_E4, CANDIDATE_FEE, CANDIDATE_FXE, CANDIDATE_VEE, CANDIDATE_VV, NodeCandidates
from .topology import Topology, scene_topology
from .validation import WORKERS, _shared_face

DEFAULT_CHUNK = 100_000
"""Largest number of candidates in one yielded chunk by default (about one second of validation)."""

MIN_CELLS = 1
MAX_CELLS = 15
EDGES_PER_CELL = 230.0
"""Cells per side of each cube-map face, between MIN_CELLS and MAX_CELLS: 3 cells**2 line directions (a line and
its opposite share one). Finer cells prune more but repeat the work of every pair of targets the cells share;
the best count grows with the scene, about one cell per side per EDGES_PER_CELL masked edges (_cells_per_side)."""

BIN_CELLS = 0.4
"""An edge source is cut into bins no longer than this fraction of the scene diagonal over the cells per side
(at most MAX_BINS): finer cells, shorter bins. Measured on the office family (E4 enumeration, one thread)
against bins of 1/12 of the diagonal: 1 % faster at 312 polygons and 6 % at 756 with this rule; 6 % at 1056
and 12 % at 1488 with 0.03 of the diagonal (the rule gives 0.036 and 0.031)."""

MAX_BINS = 8

_CLIP = 40
"""Vertex capacity of the clipping buffers (a quad clipped by 9 planes has at most 13 vertices)."""

_PIVOT_SLACK = 2.0
"""How many tol lengths off its pivot edge an E4 root may fall before the line is turned away unchecked."""

_VERTEX_BATCH = 24
_EDGE_BATCH = 12
_FACE_BATCH = 32

Cancel = Callable[[], bool]


# ----------------------------------------------------------------------------------------------------------
# public entry point


def iter_candidates(
    scene: Scene,
    vertex_mask,
    edge_mask,
    sources=None,
    chunk: int = DEFAULT_CHUNK,
    cancel: Cancel | None = None,
    workers: int = WORKERS,
    topology: Topology | None = None,
) -> Iterator[tuple[NodeCandidates, float]]:
    """Yield (candidates, fraction done) until every candidate line of the scene is proposed.

    scene: core.scene.Scene. vertex_mask (V,) bool: the vertices that may generate nodes. edge_mask (E,) bool:
    the edges that may (not flat). sources: None for every line, or polygon ids: only lines crossing one of
    them (within tol; seed 003 section 5). chunk: most candidates per yielded NodeCandidates (>= 1).
    cancel: a callable checked between chunks; CancelledError is raised when it returns True. workers: threads
    running work units at once (the kernels release the GIL); the candidates do not depend on it. topology: the
    scene's core.skeleton.topology.scene_topology when the caller has it (made here otherwise).

    Chunks are never empty; fractions increase strictly and the last one is 1.0. Each candidate appears
    once: VV with vertices (v, w), v < w; VEE with edges sorted; E4 and FEE with their four edges sorted.
    """
    vmask, emask, polygons, chunk = _check_arguments(scene, vertex_mask, edge_mask, sources, chunk)
    if cancel is not None and not callable(cancel):
        raise ValueError("cancel must be a callable returning bool, or None")
    lazy = polygons is not None
    src = np.empty(0, dtype=np.int64) if polygons is None else polygons

    vertex_ids = np.flatnonzero(vmask).astype(np.int64)
    edge_ids = np.flatnonzero(emask).astype(np.int64)
    cells = _cells_per_side(len(edge_ids))
    geometry = _Geometry(scene, cells, scene_topology(scene) if topology is None else topology)
    lengths = np.linalg.norm(
        scene.vertices[scene.edges[edge_ids, 1]] - scene.vertices[scene.edges[edge_ids, 0]], axis=1
    )
    bins = np.clip(np.ceil(lengths * cells / (BIN_CELLS * scene.diagonal)), 1, MAX_BINS).astype(np.int64)

    # work units, for the fraction: a vertex map, its VV and VEE lines, an edge bin's E4 lines, a face's lines
    steps = []
    for lo in range(0, len(vertex_ids), _VERTEX_BATCH):
        steps.append(("map", lo, min(lo + _VERTEX_BATCH, len(vertex_ids)), 1.0))
    for lo in range(0, len(vertex_ids), _VERTEX_BATCH):
        steps.append(("vertex", lo, min(lo + _VERTEX_BATCH, len(vertex_ids)), 3.0))
    for lo in range(0, len(edge_ids), _EDGE_BATCH):
        hi = min(lo + _EDGE_BATCH, len(edge_ids))
        steps.append(("edge", lo, hi, 2.0 * float(bins[lo:hi].sum()) / max(1, hi - lo)))
    polygon_ids = np.arange(scene.n_polygons, dtype=np.int64) if len(edge_ids) else np.empty(0, dtype=np.int64)
    for lo in range(0, len(polygon_ids), _FACE_BATCH):
        steps.append(("face", lo, min(lo + _FACE_BATCH, len(polygon_ids)), 1.0))
    if len(edge_ids):
        steps.append(("crossing", 0, 1, 1.0))
        steps.append(("crossing plane", 0, 1, 1.0))
        steps.append(("crossing transversal", 0, 1, 1.0))
        steps.append(("junction", 0, 1, 1.0))
    weights = np.array([(s[2] - s[1]) * s[3] for s in steps], dtype=np.float64)
    total = float(weights.sum()) if len(weights) else 1.0

    g = geometry
    crossings = _edge_crossings(emask, g.vertices, g.edges, g.tol)
    # E4 lines of the edge phase through a crossing of two of their edges, their lines by their four edges: the
    # edge phase proposes each once (_once_through_crossings); the crossing transversals propose them all and keep
    # only the others
    through_crossings: dict[tuple[int, ...], list] = {}
    n_cells = 3 * cells * cells
    vertex_depth = np.full((scene.n_vertices, 2, n_cells), np.inf)
    pending: NodeCandidates | None = None
    pending_fraction = 0.0
    done = 0.0
    buffer: list[NodeCandidates] = []
    buffered = 0

    def check_cancel():
        if cancel is not None and cancel():
            raise CancelledError("node enumeration cancelled")

    def run(step):
        phase, lo, hi, _ = step
        if phase == "map":
            _vertex_maps(
                vertex_ids[lo:hi], g.vertices, g.points, g.offsets, g.normals, g.plane_offsets, g.edge_out,
                g.centres, g.radii, g.widths, g.cell_sine, *g.objects, g.grid, cells, g.margin, g.delta, g.eps, lazy,
                src, g.tol, vertex_depth,
            )  # fmt: skip
            return None
        if phase == "vertex":
            return _vertex_candidates(
                vertex_ids, lo, hi, vmask, emask, g.vertices, g.edges, g.points, g.offsets, g.normals,
                g.plane_offsets, g.edge_out, g.vf_off, g.vf_face, g.vf_corner, g.ve_off, g.ve_edge, g.ef_off,
                g.ef_face, g.ef_inward, g.vertex_object, g.edge_object, g.objects[0], g.objects[1], g.centres,
                g.radii, g.grid, cells, vertex_depth, lazy, src, g.margin, g.delta, g.eps, g.tol, g.angle_tol, g.scale,
            )  # fmt: skip
        if phase == "crossing":
            return _crossing_candidates(
                vmask, g.vertices, g.edges, g.points, g.offsets, g.normals, g.plane_offsets, g.edge_out, *crossings,
                cells, lazy, src, g.tol, g.angle_tol,
            )  # fmt: skip
        if phase == "crossing plane":
            return _crossing_plane_candidates(
                emask, g.vertices, g.edges, g.points, g.offsets, g.normals, g.plane_offsets, g.edge_out, *crossings,
                cells, lazy, src, g.tol, g.angle_tol,
            )  # fmt: skip
        if phase == "crossing transversal":
            return _crossing_transversal_candidates(
                emask, g.vertices, g.edges, g.points, g.offsets, g.normals, g.plane_offsets, g.edge_out,
                g.vertex_object, g.edge_object, g.objects[0], g.objects[1], g.vf_off, g.vf_face, g.ef_off, g.ef_face,
                *crossings, cells, lazy, src, g.margin, g.delta, g.tol, g.angle_tol,
            )  # fmt: skip
        if phase == "junction":
            return _junction_candidates(
                vmask, emask, g.vertices, g.edges, g.ve_off, g.ve_edge, g.points, g.offsets, g.normals,
                g.plane_offsets, g.edge_out, cells, lazy, src, g.tol, g.angle_tol,
            )  # fmt: skip
        if phase == "face":
            return _face_candidates(
                polygon_ids, lo, hi, emask, g.vertices, g.edges, g.points, g.offsets, g.normals, g.plane_offsets,
                g.edge_out, g.corner_edge, g.vertex_object, g.edge_object, g.objects[0], g.objects[1], g.vf_off,
                g.vf_face, g.ef_off, g.ef_face, g.centres, g.radii, lazy, src, g.margin, g.delta, g.tol, g.angle_tol,
            )  # fmt: skip
        return _edge_candidates(
            edge_ids[lo:hi], bins[lo:hi], emask, g.vertices, g.edges, g.points, g.offsets, g.normals,
            g.plane_offsets, g.edge_out, g.centres, g.radii, g.widths, g.cell_sine, *g.objects, g.ef_off, g.ef_face,
            g.ef_inward, g.vf_off, g.vf_face, g.vertex_object, g.edge_object, g.grid, cells,
            lazy, src, g.margin, g.delta, g.eps, g.tol, g.angle_tol, g.scale,
        )  # fmt: skip

    n_maps = sum(1 for step in steps if step[0] == "map")
    for index, found in enumerate(_in_order(run, steps, n_maps, workers, check_cancel)):
        before = done / total
        done += weights[index]
        after = done / total
        if found is not None and steps[index][0] == "edge" and len(crossings[0]):
            found = _once_through_crossings(found, crossings, len(scene.edges), g.tol, g.scale, through_crossings)
        if found is not None and steps[index][0] == "crossing transversal":
            found = _not_proposed(found, through_crossings)
        if found is not None and len(found[0]):
            buffer.append(NodeCandidates(*found))
            buffered += len(found[0])
        last = index == len(steps) - 1
        # cut the buffer into chunks; the newest chunk waits, so that the very last one can carry 1.0, and the
        # k-th chunk cut in this step gets a fraction between the step's start and end, strictly increasing
        cut = 0
        while buffered >= chunk or (last and buffered > 0):
            merged = NodeCandidates.concatenate(buffer)
            head = _slice(merged, 0, min(chunk, len(merged)))
            rest = _slice(merged, len(head), len(merged))
            buffer = [rest] if len(rest) else []
            buffered = len(rest)
            cut += 1
            fraction = before + (after - before) * cut / (cut + 1.0)
            fraction = max(fraction, float(np.nextafter(pending_fraction, 2.0)))
            if pending is not None:
                check_cancel()
                yield pending, pending_fraction
            pending, pending_fraction = head, fraction
    if pending is not None:
        check_cancel()
        yield pending, 1.0


def _in_order(run, steps: list, n_first: int, workers: int, check_cancel) -> Iterator:
    """run(step) for every step, on `workers` threads, yielding the results in step order. The first n_first
    steps all finish before any later one starts (they fill the maps the later ones read); at most two results
    per worker wait to be yielded, so memory does not grow with the number of steps."""
    if workers <= 1:
        for step in steps:
            check_cancel()
            yield run(step)
        return
    with ThreadPoolExecutor(workers) as pool:
        pending: deque = deque()
        yield from pool.map(run, steps[:n_first])
        for step in steps[n_first:]:
            if len(pending) >= 2 * workers:
                yield pending.popleft().result()
            check_cancel()
            pending.append(pool.submit(run, step))
        while pending:
            yield pending.popleft().result()


def _slice(c: NodeCandidates, lo: int, hi: int) -> NodeCandidates:
    return NodeCandidates(c.kind[lo:hi], c.vertices[lo:hi], c.edges[lo:hi], c.origin[lo:hi], c.direction[lo:hi])


def _check_arguments(scene, vertex_mask, edge_mask, sources, chunk):
    if not isinstance(scene, Scene):
        raise SceneError(f"scene must be a core.scene.Scene, got {type(scene).__name__}")
    vmask = np.asarray(vertex_mask)
    emask = np.asarray(edge_mask)
    if vmask.shape != (scene.n_vertices,) or vmask.dtype != np.bool_:
        raise SceneError(f"vertex_mask must be a ({scene.n_vertices},) bool array, got {vmask.shape} {vmask.dtype}")
    if emask.shape != (len(scene.edges),) or emask.dtype != np.bool_:
        raise SceneError(f"edge_mask must be a ({len(scene.edges)},) bool array, got {emask.shape} {emask.dtype}")
    if isinstance(chunk, bool) or not isinstance(chunk, int | np.integer) or chunk < 1:
        raise ValueError(f"chunk must be a positive integer, got {chunk!r}")
    polygons = None
    if sources is not None:
        try:
            ids = np.asarray(list(sources))
        except TypeError:
            raise SceneError("sources must be None or an iterable of polygon ids") from None
        if ids.size and not np.issubdtype(ids.dtype, np.integer):
            raise SceneError(f"sources must hold polygon ids (integers), got dtype {ids.dtype}")
        ids = np.unique(ids.astype(np.int64))
        bad = ids[(ids < 0) | (ids >= scene.n_polygons)]
        if len(bad):
            raise SceneError(f"source {int(bad[0])} is not a polygon of the scene (0..{scene.n_polygons - 1})")
        polygons = ids
    return np.ascontiguousarray(vmask), np.ascontiguousarray(emask), polygons, int(chunk)


class _Geometry:
    """The scene arrays the kernels read, and the derived ones: outward edge normals of every polygon (in its
    plane, unit), bounding spheres, adjacency (core.skeleton.topology), the inward direction of each face
    across each of its edges, the cube-map grid, and the thresholds from scene.tol."""

    def __init__(self, scene: Scene, cells: int, topology: Topology):
        self.vertices = scene.vertices
        self.edges = scene.edges
        self.points = scene.polygon_points
        self.offsets = scene.polygon_offsets
        self.normals = scene.normals
        self.plane_offsets = scene.plane_offsets
        counts = np.diff(self.offsets)
        owner = np.repeat(np.arange(scene.n_polygons), counts)
        following = self.offsets[owner] + (np.arange(len(self.points)) - self.offsets[owner] + 1) % counts[owner]
        along = self.points[following] - self.points
        out = np.cross(along, self.normals[owner])
        self.edge_out = out / np.linalg.norm(out, axis=1)[:, None]
        self.centres = scene.centroids
        reach = np.linalg.norm(self.points - self.centres[owner], axis=1)
        self.radii = np.maximum.reduceat(reach, self.offsets[:-1])
        self.widths = _polygon_widths(self.points, self.offsets, self.edge_out)
        self.cell_sine = _cell_half_sine(cells)
        self.vf_off = topology.vertex_face_offsets
        self.vf_face = topology.vertex_faces
        self.vf_corner = topology.vertex_face_corner
        self.ve_off = topology.vertex_edge_offsets
        self.ve_edge = topology.vertex_edges
        self.ef_off = scene.edge_face_offsets
        self.corner_edge = scene.polygon_edge_ids
        self.ef_face = scene.edge_faces
        # inward direction of face f across edge e: normal x (edge direction as f runs along it)
        local = topology.edge_face_local
        start = self.offsets[self.ef_face] + local
        end = self.offsets[self.ef_face] + (local + 1) % counts[self.ef_face]
        inward = np.cross(self.normals[self.ef_face], self.points[end] - self.points[start])
        self.ef_inward = inward / np.linalg.norm(inward, axis=1)[:, None] if len(inward) else inward.reshape(0, 3)
        self.grid = _grid_directions(cells)
        tol = scene.tol
        self.objects = _convex_objects(scene, tol.snap)
        # the convex object each vertex and edge belongs to (-1: none, or faces of several objects)
        polygon_object = np.full(scene.n_polygons, -1, dtype=np.int64)
        object_offsets, object_polygons = self.objects[0], self.objects[1]
        polygon_object[object_polygons] = np.repeat(np.arange(len(object_offsets) - 1), np.diff(object_offsets))
        self.vertex_object = _element_object(self.vf_off, self.vf_face, polygon_object)
        self.edge_object = _element_object(self.ef_off, self.ef_face, polygon_object)
        self.tol = tol.length
        self.scale = tol.scale
        self.margin = tol.snap
        self.delta = tol.snap / tol.scale
        self.eps = tol.relative
        self.angle_tol = tol.cosine


def _cells_per_side(n_edges: int) -> int:
    """Cube-map cells per side for a scene of n_edges masked edges: the odd count nearest n_edges / EDGES_PER_CELL,
    within [MIN_CELLS, MAX_CELLS]. Odd, so that the axis directions lie inside cells, not on their borders:
    the lines in the planes of axis-aligned faces (most of a furnished room) would otherwise fall on a border,
    and their targets register in the cells on both sides. Finer cells prune more pairs of targets but cost
    more occlusion maps and register each target in more cells; with the enumeration's other prunes the small
    scenes gain from coarse cells. Whole builds of the office family (AMD EPYC, 2 threads, medians, 2026-11-28),
    this rule's count against the earlier sqrt(n_edges) / 4 one: 84 polygons (180 edges) 1 against 3 cells
    0.200 / 0.216 s; 168 (348) 1 against 5 0.654 / 0.691 s; 312 (636) 3 against 7 2.17 / 2.15 s; 432 (876) 3
    against 7 3.82 / 4.05 s; 756 (1524) 7 against 9 11.96 / 12.05 s; 1056 (2124) 9 against 11 23.8 / 23.6 s;
    1488 (2988) 13 either way. The same nodes and arcs at every size."""
    return int(np.clip(2 * (n_edges / EDGES_PER_CELL // 2) + 1, MIN_CELLS, MAX_CELLS))


def _convex_objects(scene: Scene, margin: float):
    """The closed convex objects of the scene (boxes, mostly), as fused occluders: a line through the inside
    of one crosses its surface, whichever faces it meets. An object is used when every edge of its polygons
    joins exactly two of them and no vertex of it lies in front of one of its face planes (beyond margin).

    Returns polygon CSR (offsets (O+1,), polygon ids) and bounding spheres about the mean vertex (centres
    (O, 3), radii (O,)).
    """
    owner = scene.object_ids[scene.edge_faces]
    counts = np.diff(scene.edge_face_offsets)
    first = scene.edge_face_offsets[:-1]
    closed_edge = (counts == 2) & (owner[first] == owner[np.minimum(first + 1, len(owner) - 1)])
    open_objects = np.zeros(int(scene.object_ids.max()) + 1, dtype=bool)
    open_objects[owner[np.repeat(~closed_edge, counts)]] = True
    polygon_offsets = [0]
    polygon_ids: list[np.ndarray] = []
    centres: list[np.ndarray] = []
    radii: list[float] = []
    for obj in np.flatnonzero(~open_objects):
        polygons = np.flatnonzero(scene.object_ids == obj)
        if len(polygons) < 4:
            continue
        ids = np.unique(np.concatenate([scene.polygon_vertices(int(p)) for p in polygons]))
        points = scene.vertices[ids]
        heights = points @ scene.normals[polygons].T + scene.plane_offsets[polygons]
        if heights.max() > margin:
            continue
        polygon_ids.append(polygons)
        polygon_offsets.append(polygon_offsets[-1] + len(polygons))
        centre = points.mean(axis=0)
        away = points - centre
        centres.append(centre)
        radii.append(float(np.sqrt(away[:, 0] ** 2 + away[:, 1] ** 2 + away[:, 2] ** 2).max()))
    return (
        np.array(polygon_offsets, dtype=np.int64),
        np.concatenate(polygon_ids).astype(np.int64) if polygon_ids else np.empty(0, dtype=np.int64),
        np.array(centres, dtype=np.float64).reshape(-1, 3),
        np.array(radii, dtype=np.float64),
    )


def _element_object(offsets: np.ndarray, faces: np.ndarray, polygon_object: np.ndarray) -> np.ndarray:
    """For each element of a CSR element -> faces list: the object all its faces belong to, else -1."""
    count = len(offsets) - 1
    result = np.full(count, -1, dtype=np.int64)
    sizes = np.diff(offsets)
    owners = polygon_object[faces]
    has = sizes > 0
    first = np.where(has, owners[np.minimum(offsets[:-1], max(len(owners) - 1, 0))], -1) if len(owners) else result
    same = np.ones(count, dtype=bool)
    if len(owners):
        element = np.repeat(np.arange(count), sizes)
        np.logical_and.at(same, element, owners == first[element])
    result[has & same] = first[has & same]
    return result


def _polygon_widths(points: np.ndarray, offsets: np.ndarray, edge_out: np.ndarray) -> np.ndarray:
    """(P,) float64: the width of each convex polygon, its least extent across one of its edges, from its points
    (N, 3), offsets (P+1,) and outward unit edge normals (N, 3) (row j: the edge from point j to the next)."""
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(len(counts)), counts)
    per_edge = counts[owner]
    edge = np.repeat(np.arange(len(points)), per_edge)
    first = np.cumsum(per_edge) - per_edge
    corner = offsets[owner[edge]] + np.arange(len(edge)) - np.repeat(first, per_edge)
    depth = np.einsum("kc,kc->k", points[edge] - points[corner], edge_out[edge])
    return np.minimum.reduceat(np.maximum.reduceat(depth, first), offsets[:-1])


def _cell_half_sine(n: int) -> float:
    """sin of a lower bound on half the angle across any cube-map cell (n per side): the angle from a cell's
    middle direction to the nearest of its four border planes, least over the cells. The directions of a cell
    hold the cone of that half angle around its middle, and every wedge holding them opens by twice it."""
    ticks = -1.0 + 2.0 * np.arange(n + 1) / n
    lo, hi = ticks[:-1], ticks[1:]
    middle = 0.5 * (lo + hi)
    # sine of the angle from direction (1, u, w) to the plane x1 = t x0 is |u - t| / (|(1, u, w)| |(-t, 1)|)
    gap = np.minimum((middle - lo) / np.sqrt(1.0 + lo * lo), (hi - middle) / np.sqrt(1.0 + hi * hi))
    length = np.sqrt(1.0 + middle[:, None] ** 2 + middle[None, :] ** 2)
    return float(np.min(np.minimum(gap[:, None], gap[None, :]) / length))


def _grid_directions(n: int) -> np.ndarray:
    """(3, n+1, n+1, 3) unit directions of the grid corners of the three positive cube-map faces: face a holds
    the directions e_a + u e_b + w e_c (b = a+1, c = a+2 mod 3) with u, w = -1 + 2k/n."""
    grid = np.empty((3, n + 1, n + 1, 3))
    ticks = -1.0 + 2.0 * np.arange(n + 1) / n
    for a in range(3):
        b, c = (a + 1) % 3, (a + 2) % 3
        grid[a, :, :, a] = 1.0
        grid[a, :, :, b] = ticks[:, None]
        grid[a, :, :, c] = ticks[None, :]
    return grid / np.linalg.norm(grid, axis=3)[..., None]


# ----------------------------------------------------------------------------------------------------------
# small geometry (numba)


@njit_leaf
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _cross(a, b):
    out = np.empty(3)
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]
    return out


@njit_leaf
def _cross_row(a0, a1, a2, b0, b1, b2, out, row):
    """out[row] = a x b, without allocating."""
    out[row, 0] = a1 * b2 - a2 * b1
    out[row, 1] = a2 * b0 - a0 * b2
    out[row, 2] = a0 * b1 - a1 * b0


@njit_leaf
def _norm(a):
    return np.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])


@njit_leaf
def _line_cell(d, n):
    """The cell of a line of direction d (3,): (face axis a, i, j, flipped). The line's canonical direction
    has a positive dominant component (the first largest); flipped tells whether that is -d."""
    a = 0
    big = abs(d[0])
    if abs(d[1]) > big:
        a = 1
        big = abs(d[1])
    if abs(d[2]) > big:
        a = 2
    inv = 1.0 / d[a]
    u = d[(a + 1) % 3] * inv
    w = d[(a + 2) % 3] * inv
    i = int((u + 1.0) * 0.5 * n)
    j = int((w + 1.0) * 0.5 * n)
    i = min(max(i, 0), n - 1)
    j = min(max(j, 0), n - 1)
    return a, i, j, d[a] < 0.0


@njit_leaf
def _clip(src, count, ca, cb, cc, dst):
    """Sutherland-Hodgman: the part of the convex polygon src[:count] (chart coordinates) where
    ca x0 + cb x1 + cc x2 >= 0, written to dst; returns its vertex count (0 when nothing is left)."""
    out = 0
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        p0 = src[k, 0]
        p1 = src[k, 1]
        p2 = src[k, 2]
        fp = ca * p0 + cb * p1 + cc * p2
        fq = ca * src[k2, 0] + cb * src[k2, 1] + cc * src[k2, 2]
        if fp >= 0.0:
            dst[out, 0] = p0
            dst[out, 1] = p1
            dst[out, 2] = p2
            out += 1
        if (fp >= 0.0) != (fq >= 0.0):
            t = fp / (fp - fq)
            dst[out, 0] = p0 + t * (src[k2, 0] - p0)
            dst[out, 1] = p1 + t * (src[k2, 1] - p1)
            dst[out, 2] = p2 + t * (src[k2, 2] - p2)
            out += 1
    return out


@njit_leaf
def _clip_pyramid(buf_a, count, lo_u, hi_u, lo_w, hi_w, buf_b):
    """Clip a polygon in chart coordinates (x0 along the face axis) to the cone lo_u <= x1/x0 <= hi_u,
    lo_w <= x2/x0 <= hi_w (x0 >= 0); the result ends in buf_a; returns its count."""
    count = _clip(buf_a, count, -lo_u, 1.0, 0.0, buf_b)
    count = _clip(buf_b, count, hi_u, -1.0, 0.0, buf_a)
    count = _clip(buf_a, count, -lo_w, 0.0, 1.0, buf_b)
    count = _clip(buf_b, count, hi_w, 0.0, -1.0, buf_a)
    return count


@njit_leaf
def _clip_to_face(buf_a, count, eps, buf_b):
    """Clip the polygon buf_a[:count] (chart coordinates) to x0 >= 0 and the face's cone grown by eps (|x1|,
    |x2| <= (1 + eps) x0); the result ends in buf_a; returns its count. A polygon wholly behind the apex or wholly
    inside the cone is not clipped: the clips would drop, or keep, every point (the same tests below, the same
    arithmetic), and most polygons are one or the other."""
    grown = 1.0 + eps
    behind = True
    inside = True
    for r in range(count):
        x0 = buf_a[r, 0]
        x1 = buf_a[r, 1]
        x2 = buf_a[r, 2]
        if x0 >= 0.0:
            behind = False
        if not (x0 >= 0.0 and grown * x0 + x1 >= 0.0 and grown * x0 - x1 >= 0.0 and grown * x0 + x2 >= 0.0
                and grown * x0 - x2 >= 0.0):  # fmt: skip
            inside = False
    if behind:
        return 0
    if inside:
        return count
    m = _clip(buf_a, count, 1.0, 0.0, 0.0, buf_b)
    for r in range(m):
        for c in range(3):
            buf_a[r, c] = buf_b[r, c]
    return _clip_pyramid(buf_a, m, -1.0 - eps, grown, -1.0 - eps, grown, buf_b)


@njit_leaf
def _to_chart(points, count, a, sign, origin, out):
    """points[:count] - origin, times sign, in the coordinates of face axis a: (x_a, x_b, x_c)."""
    b = (a + 1) % 3
    c = (a + 2) % 3
    for k in range(count):
        out[k, 0] = sign * (points[k, a] - origin[a])
        out[k, 1] = sign * (points[k, b] - origin[b])
        out[k, 2] = sign * (points[k, c] - origin[c])


@njit_leaf
def _projected_box(buf, count):
    """(u_min, u_max, w_min, w_max) of the central projection of buf[:count] (x0 >= 0) onto x0 = 1; the
    whole face when a point sits at the apex."""
    u0 = np.inf
    u1 = -np.inf
    w0 = np.inf
    w1 = -np.inf
    for k in range(count):
        x0 = buf[k, 0]
        if not x0 > 0.0:
            return -1.0, 1.0, -1.0, 1.0
        u = buf[k, 1] / x0
        w = buf[k, 2] / x0
        u0 = min(u0, u)
        u1 = max(u1, u)
        w0 = min(w0, w)
        w1 = max(w1, w)
    return u0, u1, w0, w1


@njit_leaf
def _segment_distance(p0, p1, p2, q0, q1, q2):
    """Distance from the origin to the segment p-q (coordinates)."""
    d0 = q0 - p0
    d1 = q1 - p1
    d2 = q2 - p2
    dd = d0 * d0 + d1 * d1 + d2 * d2
    t = 0.0
    if dd > 0.0:
        t = min(1.0, max(0.0, -(p0 * d0 + p1 * d1 + p2 * d2) / dd))
    x0 = p0 + t * d0
    x1 = p1 + t * d1
    x2 = p2 + t * d2
    return np.sqrt(x0 * x0 + x1 * x1 + x2 * x2)


@njit_leaf
def _polygon_distance(buf, count):
    """Distance from the origin to the convex polygon buf[:count] (any count >= 1, duplicates allowed)."""
    best = np.inf
    n0 = 0.0
    n1 = 0.0
    n2 = 0.0
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        best = min(best, _segment_distance(buf[k, 0], buf[k, 1], buf[k, 2], buf[k2, 0], buf[k2, 1], buf[k2, 2]))
        n0 += buf[k, 1] * buf[k2, 2] - buf[k, 2] * buf[k2, 1]
        n1 += buf[k, 2] * buf[k2, 0] - buf[k, 0] * buf[k2, 2]
        n2 += buf[k, 0] * buf[k2, 1] - buf[k, 1] * buf[k2, 0]
    if count < 3:
        return best
    length = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    if length == 0.0:
        return best
    n0 /= length
    n1 /= length
    n2 /= length
    height = n0 * buf[0, 0] + n1 * buf[0, 1] + n2 * buf[0, 2]
    f0 = height * n0
    f1 = height * n1
    f2 = height * n2
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        e0 = buf[k2, 0] - buf[k, 0]
        e1 = buf[k2, 1] - buf[k, 1]
        e2 = buf[k2, 2] - buf[k, 2]
        r0 = f0 - buf[k, 0]
        r1 = f1 - buf[k, 1]
        r2 = f2 - buf[k, 2]
        if (e1 * r2 - e2 * r1) * n0 + (e2 * r0 - e0 * r2) * n1 + (e0 * r1 - e1 * r0) * n2 < 0.0:
            return best
    return min(best, abs(height))


# ----------------------------------------------------------------------------------------------------------
# occlusion maps


@njit_leaf
def _source_distance(q, nb, centre):
    """Distance from a point to the source segment q[0]..q[nb]."""
    return _segment_distance(q[0, 0] - centre[0], q[0, 1] - centre[1], q[0, 2] - centre[2], q[nb, 0] - centre[0],
                             q[nb, 1] - centre[1], q[nb, 2] - centre[2])  # fmt: skip


@njit_leaf
def _sphere_off_face(centre, radius, origin, a, eps):
    """Whether no point of the ball (centre, radius) is seen from `origin` through the faces of axis a, either
    way, grown by eps as in _polygon_box: every point x of the ball (relative to origin) has |x_b| or |x_c| above
    (1 + eps) |x_a|."""
    along = abs(centre[a] - origin[a]) + radius
    b = (a + 1) % 3
    c = (a + 2) % 3
    return (abs(centre[b] - origin[b]) - radius > (1.0 + eps) * along
            or abs(centre[c] - origin[c]) - radius > (1.0 + eps) * along)  # fmt: skip


@njit_leaf
def _polygon_box(points, first, count, q, nb, a, eps, buf_a, buf_b):
    """(u0, u1, w0, w1): the box of the lines from the points q[0..nb] through polygon points[first:first+count]
    on the positive face of axis a (u0 > u1 when none crosses that face)."""
    u0 = np.inf
    u1 = -np.inf
    w0 = np.inf
    w1 = -np.inf
    for k in range(nb + 1):
        for sign in (1.0, -1.0):
            _to_chart(points[first : first + count], count, a, sign, q[k], buf_a)
            m = _clip_to_face(buf_a, count, eps, buf_b)
            if m == 0:
                continue
            a0, a1, b0, b1 = _projected_box(buf_a, m)
            u0 = min(u0, a0)
            u1 = max(u1, a1)
            w0 = min(w0, b0)
            w1 = max(w1, b1)
    return u0, u1, w0, w1


@njit_leaf
def _grid_range(u0, u1, w0, w1, n):
    """Grid corner index ranges (k0, k1, l0, l1) spanning a chart box."""
    k0 = max(0, int(np.floor((u0 + 1.0) * 0.5 * n)))
    k1 = min(n, int(np.ceil((u1 + 1.0) * 0.5 * n)))
    l0 = max(0, int(np.floor((w0 + 1.0) * 0.5 * n)))
    l1 = min(n, int(np.ceil((w1 + 1.0) * 0.5 * n)))
    return k0, k1, l0, l1


@njit_leaf
def _any_wanted(wanted, a, k0, k1, l0, l1, n):
    """Whether some bin wants a cell of chart a in the index ranges [k0, k1) x [l0, l1)."""
    for b in range(wanted.shape[0]):
        for i in range(k0, k1):
            for j in range(l0, l1):
                if wanted[b, (a * n + i) * n + j]:
                    return True
    return False


@njit(cache=True)
def _depth_map(
    q, nb, points, offsets, normals, plane_offsets, edge_out, centres, radii, widths, cell_sine, object_offsets,
    object_polygons, object_centres, object_radii, grid, n, margin, delta, eps, wanted, depth, lazy, src, tol,
):  # fmt: skip
    """Depth bounds of the source segment q[0]..q[nb] cut in nb bins (a point when nb == 1 and q[0] == q[1]).

    q (nb+1, 3) bin ends; depth (nb, 2, 3 n n) filled with inf by the caller, lowered here: depth[b, side, cell]
    bounds where every line leaving bin b through the cell (side 0: along the canonical direction, 1: against it)
    first crosses a polygon interior. A polygon counts when the 8 corner lines (bin ends x cell corners) all cross
    its plane on one side of the source, beyond the margin, inside it by the margin: the crossings of all the lines
    then lie in the convex hull of those 8 points, their distances below the largest of the 8. A closed convex
    object (object_offsets, object_polygons: CSR of its faces) counts when a face plane separates it from the source
    and the 8 corner lines pass through it shrunk by the margin: then every line of the cell does (the set of lines
    from a point through a convex body is a convex cone, and along the bin the lines of one direction meeting it
    form an interval), so it crosses the object's surface, nearer than its farthest vertex facing the source. A
    polygon narrower than the patch the lines of any cell cut in its plane (widths (P,) from _polygon_widths), or
    whose bounding sphere (centres, radii) is seen under less than the half angle of every cell (its sine cell_sine,
    from _cell_half_sine), is skipped, and so is such an object (object_centres (O, 3), object_radii (O,)). Only
    cells some bin wants (wanted (nb, 3 n n) bool: a lazy build's source mask) are worked for: the others keep their
    bound (a larger bound only lets more candidates through). In a lazy build (sources `src`) a polygon or object
    that no line through the source segment and a source meets is skipped: covering a whole cell, it would be met by
    every line of the cell, so the cell holds no line through a source and none of its candidates is kept anyway.
    """
    n_poly = normals.shape[0]
    cell_tan = cell_sine / np.sqrt(1.0 - cell_sine * cell_sine)
    tvals = np.empty((nb + 1, n + 1, n + 1))
    buf_a = np.empty((_CLIP, 3))
    buf_b = np.empty((_CLIP, 3))
    hs = np.empty(nb + 1)
    ticks = np.empty(n + 1)
    for k in range(n + 1):
        ticks[k] = -1.0 + 2.0 * k / n
    # every bin end lies within `half` of the segment's middle
    middle = np.empty(3)
    for c in range(3):
        middle[c] = 0.5 * (q[0, c] + q[nb, c])
    half = 0.5 * _norm(q[nb] - q[0])
    for p in range(n_poly):
        normal = normals[p]
        ok = True
        nearest = np.inf
        for k in range(nb + 1):
            hs[k] = _dot(normal, q[k]) + plane_offsets[p]
            nearest = min(nearest, abs(hs[k]))
            if abs(hs[k]) <= margin or (k > 0 and (hs[k] > 0.0) != (hs[0] > 0.0)):
                ok = False
                break
        if not ok:
            continue
        # the corner lines of a cell from one bin end cut the plane in a patch at least 2 |h| cell_tan wide
        # (a wedge opening by twice the cell's half angle, met at distance |h|): a polygon narrower than that,
        # once shrunk by the margin, holds the patch of no cell from any bin end
        if widths[p] - 2.0 * margin < 2.0 * nearest * cell_tan:
            continue
        # nor does one whose bounding sphere is seen from every bin end under less than the cell's half angle
        if radii[p] < _source_distance(q, nb, centres[p]) * cell_sine:
            continue
        if lazy and not _segment_reaches_sources(q, nb, centres[p], radii[p], src, centres, radii, normals,
                                                 plane_offsets, tol):  # fmt: skip
            continue
        first = offsets[p]
        count = offsets[p + 1] - first
        for a in range(3):
            if _sphere_off_face(centres[p], radii[p] + half, middle, a, eps):
                continue
            u0, u1, w0, w1 = _polygon_box(points, first, count, q, nb, a, eps, buf_a, buf_b)
            if not u0 <= u1:
                continue
            k0, k1, l0, l1 = _grid_range(u0, u1, w0, w1, n)
            if k1 - k0 < 1 or l1 - l0 < 1 or not _any_wanted(wanted, a, k0, k1, l0, l1, n):
                continue
            for e in range(nb + 1):
                for k in range(k0, k1 + 1):
                    for l in range(l0, l1 + 1):
                        # by element: row views would cost two reference counts each, in the innermost loop
                        g0, g1, g2 = grid[a, k, l, 0], grid[a, k, l, 1], grid[a, k, l, 2]
                        nd = normal[0] * g0 + normal[1] * g1 + normal[2] * g2
                        tvals[e, k, l] = np.nan
                        if abs(nd) <= delta:
                            continue
                        t = -hs[e] / nd
                        inside = True
                        for c in range(count):
                            r = first + c
                            x0 = q[e, 0] + t * g0 - points[r, 0]
                            x1 = q[e, 1] + t * g1 - points[r, 1]
                            x2 = q[e, 2] + t * g2 - points[r, 2]
                            if x0 * edge_out[r, 0] + x1 * edge_out[r, 1] + x2 * edge_out[r, 2] > -margin:
                                inside = False
                                break
                        if inside:
                            tvals[e, k, l] = t
            for i in range(k0, k1):
                for j in range(l0, l1):
                    cell = (a * n + i) * n + j
                    for b in range(nb):
                        lowest = np.inf
                        highest = -np.inf
                        for e in range(b, b + 2):
                            for di in range(2):
                                for dj in range(2):
                                    t = tvals[e, i + di, j + dj]
                                    if t < lowest:
                                        lowest = t
                                    if t > highest:
                                        highest = t
                                    if np.isnan(t):
                                        lowest = np.nan
                        if np.isnan(lowest) or np.isnan(highest):
                            continue
                        if lowest > margin:
                            if highest < depth[b, 0, cell]:
                                depth[b, 0, cell] = highest
                        elif highest < -margin:
                            if -lowest < depth[b, 1, cell]:
                                depth[b, 1, cell] = -lowest

    # fused occluders: closed convex objects
    for o in range(object_offsets.shape[0] - 1):
        # too small to hold a whole cell, as for polygons: skip (cheaper, and only leaves bounds larger)
        if object_radii[o] < _source_distance(q, nb, object_centres[o]) * cell_sine:
            continue
        if lazy and not _segment_reaches_sources(q, nb, object_centres[o], object_radii[o], src, centres, radii,
                                                 normals, plane_offsets, tol):  # fmt: skip
            continue
        p0 = object_offsets[o]
        p1 = object_offsets[o + 1]
        separated = False
        for r in range(p0, p1):
            p = object_polygons[r]
            apart = True
            for k in range(nb + 1):
                if _dot(normals[p], q[k]) + plane_offsets[p] <= margin:
                    apart = False
                    break
            if apart:
                separated = True
                break
        if not separated:
            continue
        # the farthest vertex of a face that some bin end sees from the front bounds the entry point
        reach = 0.0
        for r in range(p0, p1):
            p = object_polygons[r]
            front = False
            for k in range(nb + 1):
                if _dot(normals[p], q[k]) + plane_offsets[p] > 0.0:
                    front = True
            if not front:
                continue
            for c in range(offsets[p], offsets[p + 1]):
                for k in range(nb + 1):
                    dx = points[c, 0] - q[k, 0]
                    dy = points[c, 1] - q[k, 1]
                    dz = points[c, 2] - q[k, 2]
                    reach = max(reach, np.sqrt(dx * dx + dy * dy + dz * dz))
        for a in range(3):
            if _sphere_off_face(object_centres[o], object_radii[o] + half, middle, a, eps):
                continue
            u0 = np.inf
            u1 = -np.inf
            w0 = np.inf
            w1 = -np.inf
            for r in range(p0, p1):
                p = object_polygons[r]
                b0, b1, c0, c1 = _polygon_box(points, offsets[p], offsets[p + 1] - offsets[p], q, nb, a, eps, buf_a,
                                              buf_b)  # fmt: skip
                u0 = min(u0, b0)
                u1 = max(u1, b1)
                w0 = min(w0, c0)
                w1 = max(w1, c1)
            if not u0 <= u1:
                continue
            k0, k1, l0, l1 = _grid_range(u0, u1, w0, w1, n)
            if k1 - k0 < 1 or l1 - l0 < 1 or not _any_wanted(wanted, a, k0, k1, l0, l1, n):
                continue
            # which side of the source each corner line passes through the shrunk object (nan: misses it)
            for e in range(nb + 1):
                for k in range(k0, k1 + 1):
                    for l in range(l0, l1 + 1):
                        g0, g1, g2 = grid[a, k, l, 0], grid[a, k, l, 1], grid[a, k, l, 2]
                        lo = -np.inf
                        hi = np.inf
                        for r in range(p0, p1):
                            p = object_polygons[r]
                            nd = normals[p, 0] * g0 + normals[p, 1] * g1 + normals[p, 2] * g2
                            h = normals[p, 0] * q[e, 0] + normals[p, 1] * q[e, 1] + normals[p, 2] * q[e, 2]
                            h = h + plane_offsets[p] + margin
                            if nd > 0.0:
                                hi = min(hi, -h / nd)
                            elif nd < 0.0:
                                lo = max(lo, -h / nd)
                            elif h > 0.0:
                                hi = -np.inf
                        if lo < hi:
                            tvals[e, k, l] = 1.0 if lo > 0.0 else -1.0
                        else:
                            tvals[e, k, l] = np.nan
            for i in range(k0, k1):
                for j in range(l0, l1):
                    cell = (a * n + i) * n + j
                    for b in range(nb):
                        total = 0.0
                        for e in range(b, b + 2):
                            for di in range(2):
                                for dj in range(2):
                                    total += tvals[e, i + di, j + dj]
                        if total == 8.0:
                            if reach < depth[b, 0, cell]:
                                depth[b, 0, cell] = reach
                        elif total == -8.0:
                            if reach < depth[b, 1, cell]:
                                depth[b, 1, cell] = reach


@njit(cache=True, nogil=True)
def _vertex_maps(
    ids, vertices, points, offsets, normals, plane_offsets, edge_out, centres, radii, widths, cell_sine, object_offsets,
    object_polygons, object_centres, object_radii, grid, n, margin, delta, eps, lazy, src, tol, out,
):  # fmt: skip
    """Depth maps (2, 3 n n) of the vertices `ids` into out[v]; in a lazy build only in the cells whose lines
    may cross a source (the others keep the caller's inf, which prunes nothing)."""
    q = np.empty((2, 3))
    depth = np.empty((1, 2, 3 * n * n))
    wanted = np.ones((1, 3 * n * n), dtype=np.bool_)
    for v in ids:
        q[0] = vertices[v]
        q[1] = vertices[v]
        if lazy:
            _source_mask(q, 1, src, points, offsets, normals, plane_offsets, edge_out, grid, n, tol, delta, wanted)
        depth[:] = np.inf
        _depth_map(
            q, 1, points, offsets, normals, plane_offsets, edge_out, centres, radii, widths, cell_sine, object_offsets,
            object_polygons, object_centres, object_radii, grid, n, margin, delta, eps, wanted, depth, lazy,
            src, tol,
        )  # fmt: skip
        out[v] = depth[0]


@njit(cache=True)
def _source_mask(q, nb, src, points, offsets, normals, plane_offsets, edge_out, grid, n, tol, delta, mask):
    """mask (nb, 3 n n) bool: False only where no line leaving bin b through the cell can cross (within tol)
    one of the polygons `src`; a line in (or parallel to) a source's plane counts as crossing."""
    mask[:] = False
    for p in src:
        normal = normals[p]
        first = offsets[p]
        count = offsets[p + 1] - first
        for a in range(3):
            outside = np.zeros((nb + 1, n + 1, n + 1), dtype=np.int64)
            parallel = np.zeros((n + 1, n + 1), dtype=np.int8)
            for k in range(n + 1):
                for l in range(n + 1):
                    g = grid[a, k, l]
                    nd = _dot(normal, g)
                    if abs(nd) <= delta:
                        parallel[k, l] = 2
                        continue
                    parallel[k, l] = 1 if nd > 0.0 else 0
                    for e in range(nb + 1):
                        t = -(_dot(normal, q[e]) + plane_offsets[p]) / nd
                        bits = 0
                        for c in range(min(count, 62)):
                            corner = points[first + c]
                            out = edge_out[first + c]
                            x = q[e] + t * g - corner
                            if _dot(x, out) > tol:
                                bits |= 1 << c
                        outside[e, k, l] = bits
            for i in range(n):
                for j in range(n):
                    cell = (a * n + i) * n + j
                    s = parallel[i, j]
                    mixed = s == 2 or count > 62
                    for di in range(2):
                        for dj in range(2):
                            if parallel[i + di, j + dj] != s:
                                mixed = True
                    for b in range(nb):
                        if mask[b, cell]:
                            continue
                        if mixed:
                            mask[b, cell] = True
                            continue
                        common = -1
                        for e in range(b, b + 2):
                            for di in range(2):
                                for dj in range(2):
                                    common &= outside[e, i + di, j + dj]
                        if common == 0:
                            mask[b, cell] = True


@njit(cache=True)
def _line_meets(origin, d, src, points, offsets, normals, plane_offsets, edge_out, tol, cosine):
    """Whether the line origin + t d (d unit) crosses one of the polygons `src` (within tol), or lies in the
    plane of one (within tol) -- the skeleton's test for lines through built sources."""
    for p in src:
        normal = normals[p]
        nd = _dot(normal, d)
        dist = _dot(normal, origin) + plane_offsets[p]
        if abs(nd) <= cosine:
            if abs(dist) <= tol:
                return True
            continue
        x = origin - (dist / nd) * d
        inside = True
        for c in range(offsets[p], offsets[p + 1]):
            if _dot(x - points[c], edge_out[c]) > tol:
                inside = False
                break
        if inside:
            return True
    return False


@njit_leaf
def _reaches_sources(q, b, centre, radius, src, centres, radii, normals, plane_offsets, tol):
    """Whether a line through bin b of q (nb+1, 3) and a source polygon (within tol) may pass within `radius`
    of `centre`: False only when none can. Shifting such a line to pass through the bin's middle m moves it by
    at most the bin's half length h, so it then meets the source's bounding sphere grown by h and the sphere
    (centre, radius + h): the directions from m into both spheres (double cones, a line running both ways)
    must overlap. A bin within reach of a source's plane may hold lines lying in it, which count as crossing."""
    m0 = 0.5 * (q[b, 0] + q[b + 1, 0])
    m1 = 0.5 * (q[b, 1] + q[b + 1, 1])
    m2 = 0.5 * (q[b, 2] + q[b + 1, 2])
    h0 = q[b + 1, 0] - m0
    h1 = q[b + 1, 1] - m1
    h2 = q[b + 1, 2] - m2
    h = np.sqrt(h0 * h0 + h1 * h1 + h2 * h2) + tol
    w0 = centre[0] - m0
    w1 = centre[1] - m1
    w2 = centre[2] - m2
    dw = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
    reach = radius + h
    if dw <= reach:
        return True
    target_angle = np.arcsin(reach / dw)
    for p in src:
        normal = normals[p]
        if abs(normal[0] * m0 + normal[1] * m1 + normal[2] * m2 + plane_offsets[p]) <= h + tol:
            return True
        a0 = centres[p, 0] - m0
        a1 = centres[p, 1] - m1
        a2 = centres[p, 2] - m2
        da = np.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
        spread = radii[p] + h + tol
        if da <= spread:
            return True
        apart = np.arccos(min(1.0, abs(a0 * w0 + a1 * w1 + a2 * w2) / (da * dw)))
        if apart <= np.arcsin(spread / da) + target_angle + 1e-9:
            return True
    return False


@njit_leaf
def _plane_near_sources(f, src, normals, plane_offsets, centres, radii, tol):
    """Whether a line lying in polygon f's plane and crossing f may count as crossing a source (_line_meets):
    it meets a source only where the source's bounding sphere reaches f's plane, and it lies in a source's
    plane only where f comes within tol of that plane (the line passes through f, and a line in the plane
    within tol.cosine of parallel strays from it by far less than tol across the scene; 4 tol is ample)."""
    for p in src:
        if abs(_dot(normals[f], centres[p]) + plane_offsets[f]) <= radii[p] + 4.0 * tol:
            return True
        if abs(_dot(normals[p], centres[f]) + plane_offsets[p]) <= radii[f] + 4.0 * tol:
            return True
    return False


@njit_leaf
def _segment_reaches_sources(q, nb, centre, radius, src, centres, radii, normals, plane_offsets, tol):
    """_reaches_sources for some bin of q (nb+1, 3)."""
    for b in range(nb):
        if _reaches_sources(q, b, centre, radius, src, centres, radii, normals, plane_offsets, tol):
            return True
    return False


# ----------------------------------------------------------------------------------------------------------
# registration of target edges in the cells of a source


@njit(cache=True)
def _register(
    q, nb, depth, lazy, mask, ends, target_ids, n, margin, eps, keys, targets, sides, bits, count,
    src, centres, radii, normals, plane_offsets, tol,
):  # fmt: skip
    """Append (key, target, side, bits) for every cell of every bin through which target edge ends[t] (2, 3)
    may be reached from the bin within the cell's depth bound. key = b * 3 n n + cell; side 0 along the
    canonical direction; bits (uint64) the sub-cells of an 8 x 8 split of the cell that the directions from
    the bin to the target reach (_sub_cells). Grows the arrays when full; returns (keys, targets, sides, bits,
    count). Only the cells of `mask` (nb, 3 n n) bool are worked for; in a lazy build, targets that no line
    through the bin and a source polygon `src` (within tol) meets within the margin are skipped at once."""
    clip = np.empty((6, _CLIP, 3))
    quad = np.empty((4, 3))
    origin = np.zeros(3)
    middle = np.empty(3)
    row_bounds = np.empty((2, 8))
    b = 0
    t = 0
    while True:
        count, b, t = _register_from(
            b, t, q, nb, depth, lazy, mask, ends, target_ids, n, margin, eps, keys, targets, sides, bits, count, src,
            centres, radii, normals, plane_offsets, tol, clip, quad, origin, middle, row_bounds,
        )  # fmt: skip
        if b == nb:
            return keys, targets, sides, bits, count
        keys = _grow(keys)
        targets = _grow(targets)
        sides = _grow8(sides)
        bits = _grow(bits)


@njit_leaf
def _register_from(
    b_first, t_first, q, nb, depth, lazy, mask, ends, target_ids, n, margin, eps, keys, targets, sides, bits, count,
    src, centres, radii, normals, plane_offsets, tol, clip, quad, origin, middle, row_bounds,
):  # fmt: skip
    """The work of _register from bin b_first and its target t_first on, compiled without numba's runtime (the
    calls of its clipping loop passed arrays, each costing two reference counts). Returns (count, nb, 0) when
    done, or (count, b, t) when the arrays are full while target t of bin b is registered: its rows are then
    dropped (count is where they began), to be registered again once the caller has grown the arrays.
    clip (6, _CLIP, 3), quad (4, 3), origin (3,) zeros, middle (3,), row_bounds (2, 8): scratch."""
    buf_a = clip[0]
    buf_b = clip[1]
    cell_a = clip[2]
    cell_b = clip[3]
    row_a = clip[4]
    row_b = clip[5]
    row_lo = row_bounds[0]
    row_hi = row_bounds[1]
    n_cells = 3 * n * n
    point_source = nb == 1 and q[0, 0] == q[1, 0] and q[0, 1] == q[1, 1] and q[0, 2] == q[1, 2]
    for b in range(b_first, nb):
        # the farthest any line of the bin may go: skip targets beyond every bound (of the cells worked for)
        reach = 0.0
        for side in range(2):
            for cell in range(n_cells):
                if depth[b, side, cell] > reach and mask[b, cell]:
                    reach = depth[b, side, cell]
        for t in range(t_first if b == b_first else 0, target_ids.shape[0]):
            target_first_row = count
            if lazy:
                for c in range(3):
                    middle[c] = 0.5 * (ends[t, 0, c] + ends[t, 1, c])
                half = 0.5 * np.sqrt((ends[t, 1, 0] - ends[t, 0, 0]) ** 2 + (ends[t, 1, 1] - ends[t, 0, 1]) ** 2
                                     + (ends[t, 1, 2] - ends[t, 0, 2]) ** 2)  # fmt: skip
                if not _reaches_sources(q, b, middle, half + margin, src, centres, radii, normals, plane_offsets, tol):
                    continue
            corners = 2 if point_source else 4
            for c in range(3):
                quad[0, c] = ends[t, 0, c] - q[b, c]
                quad[1, c] = ends[t, 1, c] - q[b, c]
                quad[2, c] = ends[t, 1, c] - q[b + 1, c]
                quad[3, c] = ends[t, 0, c] - q[b + 1, c]
            closest = _polygon_distance(quad, corners)
            if closest > reach + margin:
                continue
            # lines meeting the target within the snap margin (validation accepts them) turn by up to that
            # margin over the distance: the sub-cells are grown by it
            sub_eps = eps + 8.0 * margin / closest if closest > 0.0 else np.inf
            # the target seen from the bin's middle, within a ball holding every direction from the bin to it
            for c in range(3):
                middle[c] = 0.5 * (ends[t, 0, c] + ends[t, 1, c]) - 0.5 * (q[b, c] + q[b + 1, c])
            target_length = 0.0
            bin_length = 0.0
            for c in range(3):
                target_length += (ends[t, 1, c] - ends[t, 0, c]) ** 2
                bin_length += (q[b + 1, c] - q[b, c]) ** 2
            spread = 0.5 * (np.sqrt(target_length) + np.sqrt(bin_length))
            for a in range(3):
                if _sphere_off_face(middle, spread, origin, a, eps):
                    continue
                for side in range(2):
                    sign = 1.0 if side == 0 else -1.0
                    # wholly behind the source along this axis: the first clip would leave nothing
                    ahead = False
                    for k in range(corners):
                        if sign * quad[k, a] >= 0.0:
                            ahead = True
                    if not ahead:
                        continue
                    _to_chart(quad, corners, a, sign, origin, buf_a)
                    m = _clip_to_face(buf_a, corners, eps, buf_b)
                    if m == 0:
                        continue
                    u0, u1, w0, w1 = _projected_box(buf_a, m)
                    i0 = max(0, int(np.floor((u0 - eps + 1.0) * 0.5 * n)))
                    i1 = min(n - 1, int(np.floor((u1 + eps + 1.0) * 0.5 * n)))
                    j0 = max(0, int(np.floor((w0 - eps + 1.0) * 0.5 * n)))
                    j1 = min(n - 1, int(np.floor((w1 + eps + 1.0) * 0.5 * n)))
                    for i in range(i0, i1 + 1):
                        lo_u = -1.0 + 2.0 * i / n - eps
                        hi_u = -1.0 + 2.0 * (i + 1) / n + eps
                        # the row's strip once, then each cell's columns (the clipping order of _clip_pyramid)
                        m_row = _clip(buf_a, m, -lo_u, 1.0, 0.0, row_b)
                        m_row = _clip(row_b, m_row, hi_u, -1.0, 0.0, row_a)
                        if m_row == 0:
                            continue
                        for j in range(j0, j1 + 1):
                            cell = (a * n + i) * n + j
                            if not mask[b, cell]:
                                continue
                            bound = depth[b, side, cell]
                            lo_w = -1.0 + 2.0 * j / n - eps
                            hi_w = -1.0 + 2.0 * (j + 1) / n + eps
                            k = _clip(row_a, m_row, -lo_w, 0.0, 1.0, cell_b)
                            k = _clip(cell_b, k, hi_w, 0.0, -1.0, cell_a)
                            if k == 0:
                                continue
                            if bound < np.inf and _polygon_distance(cell_a, k) > bound + margin:
                                continue
                            if count == keys.shape[0]:
                                return target_first_row, b, t
                            keys[count] = b * n_cells + cell
                            targets[count] = target_ids[t]
                            sides[count] = side
                            bits[count] = _sub_cells(cell_a, k, lo_u, hi_u, lo_w, hi_w, sub_eps, row_lo, row_hi)
                            count += 1
    return count, nb, 0


@njit_leaf
def _sub_cells(poly, count, lo_u, hi_u, lo_w, hi_w, eps, row_lo, row_hi):
    """uint64: the sub-cells of the cell [lo_u, hi_u] x [lo_w, hi_w], cut 8 x 8 (bit 8 j + i: column i, row
    j), that the central projection of the convex polygon poly[:count] (chart coordinates, x0 >= 0) touches,
    grown by eps. A line through several generators has its direction in every one's projection, so only
    generators sharing a sub-cell can meet on one line: a finer grid for the price of an AND. row_lo, row_hi:
    (8,) float64 scratch."""
    every = np.uint64(0xFFFFFFFFFFFFFFFF)
    if eps == np.inf:
        return every
    du = (hi_u - lo_u) / 8.0
    dw = (hi_w - lo_w) / 8.0
    row_lo[:] = np.inf
    row_hi[:] = -np.inf
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        if not (poly[k, 0] > 0.0 and poly[k2, 0] > 0.0):
            return every
        u0 = poly[k, 1] / poly[k, 0]
        w0 = poly[k, 2] / poly[k, 0]
        u1 = poly[k2, 1] / poly[k2, 0]
        w1 = poly[k2, 2] / poly[k2, 0]
        # every row the side crosses gets the side's u range over the row's band (the side is straight)
        j0 = int(np.floor((min(w0, w1) - eps - lo_w) / dw))
        j1 = int(np.floor((max(w0, w1) + eps - lo_w) / dw))
        for j in range(max(j0, 0), min(j1, 7) + 1):
            band_lo = lo_w + j * dw - eps
            band_hi = band_lo + dw + 2.0 * eps
            ua = u0
            ub = u1
            if w1 != w0:
                ta = min(max((band_lo - w0) / (w1 - w0), 0.0), 1.0)
                tb = min(max((band_hi - w0) / (w1 - w0), 0.0), 1.0)
                ua = u0 + ta * (u1 - u0)
                ub = u0 + tb * (u1 - u0)
            row_lo[j] = min(row_lo[j], min(ua, ub))
            row_hi[j] = max(row_hi[j], max(ua, ub))
    result = np.uint64(0)
    for j in range(8):
        if row_lo[j] > row_hi[j]:
            continue
        i0 = max(int(np.floor((row_lo[j] - eps - lo_u) / du)), 0)
        i1 = min(int(np.floor((row_hi[j] + eps - lo_u) / du)), 7)
        for i in range(i0, i1 + 1):
            result |= np.uint64(1) << np.uint64(8 * j + i)
    return result


@njit(cache=True)
def _grow(a):
    out = np.empty(2 * a.shape[0] + 16, dtype=a.dtype)
    out[: a.shape[0]] = a
    return out


@njit(cache=True)
def _grow8(a):
    out = np.empty(2 * a.shape[0] + 16, dtype=np.int8)
    out[: a.shape[0]] = a
    return out


@njit(cache=True)
def _group(keys, count, n_keys):
    """Counting sort of keys[:count]: (order, offsets (n_keys + 1,))."""
    offsets = np.zeros(n_keys + 1, dtype=np.int64)
    for r in range(count):
        offsets[keys[r] + 1] += 1
    for k in range(n_keys):
        offsets[k + 1] += offsets[k]
    fill = offsets[:-1].copy()
    order = np.empty(count, dtype=np.int64)
    for r in range(count):
        order[fill[keys[r]]] = r
        fill[keys[r]] += 1
    return order, offsets


# ----------------------------------------------------------------------------------------------------------
# local visibility: is an inner generator pierced by the line?


@njit_leaf
def _edge_pierced(e, d, vertices, edges, ef_off, ef_inward, delta):
    """Whether the faces along edge e clearly close around a line of direction d (unit) through it: two of
    them on opposite sides of the plane (e, d), each away from it by more than the angle delta. Undecided
    (a face nearly in that plane, the line nearly along e) counts as not pierced."""
    a = edges[e, 0]
    b = edges[e, 1]
    along = (vertices[b, 0] - vertices[a, 0], vertices[b, 1] - vertices[a, 1], vertices[b, 2] - vertices[a, 2])
    m = (along[1] * d[2] - along[2] * d[1], along[2] * d[0] - along[0] * d[2], along[0] * d[1] - along[1] * d[0])
    length = _norm(m)
    if length <= delta * _norm(along):
        return False
    positive = False
    negative = False
    for k in range(ef_off[e], ef_off[e + 1]):
        s = _dot(ef_inward[k], m) / length
        if abs(s) <= delta:
            return False
        if s > 0.0:
            positive = True
        else:
            negative = True
    return positive and negative


@njit_leaf
def _target_pierces(e, f, vertices, edges, ef_off, ef_inward, delta, tol):
    """Whether every line through edge e that meets edge f (within 2 tol of it) pierces e as _edge_pierced
    decides: then f generates no line kept from e, where e is an inner edge. Clear of _edge_pierced's undecided
    bands by a factor of two and the 2 tol.

    Through a point of e and a point Y, face k's side is the sign of (Y - a) . (inward_k x along) (a: e's first
    end), linear in Y, so its least and largest values over f are at f's ends; _edge_pierced compares it with
    delta |along| dist(Y, e's line), and dist is largest at f's ends too. The line is nowhere near e's direction
    when f keeps away from e's line (its nearest point: an end, or the foot of the lines' common perpendicular)
    by more than delta times the largest distance between the two edges' ends."""
    first = ef_off[e]
    if ef_off[e + 1] - first < 2:
        return False
    a = edges[e, 0]
    b = edges[e, 1]
    l0 = vertices[b, 0] - vertices[a, 0]
    l1 = vertices[b, 1] - vertices[a, 1]
    l2 = vertices[b, 2] - vertices[a, 2]
    length = np.sqrt(l0 * l0 + l1 * l1 + l2 * l2)
    # scalars throughout: this runs for every pair of edges
    p0 = vertices[edges[f, 0], 0] - vertices[a, 0]
    p1 = vertices[edges[f, 0], 1] - vertices[a, 1]
    p2 = vertices[edges[f, 0], 2] - vertices[a, 2]
    q0 = vertices[edges[f, 1], 0] - vertices[a, 0]
    q1 = vertices[edges[f, 1], 1] - vertices[a, 1]
    q2 = vertices[edges[f, 1], 2] - vertices[a, 2]
    far = max(
        np.sqrt(p0 * p0 + p1 * p1 + p2 * p2),
        np.sqrt(q0 * q0 + q1 * q1 + q2 * q2),
        np.sqrt((p0 - l0) ** 2 + (p1 - l1) ** 2 + (p2 - l2) ** 2),
        np.sqrt((q0 - l0) ** 2 + (q1 - l1) ** 2 + (q2 - l2) ** 2),
    )
    # along x (end - a): its length over |along| is the end's distance from e's line
    cp0 = l1 * p2 - l2 * p1
    cp1 = l2 * p0 - l0 * p2
    cp2 = l0 * p1 - l1 * p0
    cq0 = l1 * q2 - l2 * q1
    cq1 = l2 * q0 - l0 * q2
    cq2 = l0 * q1 - l1 * q0
    dist_p = np.sqrt(cp0 * cp0 + cp1 * cp1 + cp2 * cp2) / length
    dist_q = np.sqrt(cq0 * cq0 + cq1 * cq1 + cq2 * cq2) / length
    reach = max(dist_p, dist_q)
    near = min(dist_p, dist_q)
    # along x (f's direction): the distance from e's line along f is |cp + w x| / |along|, least at w_min
    x0 = cq0 - cp0
    x1 = cq1 - cp1
    x2 = cq2 - cp2
    squared = x0 * x0 + x1 * x1 + x2 * x2
    if squared > 0.0:
        w_min = -(cp0 * x0 + cp1 * x1 + cp2 * x2) / squared
        if 0.0 < w_min < 1.0:
            near = min(near, np.sqrt((cp0 + w_min * x0) ** 2 + (cp1 + w_min * x1) ** 2
                                     + (cp2 + w_min * x2) ** 2) / length)  # fmt: skip
    if near - 2.0 * tol <= 2.0 * delta * (far + 2.0 * tol):
        return False
    bound = 2.0 * length * (delta * (reach + 2.0 * tol) + tol)
    positive = False
    negative = False
    for k in range(first, ef_off[e + 1]):
        n0 = ef_inward[k, 1] * l2 - ef_inward[k, 2] * l1
        n1 = ef_inward[k, 2] * l0 - ef_inward[k, 0] * l2
        n2 = ef_inward[k, 0] * l1 - ef_inward[k, 1] * l0
        side_p = p0 * n0 + p1 * n1 + p2 * n2
        side_q = q0 * n0 + q1 * n1 + q2 * n2
        if min(side_p, side_q) > bound:
            positive = True
        elif max(side_p, side_q) < -bound:
            negative = True
        else:
            return False
    return positive and negative


@njit(cache=True)
def _mask_pierced_cells(e, vertices, edges, ef_off, ef_inward, grid, n, delta, mask):
    """Clear mask[:, cell] (mask (nb, 3 n n) bool) for the cells whose every direction pierces edge e as
    _edge_pierced decides, beyond its undecided band: no line of such a cell has e as an inner generator.
    The side of face k is the sign of d . (inward_k x along), linear in d, and a unit d of the cell is a
    combination of the cell's four unit corner directions with weights summing to at least 1, so a margin
    holding at the four corners holds over the cell (and for -d, with both signs swapped)."""
    along = vertices[edges[e, 1]] - vertices[edges[e, 0]]
    bound = delta * _norm(along)
    n_faces = ef_off[e + 1] - ef_off[e]
    if n_faces < 2:
        return
    sides = np.empty((n_faces, 3))
    for k in range(n_faces):
        sides[k] = _cross(ef_inward[ef_off[e] + k], along)
    for a in range(3):
        for i in range(n):
            for j in range(n):
                positive = False
                negative = False
                for k in range(n_faces):
                    above = True
                    below = True
                    for di in range(2):
                        for dj in range(2):
                            value = _dot(grid[a, i + di, j + dj], sides[k])
                            above = above and value > bound
                            below = below and value < -bound
                    positive = positive or above
                    negative = negative or below
                if positive and negative:
                    mask[:, (a * n + i) * n + j] = False


@njit_leaf
def _vertex_pierced(v, d, points, offsets, normals, vf_off, vf_face, vf_corner, delta, angle_tol, starts, lengths,
                    bounds):  # fmt: skip
    """Whether the faces around vertex v close around a line of direction d (unit) through it, as validation
    decides for an inner vertex (core.raycast contact arcs), with half its angular gap tolerance; a face
    nearly containing d leaves it undecided (not pierced). starts, lengths (F,), bounds (2 F,) float64: scratch
    for the arcs of v's faces (F at least their count; this runs for every pair of edges seen from v)."""
    count = vf_off[v + 1] - vf_off[v]
    if count < 2:
        return False
    e1, e2 = _perpendicular_frame(d)
    for k in range(count):
        face = vf_face[vf_off[v] + k]
        if abs(_dot(normals[face], d)) <= delta:
            return False
        starts[k], lengths[k] = _contact_arc(points, offsets, normals, face, CONTACT_VERTEX, vf_corner[vf_off[v] + k],
                                             e1, e2)  # fmt: skip
    return _arcs_cover_circle_with(starts, lengths, count, 0.5 * angle_tol, bounds)


# ----------------------------------------------------------------------------------------------------------
# candidate output


@njit(cache=True)
def _new_output(capacity):
    return (
        np.empty(capacity, dtype=np.int8),
        np.empty((capacity, 2), dtype=np.int64),
        np.empty((capacity, 4), dtype=np.int64),
        np.empty((capacity, 3)),
        np.empty((capacity, 3)),
    )


@njit(cache=True)
def _grown_output(out, count):
    """(output with room for twice as many candidates, the first `count` copied; its capacity)."""
    capacity = 2 * count + 64
    bigger = _new_output(capacity)
    bigger[0][:count] = out[0][:count]
    bigger[1][:count] = out[1][:count]
    bigger[2][:count] = out[2][:count]
    bigger[3][:count] = out[3][:count]
    bigger[4][:count] = out[4][:count]
    return bigger, capacity


# Candidates are written by leaf kernels into room the caller makes (`_grown_output` when count reaches its
# capacity, kept as a number): a kernel taking and returning the output tuple counted a reference to each of its
# five arrays at entry and exit, and reading a capacity off it one more, for every candidate


@njit_leaf
def _write(out, count, kind, v0, v1, e0, e1, e2, e3, origin, d):
    """Write candidate `count` (edges already sorted, -1 last) into the output, which has room for it."""
    o_kind, o_vert, o_edge, o_origin, o_dir = out
    o_kind[count] = kind
    o_vert[count, 0] = v0
    o_vert[count, 1] = v1
    o_edge[count, 0] = e0
    o_edge[count, 1] = e1
    o_edge[count, 2] = e2
    o_edge[count, 3] = e3
    for c in range(3):
        o_origin[count, c] = origin[c]
        o_dir[count, c] = d[c]


@njit_leaf
def _write_edges(out, count, kind, e0, e1, e2, e3, origin, d):
    """_write of a candidate of four edge generators (E4, FEE), given in any order."""
    # a sorting network on the four ids: an array to sort would be allocated per candidate
    e0, e1 = min(e0, e1), max(e0, e1)
    e2, e3 = min(e2, e3), max(e2, e3)
    e0, e2 = min(e0, e2), max(e0, e2)
    e1, e3 = min(e1, e3), max(e1, e3)
    e1, e2 = min(e1, e2), max(e1, e2)
    _write(out, count, kind, -1, -1, e0, e1, e2, e3, origin, d)


@njit(cache=True)
def _trim(out, count):
    return out[0][:count].copy(), out[1][:count].copy(), out[2][:count].copy(), out[3][:count].copy(), \
        out[4][:count].copy()  # fmt: skip


# ----------------------------------------------------------------------------------------------------------
# VV and VEE / EVE: lines through a vertex


@njit_leaf
def _meet(o0, o1, o2, d0, d1, d2, a0, a1, a2, b0, b1, b2):
    """Where the line o + t d (d unit) passes closest to the line a + s (b - a): (ok, t, s, distance between
    the lines); ok is False when they are parallel."""
    g0 = b0 - a0
    g1 = b1 - a1
    g2 = b2 - a2
    n0 = d1 * g2 - d2 * g1
    n1 = d2 * g0 - d0 * g2
    n2 = d0 * g1 - d1 * g0
    nn = n0 * n0 + n1 * n1 + n2 * n2
    if nn == 0.0:
        return False, 0.0, 0.0, 0.0
    w0 = a0 - o0
    w1 = a1 - o1
    w2 = a2 - o2
    t = ((w1 * g2 - w2 * g1) * n0 + (w2 * g0 - w0 * g2) * n1 + (w0 * g1 - w1 * g0) * n2) / nn
    s = ((w1 * d2 - w2 * d1) * n0 + (w2 * d0 - w0 * d2) * n1 + (w0 * d1 - w1 * d0) * n2) / nn
    gap = abs(w0 * n0 + w1 * n1 + w2 * n2) / np.sqrt(nn)
    return True, t, s, gap


@njit_leaf
def _meets_segment(o, d, vertices, edges, normals, plane_offsets, ef_off, ef_face, f, tol, delta):
    """(ok, t): whether the line o + t d (d unit) meets edge f within tol, and where along the line.

    A line through an end of f (within tol / 2) meets a corner there for validation, which then finds no
    contact with the edge, when each face of f is either crossed that near the end or exactly parallel to the
    line (d . normal == 0, an axis-aligned line along an axis-aligned face) and within tol / 2 of its plane:
    validation sets such a face aside as one the line slides over. Such a line is refused here."""
    i = edges[f, 0]
    j = edges[f, 1]
    a0 = vertices[i, 0]
    a1 = vertices[i, 1]
    a2 = vertices[i, 2]
    b0 = vertices[j, 0]
    b1 = vertices[j, 1]
    b2 = vertices[j, 2]
    ok, t, s, gap = _meet(o[0], o[1], o[2], d[0], d[1], d[2], a0, a1, a2, b0, b1, b2)
    if not ok or gap > tol:
        return False, t
    length = np.sqrt((b0 - a0) ** 2 + (b1 - a1) ** 2 + (b2 - a2) ** 2)
    if s * length < -tol or (s - 1.0) * length > tol:
        return False, t
    near = min(abs(s * length), abs((1.0 - s) * length))
    if near <= 0.5 * tol:
        at_corner = True
        for k in range(ef_off[f], ef_off[f + 1]):
            face = ef_face[k]
            rate = abs(normals[face, 0] * d[0] + normals[face, 1] * d[1] + normals[face, 2] * d[2])
            if rate == 0.0:
                offset = normals[face, 0] * o[0] + normals[face, 1] * o[1] + normals[face, 2] * o[2]
                if abs(offset + plane_offsets[face]) > 0.5 * tol:
                    at_corner = False
            elif rate <= delta or near + gap / rate > 0.5 * tol:
                at_corner = False
        if at_corner:
            return False, t
    return True, t


@njit_leaf
def _enters_object(is_vertex, gid, u, others, n_others, vertex_object, edge_object, object_offsets, object_polygons,
                   vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
    """Local visibility at an outer generator (seed 003 section 3.2, made safe): whether the line leaves the
    generator (a vertex if is_vertex, else an edge; id gid) in direction u (unit) straight into the inside of
    the closed convex object it belongs to -- behind every face around it by more than the angle delta --
    while none of the other generators' contact points others[:n_others] lies on or in that object. The line
    then crosses the object's surface strictly between its generators, and validation rejects it."""
    obj = vertex_object[gid] if is_vertex else edge_object[gid]
    if obj < 0:
        return False
    lo = vf_off[gid] if is_vertex else ef_off[gid]
    hi = vf_off[gid + 1] if is_vertex else ef_off[gid + 1]
    for k in range(lo, hi):
        face = vf_face[k] if is_vertex else ef_face[k]
        if _dot(normals[face], u) >= -delta:
            return False
    for r in range(n_others):
        inside = True
        for k in range(object_offsets[obj], object_offsets[obj + 1]):
            p = object_polygons[k]
            if _dot(normals[p], others[r]) + plane_offsets[p] > margin:
                inside = False
                break
        if inside:
            return False
    return True


@njit(cache=True, nogil=True)
def _vertex_candidates(
    vertex_ids, lo, hi, vmask, emask, vertices, edges, points, offsets, normals, plane_offsets, edge_out,
    vf_off, vf_face, vf_corner, ve_off, ve_edge, ef_off, ef_face, ef_inward, vertex_object, edge_object,
    object_offsets, object_polygons, centres, radii, grid, n, vertex_depth, lazy, src, margin, delta, eps, tol,
    angle_tol, scale,
):  # fmt: skip
    """VV candidates (v, w > v) and VEE / EVE candidates of the vertices vertex_ids[lo:hi].

    A VEE line through v meets edges f and g in the planes (v, f) and (v, g): on their common line, which meets
    f inside it only where f crosses g's plane, and g where it crosses f's. A pair whose edge lies wholly on one
    side of the other's plane is not solved: beyond a height of 2 tol (a meeting within tol of the edge grown by
    tol, as _meets_segment accepts) and 1e-6 scale, which covers the rounding of the line's direction (the planes
    meet at an angle above delta: the rounded cross product leaves them by at most 1e-7 scale across the
    scene)."""
    capacity = 1024
    out = _new_output(capacity)
    count = 0
    n_cells = 3 * n * n
    n_vertices = vertices.shape[0]
    q = np.empty((2, 3))
    mask = np.ones((1, n_cells), dtype=np.bool_)
    depth = np.empty((1, 2, n_cells))
    edge_ids = np.flatnonzero(emask)
    n_edges = edge_ids.shape[0]
    ends = np.empty((n_edges, 2, 3))
    slots = np.empty(n_edges, dtype=np.int64)
    ids = np.empty(n_edges, dtype=np.int64)
    plane = np.empty((n_edges, 3))
    unit = np.empty((n_edges, 3))
    reach = 2.0 * tol + 1e-6 * scale
    keys = np.empty(4096, dtype=np.int64)
    tgts = np.empty(4096, dtype=np.int64)
    sides = np.empty(4096, dtype=np.int8)
    bits = np.empty(4096, dtype=np.uint64)
    incident = np.zeros(edges.shape[0], dtype=np.bool_)
    d = np.empty(3)
    back = np.empty(3)
    most_faces = 0
    for w in range(n_vertices):
        most_faces = max(most_faces, vf_off[w + 1] - vf_off[w])
    arc_starts = np.empty(most_faces)
    arc_lengths = np.empty(most_faces)
    arc_bounds = np.empty(2 * most_faces)
    others = np.empty((3, 3))
    for index in range(lo, hi):
        v = vertex_ids[index]
        p = vertices[v]
        q[0] = p
        q[1] = p
        if lazy:
            _source_mask(q, 1, src, points, offsets, normals, plane_offsets, edge_out, grid, n, tol, delta, mask)
        depth[0] = vertex_depth[v]

        # VV: the pair is kept by both vertices' maps
        for w in range(v + 1, n_vertices):
            if not vmask[w]:
                continue
            d0 = vertices[w, 0] - p[0]
            d1 = vertices[w, 1] - p[1]
            d2 = vertices[w, 2] - p[2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            if length <= tol:
                continue
            d[0] = d0 / length
            d[1] = d1 / length
            d[2] = d2 / length
            a, i, j, flipped = _line_cell(d, n)
            cell = (a * n + i) * n + j
            if lazy and not mask[0, cell]:
                continue
            side = 1 if flipped else 0
            if length > vertex_depth[v, side, cell] + margin or length > vertex_depth[w, 1 - side, cell] + margin:
                continue
            for c in range(3):
                others[0, c] = vertices[w, c]
            if _enters_object(True, v, d, others, 1, vertex_object, edge_object, object_offsets, object_polygons,
                              vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
                continue
            others[0] = p
            back[0] = -d[0]
            back[1] = -d[1]
            back[2] = -d[2]
            if _enters_object(True, w, back, others, 1, vertex_object, edge_object, object_offsets, object_polygons,
                              vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
                continue
            if lazy and not _line_meets(p, d, src, points, offsets, normals, plane_offsets, edge_out, tol, angle_tol):
                continue
            if count == capacity:
                out, capacity = _grown_output(out, count)
            _write(out, count, CANDIDATE_VV, v, w, -1, -1, -1, -1, p, d)
            count += 1

        # VEE / EVE: register the edges not incident to v, then pair them within each cell
        for k in range(ve_off[v], ve_off[v + 1]):
            incident[ve_edge[k]] = True
        m = 0
        for e in edge_ids:
            if incident[e]:
                continue
            for c in range(3):
                ends[m, 0, c] = vertices[edges[e, 0], c]
                ends[m, 1, c] = vertices[edges[e, 1], c]
            fa0 = ends[m, 0, 0] - p[0]
            fa1 = ends[m, 0, 1] - p[1]
            fa2 = ends[m, 0, 2] - p[2]
            fb0 = ends[m, 1, 0] - p[0]
            fb1 = ends[m, 1, 1] - p[1]
            fb2 = ends[m, 1, 2] - p[2]
            # normal of the plane (v, e): every line through v meeting e lies in it
            plane[m, 0] = fa1 * fb2 - fa2 * fb1
            plane[m, 1] = fa2 * fb0 - fa0 * fb2
            plane[m, 2] = fa0 * fb1 - fa1 * fb0
            # an edge whose line passes through v (within rounding) spans no plane: no pair is cut by it
            norm = np.sqrt(plane[m, 0] ** 2 + plane[m, 1] ** 2 + plane[m, 2] ** 2)
            for c in range(3):
                unit[m, c] = plane[m, c] / norm if norm > 0.0 else 0.0
            ids[m] = e
            slots[m] = m
            m += 1
        for k in range(ve_off[v], ve_off[v + 1]):
            incident[ve_edge[k]] = False
        keys, tgts, sides, bits, n_reg = _register(q, 1, depth, lazy, mask, ends[:m], slots[:m], n, margin, eps, keys,
                                                   tgts, sides, bits, 0, src, centres, radii, normals, plane_offsets,
                                                   tol)  # fmt: skip
        order, group_off = _group(keys, n_reg, n_cells)
        for cell in range(n_cells):
            g0 = group_off[cell]
            g1 = group_off[cell + 1]
            for x in range(g0, g1):
                rx = order[x]
                sf = tgts[rx]
                f = ids[sf]
                # by element: row views would cost two reference counts each, per pair
                pf0, pf1, pf2 = plane[sf, 0], plane[sf, 1], plane[sf, 2]
                nf = np.sqrt(pf0 * pf0 + pf1 * pf1 + pf2 * pf2)
                for y in range(x + 1, g1):
                    ry = order[y]
                    # the sub-cells first: most pairs share none, and the test reads no other row
                    if bits[rx] & bits[ry] == 0:
                        continue
                    sg = tgts[ry]
                    g = ids[sg]
                    if f == g or _share_vertex(edges, f, g):
                        continue
                    if _off_plane(unit, ends, p, sf, sg, reach) or _off_plane(unit, ends, p, sg, sf, reach):
                        continue
                    pg0, pg1, pg2 = plane[sg, 0], plane[sg, 1], plane[sg, 2]
                    d0 = pf1 * pg2 - pf2 * pg1
                    d1 = pf2 * pg0 - pf0 * pg2
                    d2 = pf0 * pg1 - pf1 * pg0
                    length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                    if length <= delta * nf * np.sqrt(pg0 * pg0 + pg1 * pg1 + pg2 * pg2):
                        continue
                    d[0] = d0 / length
                    d[1] = d1 / length
                    d[2] = d2 / length
                    a, i, j, flipped = _line_cell(d, n)
                    if (a * n + i) * n + j != cell:
                        continue
                    if flipped:
                        d[0] = -d[0]
                        d[1] = -d[1]
                        d[2] = -d[2]
                    ok_f, tf = _meets_segment(p, d, vertices, edges, normals, plane_offsets, ef_off, ef_face, f, tol,
                                                  delta)  # fmt: skip
                    if not ok_f:
                        continue
                    ok_g, tg = _meets_segment(p, d, vertices, edges, normals, plane_offsets, ef_off, ef_face, g, tol,
                                                  delta)  # fmt: skip
                    if not ok_g:
                        continue
                    side_f = 0 if tf > 0.0 else 1
                    side_g = 0 if tg > 0.0 else 1
                    if side_f != sides[rx] or side_g != sides[ry]:
                        continue
                    if abs(tf) > depth[0, side_f, cell] + margin or abs(tg) > depth[0, side_g, cell] + margin:
                        continue
                    if side_f == side_g:
                        inner = f if abs(tf) < abs(tg) else g
                        if _edge_pierced(inner, d, vertices, edges, ef_off, ef_inward, delta):
                            # two edges crossing at one point (a box's bottom edge across the top edge of the
                            # box it stands on): either may be the inner one, the other the one the line stops on
                            outer = g if inner == f else f
                            if abs(abs(tf) - abs(tg)) > tol or _edge_pierced(
                                outer, d, vertices, edges, ef_off, ef_inward, delta
                            ):
                                continue
                    elif _vertex_pierced(v, d, points, offsets, normals, vf_off, vf_face, vf_corner, delta, angle_tol,
                                         arc_starts, arc_lengths, arc_bounds):  # fmt: skip
                        continue
                    if _vee_enters(v, f, g, p, d, tf, tg, others, back, vertex_object, edge_object, object_offsets,
                                   object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin,
                                   delta):  # fmt: skip
                        continue
                    if lazy and not _line_meets(p, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                                angle_tol):  # fmt: skip
                        continue
                    if count == capacity:
                        out, capacity = _grown_output(out, count)
                    _write(out, count, CANDIDATE_VEE, v, -1, min(f, g), max(f, g), -1, -1, p, d)
                    count += 1
    return _trim(out, count)


@njit_leaf
def _off_plane(unit, ends, p, plane_row, edge_row, reach):
    """Whether both ends of target edge_row (ends (M, 2, 3)) lie beyond `reach` on one side of the plane through p
    of unit normal unit[plane_row]."""
    h0 = 0.0
    h1 = 0.0
    for c in range(3):
        h0 += unit[plane_row, c] * (ends[edge_row, 0, c] - p[c])
        h1 += unit[plane_row, c] * (ends[edge_row, 1, c] - p[c])
    return min(h0, h1) > reach or max(h0, h1) < -reach


@njit_leaf
def _vee_enters(v, f, g, p, d, tf, tg, others, u, vertex_object, edge_object, object_offsets, object_polygons, vf_off,
                vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
    """Whether an outer generator of the VEE / EVE line (through p = vertex v, edges f at tf and g at tg along
    d) leaves into its object's inside, away from the other generators (see `_enters_object`)."""
    if (tf > 0.0) == (tg > 0.0):
        sign = 1.0 if tf > 0.0 else -1.0
        far = f if abs(tf) > abs(tg) else g
        t_near = tg if far == f else tf
        for c in range(3):
            others[0, c] = p[c] + tf * d[c]
            others[1, c] = p[c] + tg * d[c]
            u[c] = sign * d[c]
        if _enters_object(True, v, u, others, 2, vertex_object, edge_object, object_offsets, object_polygons, vf_off,
                          vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
            return True
        for c in range(3):
            others[0, c] = p[c]
            others[1, c] = p[c] + t_near * d[c]
            u[c] = -sign * d[c]
        return _enters_object(False, far, u, others, 2, vertex_object, edge_object, object_offsets, object_polygons,
                              vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta)  # fmt: skip
    for k in range(2):
        edge = f if k == 0 else g
        t_own = tf if k == 0 else tg
        t_other = tg if k == 0 else tf
        sign = -1.0 if t_own > 0.0 else 1.0
        for c in range(3):
            others[0, c] = p[c]
            others[1, c] = p[c] + t_other * d[c]
            u[c] = sign * d[c]
        if _enters_object(False, edge, u, others, 2, vertex_object, edge_object, object_offsets, object_polygons,
                          vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
            return True
    return False


# ----------------------------------------------------------------------------------------------------------
# E4: lines through four edges, found from the inner edge of lowest id


@njit_leaf
def _clip2(src, count, ca, cb, cc, dst):
    """Sutherland-Hodgman in the (s, t) plane: the part of src[:count] where ca s + cb t + cc >= 0."""
    out = 0
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        fp = ca * src[k, 0] + cb * src[k, 1] + cc
        fq = ca * src[k2, 0] + cb * src[k2, 1] + cc
        if fp >= 0.0:
            dst[out, 0] = src[k, 0]
            dst[out, 1] = src[k, 1]
            out += 1
        if (fp >= 0.0) != (fq >= 0.0):
            t = fp / (fp - fq)
            dst[out, 0] = src[k, 0] + t * (src[k2, 0] - src[k, 0])
            dst[out, 1] = src[k, 1] + t * (src[k2, 1] - src[k, 1])
            out += 1
    return out


@njit_leaf
def _curve_meets(c0, c1, c2, c3, poly, count, slack):
    """Whether c0 + c1 s + c2 t + c3 s t vanishes (within slack) on the convex polygon poly[:count] of the
    (s, t) plane. The function is harmonic, so its range over the polygon is its range over the boundary,
    a quadratic along each side."""
    lo = np.inf
    hi = -np.inf
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        ps = poly[k, 0]
        pt = poly[k, 1]
        ds = poly[k2, 0] - ps
        dt = poly[k2, 1] - pt
        f = c0 + c1 * ps + c2 * pt + c3 * ps * pt
        lo = min(lo, f)
        hi = max(hi, f)
        qa = c3 * ds * dt
        qb = c1 * ds + c2 * dt + c3 * (ps * dt + pt * ds)
        if qa != 0.0:
            tau = -qb / (2.0 * qa)
            if 0.0 < tau < 1.0:
                fm = f + qb * tau + qa * tau * tau
                lo = min(lo, fm)
                hi = max(hi, fm)
        if lo <= slack and hi >= -slack:
            return True
    return lo <= slack and hi >= -slack


@njit_leaf
def _bilinear_range(c0, c1, c2, c3, poly, count):
    """(lo, hi): the range of c0 + c1 s + c2 t + c3 s t over the convex polygon poly[:count] of the (s, t)
    plane (harmonic: reached on the boundary, a quadratic along each side)."""
    lo = np.inf
    hi = -np.inf
    for k in range(count):
        k2 = k + 1 if k + 1 < count else 0
        ps = poly[k, 0]
        pt = poly[k, 1]
        ds = poly[k2, 0] - ps
        dt = poly[k2, 1] - pt
        f = c0 + c1 * ps + c2 * pt + c3 * ps * pt
        lo = min(lo, f)
        hi = max(hi, f)
        qa = c3 * ds * dt
        qb = c1 * ds + c2 * dt + c3 * (ps * dt + pt * ds)
        if qa != 0.0:
            tau = -qb / (2.0 * qa)
            if 0.0 < tau < 1.0:
                fm = f + qb * tau + qa * tau * tau
                lo = min(lo, fm)
                hi = max(hi, fm)
    return lo, hi


@njit(cache=True)
def _family_may_cross(ea, ed, h, xd, region, count, src, points, offsets, tol):
    """Whether some line E(s) X(t) of region[:count] (E(s) = ea + s ed, X(t) = ea + h + t xd) may cross one
    of the polygons `src` within tol; False only when none can (a lazy build's pruning of a pivot).

    A line crosses a convex polygon when it passes on one side of all its edge lines: the side of the line
    through E and X against the edge P P' is (X - E) . ((P - E) x (P' - E)), bilinear in (s, t) (its s^2 term
    is ed . (ed x (P' - P)) = 0). Its value is the lines' distance times |(X - E) x (P' - P)|: a line within
    tol of the polygon (in its plane, say) gets values within tol |X - E| |P' - P| of the right sign."""
    reach = np.sqrt(_dot(h, h)) + np.sqrt(_dot(xd, xd)) + np.sqrt(_dot(ed, ed))
    for p in src:
        first = offsets[p]
        count_p = offsets[p + 1] - first
        can_positive = True
        can_negative = True
        for k in range(count_p):
            a = points[first + k] - ea
            b = points[first + (k + 1) % count_p] - ea
            side = b - a
            big = _cross(a, b)
            small = -_cross(ed, side)
            c0 = _dot(h, big)
            c1 = _dot(h, small) - _dot(ed, big)
            c2 = _dot(xd, big)
            c3 = _dot(xd, small)
            slack = 2.0 * tol * reach * np.sqrt(_dot(side, side)) + 1e-9 * (abs(c0) + abs(c1) + abs(c2) + abs(c3))
            lo, hi = _bilinear_range(c0, c1, c2, c3, region, count)
            if hi < -slack:
                can_positive = False
            if lo > slack:
                can_negative = False
            if not (can_positive or can_negative):
                break
        if can_positive or can_negative:
            return True
    return False


@njit_leaf
def _quadratic_roots(c0, c1, c2, c3, k0, k1, k2, k3, cosine, roots):
    """The common zeros (s, t) of c0 + c1 s + c2 t + c3 s t and k0 + k1 s + k2 t + k3 s t, written to roots
    (2, 2); returns how many (0 also when the two curves coincide: infinitely many lines, no node)."""
    # eliminate t = -(c0 + c1 s) / (c2 + c3 s): a quadratic in s
    qa = k1 * c3 - k3 * c1
    qb = k0 * c3 + k1 * c2 - k2 * c1 - k3 * c0
    qc = k0 * c2 - k2 * c0
    scale = max(abs(c0), abs(c1), abs(c2), abs(c3)) * max(abs(k0), abs(k1), abs(k2), abs(k3))
    if max(abs(qa), abs(qb), abs(qc)) <= cosine * scale:
        return 0
    # scalars, not an array: this runs for every pair of curves of a cell, and an allocation costs more than the rest
    s_first = 0.0
    s_second = 0.0
    found = 0
    if qa == 0.0:
        if qb == 0.0:
            return 0
        s_first = -qc / qb
        found = 1
    else:
        disc = qb * qb - 4.0 * qa * qc
        if disc < 0.0:
            return 0
        root = np.sqrt(disc)
        big = -0.5 * (qb + (root if qb >= 0.0 else -root))
        if big == 0.0:
            found = 1
        else:
            s_first = big / qa
            s_second = qc / big
            found = 2
    n_out = 0
    for r in range(found):
        s = s_first if r == 0 else s_second
        den1 = c2 + c3 * s
        den2 = k2 + k3 * s
        if abs(den1) >= abs(den2):
            if den1 == 0.0:
                continue
            t = -(c0 + c1 * s) / den1
        else:
            t = -(k0 + k1 * s) / den2
        roots[n_out, 0] = s
        roots[n_out, 1] = t
        n_out += 1
    return n_out


@njit_leaf
def _along_from_s(rel, along, x, y, ed, margin, delta, out, row):
    """For the lines E(s) X(t) meeting edge y (E(s) = e_a + s ed, X(t) = e_a + h + t xd, y from e_a + y_rel
    along yd; h, xd, y_rel, yd the rows x and y of rel and along): the point Y(u) = e_a + y_rel + u yd where
    the line through E(s) meets y is a Moebius function of s, u = (a0 - s b0) / (s b1 - a1). out[row] (7,):
    a0, a1, b0, b1, the u range (lo, hi) of y grown by margin at both ends, and 1 (filled). Rows are passed
    by index: a view would cost the caller two reference counts per root. The range is unbounded when s
    hardly depends on u (x and y in one plane with E(s), or nearly: determinant within delta of the
    coefficients' scale), where u from s means nothing.

    The line through Y(u) meeting x lies in the plane through Y(u) and x, of normal A - u B with A = (x_a - y_a)
    x xd, B = yd x xd; E(s) lies in it for s = (A - u B) . (Y(u) - e_a) / ((A - u B) . ed), linear over linear
    in u (B . yd = 0), and inverted here."""
    r0 = rel[x, 0] - rel[y, 0]
    r1 = rel[x, 1] - rel[y, 1]
    r2 = rel[x, 2] - rel[y, 2]
    x0, x1, x2 = along[x, 0], along[x, 1], along[x, 2]
    y0, y1, y2 = along[y, 0], along[y, 1], along[y, 2]
    a0 = r1 * x2 - r2 * x1
    a1 = r2 * x0 - r0 * x2
    a2 = r0 * x1 - r1 * x0
    b0 = y1 * x2 - y2 * x1
    b1 = y2 * x0 - y0 * x2
    b2 = y0 * x1 - y1 * x0
    out[row, 0] = a0 * rel[y, 0] + a1 * rel[y, 1] + a2 * rel[y, 2]
    out[row, 1] = a0 * y0 + a1 * y1 + a2 * y2 - (b0 * rel[y, 0] + b1 * rel[y, 1] + b2 * rel[y, 2])
    out[row, 2] = a0 * ed[0] + a1 * ed[1] + a2 * ed[2]
    out[row, 3] = -(b0 * ed[0] + b1 * ed[1] + b2 * ed[2])
    out[row, 6] = 1.0
    determinant = out[row, 1] * out[row, 2] - out[row, 0] * out[row, 3]
    scale = (abs(out[row, 0]) + abs(out[row, 1])) * (abs(out[row, 2]) + abs(out[row, 3]))
    if abs(determinant) <= delta * scale:
        out[row, 4] = -np.inf
        out[row, 5] = np.inf
        return
    reach = margin / np.sqrt(y0 * y0 + y1 * y1 + y2 * y2)
    out[row, 4] = -reach
    out[row, 5] = 1.0 + reach


@njit_leaf
def _plane_reach(ed, h0, h1, h2, xd0, xd1, xd2, scale, tol):
    """(n0, n1, n2, reach) for source edge e (direction ed (3,)) and pivot x (from e's first end: offset h, direction
    xd): the unit normal of the plane through e parallel to x, and how far from that plane a target met by a line
    of the pivot's family can lie (inf when nothing is bounded: e and x nearly parallel or apart).

    Lines E(s) X(t) more than tol long (shorter ones are no line: _edge_candidates turns them away first) rise
    from height 0 at E(s) to the height delta of x's line over the plane, so at distance tau along the line they
    lie within delta |tau| / tol of it. Where such a line meets a target (_meets_segment: within tol of the target
    grown by tol at both ends), both points lie in the scene's box grown by 2 tol, as E(s) does by tol: |tau| <=
    scale + 8 tol, and the target's ends lie within that height plus 2 tol. Coplanar edges (delta 0: boxes of one
    height, edges on one floor) bound their lines to the plane, where most targets are not. Heights are dot
    products of scene-sized vectors with the normal, each rounded by far less than 1e-12 scale once the angle
    between e and x exceeds 1e-3 radians: that slack is added wherever a height is compared."""
    n0 = ed[1] * xd2 - ed[2] * xd1
    n1 = ed[2] * xd0 - ed[0] * xd2
    n2 = ed[0] * xd1 - ed[1] * xd0
    across = np.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
    lengths = np.sqrt(ed[0] * ed[0] + ed[1] * ed[1] + ed[2] * ed[2]) * np.sqrt(xd0 * xd0 + xd1 * xd1 + xd2 * xd2)
    if not across > 1e-3 * lengths:
        return 0.0, 0.0, 0.0, np.inf
    n0 /= across
    n1 /= across
    n2 /= across
    slack = 1e-12 * scale
    delta = abs(n0 * h0 + n1 * h1 + n2 * h2) + slack
    return n0, n1, n2, delta * (scale + 8.0 * tol) / tol + 2.0 * tol + slack


@njit_leaf
def _far_past_ends(moebius, row, s):
    """Whether the line of the family through E(s) meets y outside its u range (moebius[row], see
    _along_from_s), without a division; False when the range is unbounded or the map has its pole at s."""
    if moebius[row, 5] == np.inf:
        return False
    numerator = moebius[row, 0] - s * moebius[row, 2]
    denominator = s * moebius[row, 3] - moebius[row, 1]
    if denominator > 0.0:
        return numerator < moebius[row, 4] * denominator or numerator > moebius[row, 5] * denominator
    if denominator < 0.0:
        return numerator > moebius[row, 4] * denominator or numerator < moebius[row, 5] * denominator
    return False


@njit_leaf
def _cone_value(a, k, lo_u, hi_u, lo_w, hi_w, rows, r):
    """The k-th bounding plane of a cell's cone (chart axis a) applied to the vector rows[r] (3,): >= 0 inside.
    (A row index, not a row: a view would cost two reference counts per call in the pivot loop.)"""
    b = (a + 1) % 3
    c = (a + 2) % 3
    if k == 0:
        return rows[r, b] - lo_u * rows[r, a]
    if k == 1:
        return hi_u * rows[r, a] - rows[r, b]
    if k == 2:
        return rows[r, c] - lo_w * rows[r, a]
    return hi_w * rows[r, a] - rows[r, c]


@njit(cache=True, nogil=True)
def _edge_candidates(
    sources, source_bins, emask, vertices, edges, points, offsets, normals, plane_offsets, edge_out, centres, radii,
    widths, cell_sine, object_offsets, object_polygons, object_centres, object_radii, ef_off, ef_face,
    ef_inward, vf_off, vf_face, vertex_object, edge_object, grid, n, lazy, src, margin, delta, eps, tol, angle_tol,
    scale,
):  # fmt: skip
    """E4 candidates whose inner edge of lowest id is one of `sources` (cut in source_bins bins each).

    For a bin of source edge e and a cell, the lines are parametrised by their points E(s) on e and X(t) on a
    pivot edge x; those with a direction in the cell form a convex region R of the (s, t) plane, and the
    lines of the family meeting another edge y form the zero set of a bilinear function (the EEE restriction
    of seed 003 section 3.2.2). Only edges whose curve crosses R are paired; each pair of curves meets in at
    most two points, the E4 lines.
    """
    capacity = 256
    out = _new_output(capacity)
    count = 0
    n_cells = 3 * n * n
    edge_ids = np.flatnonzero(emask)
    n_edges = edge_ids.shape[0]
    ends = np.empty((n_edges, 2, 3))
    ids = np.empty(n_edges, dtype=np.int64)
    slots = np.empty(n_edges, dtype=np.int64)
    rel = np.empty((n_edges, 3))  # x_a - e_a
    along = np.empty((n_edges, 3))  # x_b - x_a
    wg = np.empty((n_edges, 3))  # (y_a - e_a) x (y_b - y_a)
    dg = np.empty((n_edges, 3))  # (e_b - e_a) x (y_b - y_a)
    keys = np.empty(4096, dtype=np.int64)
    tgts = np.empty(4096, dtype=np.int64)
    sides = np.empty(4096, dtype=np.int8)
    bits = np.empty(4096, dtype=np.uint64)
    roots = np.empty((2, 2))
    region = np.empty((16, 2))
    scratch = np.empty((16, 2))
    coef = np.empty((n_edges, 4))
    chosen = np.empty(n_edges, dtype=np.int64)
    # what the pair loop reads of each chosen curve, side by side: gathered once per curve instead of through the
    # registration rows at every pair (17.9 M pairs of 2.03 M curves at 312 polygons)
    chosen_bits = np.empty(n_edges, dtype=np.uint64)
    chosen_side = np.empty(n_edges, dtype=np.int8)
    chosen_edge = np.empty(n_edges, dtype=np.int64)
    chosen_ends = np.empty((n_edges, 2), dtype=np.int64)
    chosen_slot = np.empty(n_edges, dtype=np.int64)
    # the same of a group's members (a target registers in a key at most once per side), gathered once per group
    # for the loops over its pivots and their partners
    member_bits = np.empty(2 * n_edges, dtype=np.uint64)
    member_side = np.empty(2 * n_edges, dtype=np.int8)
    member_edge = np.empty(2 * n_edges, dtype=np.int64)
    member_ends = np.empty((2 * n_edges, 2), dtype=np.int64)
    member_slot = np.empty(2 * n_edges, dtype=np.int64)
    across = np.empty(n_edges, dtype=np.int64)
    moebius = np.empty((n_edges, 7))
    gen = np.empty(3, dtype=np.int64)
    reg = np.empty(3, dtype=np.int64)
    pos = np.empty(3)
    start = np.empty(3)
    d = np.empty(3)
    u = np.empty(3)
    others = np.empty((3, 3))
    for index in range(sources.shape[0]):
        e = sources[index]
        nb = source_bins[index]
        ea = vertices[edges[e, 0]]
        eb = vertices[edges[e, 1]]
        ed = eb - ea
        source_direction = ed.reshape((1, 3))
        q = np.empty((nb + 1, 3))
        for k in range(nb + 1):
            q[k] = ea + (k / nb) * ed
        mask = np.ones((nb, n_cells), dtype=np.bool_)
        if lazy:
            _source_mask(q, nb, src, points, offsets, normals, plane_offsets, edge_out, grid, n, tol, delta, mask)
        _mask_pierced_cells(e, vertices, edges, ef_off, ef_inward, grid, n, delta, mask)
        if not mask.any():
            continue
        depth = np.full((nb, 2, n_cells), np.inf)
        _depth_map(
            q, nb, points, offsets, normals, plane_offsets, edge_out, centres, radii, widths, cell_sine, object_offsets,
            object_polygons, object_centres, object_radii, grid, n, margin, delta, eps, mask, depth, lazy,
            src, tol,
        )  # fmt: skip
        m = 0
        for f in edge_ids:
            if f == e or _share_vertex(edges, e, f):
                continue
            # every line through e and f pierces e: f generates no line kept from e
            if _target_pierces(e, f, vertices, edges, ef_off, ef_inward, delta, tol):
                continue
            xa = edges[f, 0]
            xb = edges[f, 1]
            for c in range(3):
                ends[m, 0, c] = vertices[xa, c]
                ends[m, 1, c] = vertices[xb, c]
                rel[m, c] = vertices[xa, c] - ea[c]
                along[m, c] = vertices[xb, c] - vertices[xa, c]
            _cross_row(rel[m, 0], rel[m, 1], rel[m, 2], along[m, 0], along[m, 1], along[m, 2], wg, m)
            _cross_row(ed[0], ed[1], ed[2], along[m, 0], along[m, 1], along[m, 2], dg, m)
            ids[m] = f
            slots[m] = m
            m += 1
        keys, tgts, sides, bits, n_reg = _register(q, nb, depth, lazy, mask, ends[:m], slots[:m], n, margin, eps,
                                                   keys, tgts, sides, bits, 0, src, centres, radii, normals,
                                                   plane_offsets, tol)  # fmt: skip
        order, group_off = _group(keys, n_reg, nb * n_cells)
        len_e = _norm(ed)
        for key in range(nb * n_cells):
            g0 = group_off[key]
            g1 = group_off[key + 1]
            # a group lists its targets in increasing id (registration follows the slots); a line is kept from
            # its lowest inner edge, so a group of ids all below e yields no line kept here
            if g1 - g0 < 3 or ids[tgts[order[g1 - 1]]] < e:
                continue
            b = key // n_cells
            cell = key - b * n_cells
            a = cell // (n * n)
            a_u = (a + 1) % 3
            a_w = (a + 2) % 3
            i = (cell // n) % n
            j = cell % n
            lo_u = -1.0 + 2.0 * i / n - eps
            hi_u = -1.0 + 2.0 * (i + 1) / n + eps
            lo_w = -1.0 + 2.0 * j / n - eps
            hi_w = -1.0 + 2.0 * (j + 1) / n + eps
            s_lo = b / nb - eps
            s_hi = (b + 1) / nb + eps
            later_behind = 0
            for xi in range(g0, g1):
                r = order[xi]
                m = xi - g0
                member_bits[m] = bits[r]
                member_side[m] = sides[r]
                member_slot[m] = tgts[r]
                f = ids[tgts[r]]
                member_edge[m] = f
                member_ends[m, 0] = edges[f, 0]
                member_ends[m, 1] = edges[f, 1]
                later_behind += member_side[m]
            for xi in range(g0, g1 - 2):
                rx = order[xi]
                later_behind -= sides[rx]
                # the pivot's lines need a later generator across e from it
                if (later_behind if sides[rx] == 0 else g1 - xi - 1 - later_behind) == 0:
                    continue
                sx = tgts[rx]
                fx = ids[sx]
                sign = 1.0 if sides[rx] == 0 else -1.0
                # R: lines E(s) X(t) of the bin whose direction +-(X - E) lies in the cell
                region[0, 0] = s_lo
                region[0, 1] = 0.0
                region[1, 0] = s_hi
                region[1, 1] = 0.0
                region[2, 0] = s_hi
                region[2, 1] = 1.0
                region[3, 0] = s_lo
                region[3, 1] = 1.0
                k_count = 4
                for k in range(4):
                    cs = -sign * _cone_value(a, k, lo_u, hi_u, lo_w, hi_w, source_direction, 0)
                    ct = sign * _cone_value(a, k, lo_u, hi_u, lo_w, hi_w, along, sx)
                    cc = sign * _cone_value(a, k, lo_u, hi_u, lo_w, hi_w, rel, sx)
                    k_count = _clip2(region, k_count, cs, ct, cc, scratch)
                    for r in range(k_count):
                        region[r, 0] = scratch[r, 0]
                        region[r, 1] = scratch[r, 1]
                if k_count == 0:
                    continue
                if lazy and not _family_may_cross(ea, ed, rel[sx], along[sx], region, k_count, src, points, offsets,
                                                  tol):  # fmt: skip
                    continue
                # the pivot's rows as numbers: views would cost reference counts per pivot
                h0, h1, h2 = rel[sx, 0], rel[sx, 1], rel[sx, 2]
                xd0, xd1, xd2 = along[sx, 0], along[sx, 1], along[sx, 2]
                len_x = np.sqrt(xd0 * xd0 + xd1 * xd1 + xd2 * xd2)
                # a pivot coplanar with e (a fifth of them in an office) holds its lines to their plane: the
                # targets lying off it on one side are met by none
                p0, p1, p2, reach = _plane_reach(ed, h0, h1, h2, xd0, xd1, xd2, scale, tol)
                bounded = reach < scale
                n_chosen = 0
                behind_after = later_behind
                chosen_across = False
                x_bits = member_bits[xi - g0]
                x_side = member_side[xi - g0]
                x0 = member_ends[xi - g0, 0]
                x1 = member_ends[xi - g0, 1]
                for yi in range(xi + 1, g1):
                    my = yi - g0
                    y_side = member_side[my]
                    behind_after -= y_side
                    # a y beside x pairs with a z across: with none chosen and none left, nothing is
                    if (
                        y_side == x_side
                        and not chosen_across
                        and (behind_after if x_side == 0 else g1 - yi - 1 - behind_after) == 0
                    ):
                        break
                    if x_bits & member_bits[my] == 0:
                        continue
                    fy = member_edge[my]
                    y0 = member_ends[my, 0]
                    y1 = member_ends[my, 1]
                    if fy == fx or _ends_shared(x0, x1, y0, y1):
                        continue
                    # beside x on its side, y would be with x the two generators of the side holding two, both
                    # below e (ids increase along the group): no line of such a pair is kept (see below)
                    if y_side == x_side and fy < e:
                        continue
                    sy = member_slot[my]
                    if bounded:
                        height = p0 * rel[sy, 0] + p1 * rel[sy, 1] + p2 * rel[sy, 2]
                        rise = p0 * along[sy, 0] + p1 * along[sy, 1] + p2 * along[sy, 2]
                        if min(height, height + rise) > reach or max(height, height + rise) < -reach:
                            continue
                    # by element: views of the rows would cost two reference counts per pair
                    w0, w1, w2 = wg[sy, 0], wg[sy, 1], wg[sy, 2]
                    dg0, dg1, dg2 = dg[sy, 0], dg[sy, 1], dg[sy, 2]
                    c0 = h0 * w0 + h1 * w1 + h2 * w2
                    c1 = -(ed[0] * w0 + ed[1] * w1 + ed[2] * w2) - (h0 * dg0 + h1 * dg1 + h2 * dg2)
                    c2 = xd0 * w0 + xd1 * w1 + xd2 * w2
                    c3 = -(xd0 * dg0 + xd1 * dg1 + xd2 * dg2)
                    slack = eps * (abs(c0) + abs(c1) + abs(c2) + abs(c3))
                    if not _curve_meets(c0, c1, c2, c3, region, k_count, slack):
                        continue
                    chosen[n_chosen] = order[yi]
                    chosen_bits[n_chosen] = member_bits[my]
                    chosen_side[n_chosen] = y_side
                    chosen_edge[n_chosen] = fy
                    chosen_ends[n_chosen, 0] = y0
                    chosen_ends[n_chosen, 1] = y1
                    chosen_slot[n_chosen] = sy
                    chosen_across = chosen_across or y_side != x_side
                    moebius[n_chosen, 6] = 0.0
                    coef[n_chosen, 0] = c0
                    coef[n_chosen, 1] = c1
                    coef[n_chosen, 2] = c2
                    coef[n_chosen, 3] = c3
                    n_chosen += 1
                # an E4 line has generators on both sides of e: beside a y on x's side, z comes from across
                n_across = 0
                for ya in range(n_chosen):
                    if chosen_side[ya] != x_side:
                        across[n_across] = ya
                        n_across += 1
                passed = 0
                for ya in range(n_chosen):
                    ry = chosen[ya]
                    fy = chosen_edge[ya]
                    y0 = chosen_ends[ya, 0]
                    y1 = chosen_ends[ya, 1]
                    y_side = chosen_side[ya]
                    bits_xy = x_bits & chosen_bits[ya]
                    while passed < n_across and across[passed] <= ya:
                        passed += 1
                    beside = y_side == x_side
                    for k in range(n_across - passed if beside else n_chosen - ya - 1):
                        za = across[passed + k] if beside else ya + 1 + k
                        if bits_xy & chosen_bits[za] == 0:
                            continue
                        fz = chosen_edge[za]
                        z0 = chosen_ends[za, 0]
                        z1 = chosen_ends[za, 1]
                        if fz == fy or _ends_shared(y0, y1, z0, z1):
                            continue
                        z_side = chosen_side[za]
                        behind = x_side + y_side + z_side
                        # the line is kept from its inner edge of lowest id (below), and the other inner edge
                        # is one of the two generators on the side holding two: both below e, it is not kept
                        two_side = 0 if behind == 1 else 1
                        if max(fx if x_side == two_side else -1, fy if y_side == two_side else -1,
                               fz if z_side == two_side else -1) < e:  # fmt: skip
                            continue
                        rz = chosen[za]
                        ry_slot = chosen_slot[ya]
                        rz_slot = chosen_slot[za]
                        found = _quadratic_roots(coef[ya, 0], coef[ya, 1], coef[ya, 2], coef[ya, 3], coef[za, 0],
                                                 coef[za, 1], coef[za, 2], coef[za, 3], angle_tol, roots)  # fmt: skip
                        for r in range(found):
                            s = roots[r, 0]
                            t = roots[r, 1]
                            if s * len_e < -tol or (s - 1.0) * len_e > tol:
                                continue
                            # the two curves also cross off R, where the line misses the pivot (its point
                            # X(t) off x by more than tol: _meets_segment turns it away, after costlier tests;
                            # 30 % of the roots within e at 312 polygons). Twice tol: the root's t is not the
                            # point _meets_segment finds, up to rounding
                            if t * len_x < -_PIVOT_SLACK * tol or (t - 1.0) * len_x > _PIVOT_SLACK * tol:
                                continue
                            if min(max(int(s * nb), 0), nb - 1) != b:
                                continue
                            for c in range(3):
                                start[c] = ea[c] + s * ed[c]
                            d[0] = h0 + t * xd0 + ea[0] - start[0]
                            d[1] = h1 + t * xd1 + ea[1] - start[1]
                            d[2] = h2 + t * xd2 + ea[2] - start[2]
                            # a pivot touching e (an edge resting on it, a corner on it) puts a root of every pair
                            # at the contact point, where E(s) = X(t): no line; a sixth of all roots at 312 polygons
                            length = _norm(d)
                            if length <= tol:
                                continue
                            # most roots fall in another cell: the cell's cone (grown by eps), either way along
                            # the line, turns them away before the division
                            v0 = d[a_u] - lo_u * d[a]
                            v1 = hi_u * d[a] - d[a_u]
                            v2 = d[a_w] - lo_w * d[a]
                            v3 = hi_w * d[a] - d[a_w]
                            if not (min(v0, v1, v2, v3) >= 0.0 or max(v0, v1, v2, v3) <= 0.0):
                                continue
                            # where the line meets y and z, from s alone: most lines of the cell miss one
                            if moebius[ya, 6] == 0.0:
                                _along_from_s(rel, along, sx, ry_slot, ed, margin, delta, moebius, ya)
                            if moebius[za, 6] == 0.0:
                                _along_from_s(rel, along, sx, rz_slot, ed, margin, delta, moebius, za)
                            if _far_past_ends(moebius, ya, s) or _far_past_ends(moebius, za, s):
                                continue
                            for c in range(3):
                                d[c] /= length
                            ca, ci, cj, flipped = _line_cell(d, n)
                            if (ca * n + ci) * n + cj != cell:
                                continue
                            if flipped:
                                for c in range(3):
                                    d[c] = -d[c]
                            gen[0] = fx
                            gen[1] = fy
                            gen[2] = fz
                            reg[0] = rx
                            reg[1] = ry
                            reg[2] = rz
                            ok = True
                            for k in range(3):
                                hit, tk = _meets_segment(start, d, vertices, edges, normals, plane_offsets, ef_off,
                                                         ef_face, gen[k], tol, delta)  # fmt: skip
                                side = 0 if tk > 0.0 else 1
                                if not hit or side != sides[reg[k]] or abs(tk) > depth[b, side, cell] + margin:
                                    ok = False
                                    break
                                pos[k] = tk
                            if not ok:
                                continue
                            # e is inner; the other inner edge is the nearest on the side holding two
                            other = -1
                            nearest = np.inf
                            for k in range(3):
                                if sides[reg[k]] == two_side and abs(pos[k]) < nearest:
                                    nearest = abs(pos[k])
                                    other = gen[k]
                            if other < e:
                                continue
                            if _edge_pierced(e, d, vertices, edges, ef_off, ef_inward, delta) or _edge_pierced(
                                other, d, vertices, edges, ef_off, ef_inward, delta
                            ):
                                continue
                            # the outer edges must not leave into their object's inside
                            entering = False
                            for k in range(3):
                                lowest = True
                                highest = True
                                for k2 in range(3):
                                    if k2 != k and pos[k2] < pos[k]:
                                        lowest = False
                                    if k2 != k and pos[k2] > pos[k]:
                                        highest = False
                                if not (lowest or highest):
                                    continue
                                n_others = 0
                                for k2 in range(3):
                                    if k2 != k:
                                        for c in range(3):
                                            others[n_others, c] = start[c] + pos[k2] * d[c]
                                        n_others += 1
                                for c in range(3):
                                    others[2, c] = start[c]
                                    u[c] = d[c] if lowest else -d[c]
                                if _enters_object(False, gen[k], u, others, 3, vertex_object, edge_object,
                                                  object_offsets, object_polygons, vf_off, vf_face, ef_off, ef_face,
                                                  normals, plane_offsets, margin, delta):  # fmt: skip
                                    entering = True
                                    break
                            if entering:
                                continue
                            if lazy and not _line_meets(start, d, src, points, offsets, normals, plane_offsets,
                                                        edge_out, tol, angle_tol):  # fmt: skip
                                continue
                            if count == capacity:
                                out, capacity = _grown_output(out, count)
                            _write_edges(out, count, CANDIDATE_E4, e, fx, fy, fz, start, d)
                            count += 1
    return _trim(out, count)


# ----------------------------------------------------------------------------------------------------------
# FEE / EFE: lines in a face's plane through the crossings of two edges (section 3.2.3)


@njit(cache=True, nogil=True)
def _face_candidates(
    polygon_ids, lo, hi, emask, vertices, edges, points, offsets, normals, plane_offsets, edge_out, corner_edge,
    vertex_object, edge_object, object_offsets, object_polygons, vf_off, vf_face, ef_off, ef_face, centres, radii,
    lazy, src, margin, delta, tol, angle_tol,
):  # fmt: skip
    """Lines lying in the plane of polygons polygon_ids[lo:hi] through the points where two masked edges cross
    that plane, kept when they cross the polygon (entering and leaving it through two masked edges, not at a
    corner). Seed 003 section 3.2.3 and Fig. 10: intersect each face's plane with every edge, join pairs of
    crossings. Such a line is where an EEE swath whose lines graze an edge of the face turns into the face's
    plane: beyond it they would cut the face, and the swath through the face's other crossed edge takes over.

    Pruned (safe, see `_enters_object`): a crossing edge whose convex object the line enters on the side of
    the other generators. Returns candidates (kind CANDIDATE_FEE, the four edges sorted)."""
    capacity = 64
    out = _new_output(capacity)
    count = 0
    n_edges = edges.shape[0]
    crossing = np.empty(n_edges, dtype=np.int64)
    at = np.empty((n_edges, 3))
    others = np.empty((3, 3))
    u = np.empty(3)
    d = np.empty(3)
    for index in range(lo, hi):
        f = polygon_ids[index]
        if lazy and not _plane_near_sources(f, src, normals, plane_offsets, centres, radii, tol):
            continue
        normal = normals[f]
        first = offsets[f]
        corners = offsets[f + 1] - first
        k = 0
        n0, n1, n2 = normal[0], normal[1], normal[2]
        for e in range(n_edges):
            if not emask[e]:
                continue
            # coordinates as numbers: row views cost two reference counts each, for every face and edge
            ia = edges[e, 0]
            ib = edges[e, 1]
            ha = n0 * vertices[ia, 0] + n1 * vertices[ia, 1] + n2 * vertices[ia, 2] + plane_offsets[f]
            hb = n0 * vertices[ib, 0] + n1 * vertices[ib, 1] + n2 * vertices[ib, 2] + plane_offsets[f]
            # strictly across: an edge ending in the plane meets it at a vertex (VEE / VV lines)
            if ha * hb >= 0.0 or abs(ha) <= tol or abs(hb) <= tol:
                continue
            crossing[k] = e
            w = ha / (ha - hb)
            for c in range(3):
                at[k, c] = vertices[ia, c] + w * (vertices[ib, c] - vertices[ia, c])
            k += 1
        for i in range(k):
            p = at[i]
            p0, p1, p2 = p[0], p[1], p[2]
            for j in range(i + 1, k):
                # by component into d: array expressions here allocated, for every pair of crossings of every face
                d0 = at[j, 0] - p0
                d1 = at[j, 1] - p1
                d2 = at[j, 2] - p2
                length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
                if length <= tol:
                    continue
                d[0] = d0 / length
                d[1] = d1 / length
                d[2] = d2 / length
                # the line p + t d (in the plane) crosses the polygon over [t_in, t_out]
                t_in = -np.inf
                t_out = np.inf
                e_in = -1
                e_out = -1
                outside = False
                for c in range(first, first + corners):
                    offset = (p0 - points[c, 0]) * edge_out[c, 0] + (p1 - points[c, 1]) * edge_out[c, 1] + \
                        (p2 - points[c, 2]) * edge_out[c, 2]  # fmt: skip
                    rate = d[0] * edge_out[c, 0] + d[1] * edge_out[c, 1] + d[2] * edge_out[c, 2]
                    if abs(rate) <= angle_tol:
                        if offset > -tol:
                            outside = True
                            break
                        continue
                    t = -offset / rate
                    if rate > 0.0:
                        if t < t_out:
                            t_out = t
                            e_out = corner_edge[c]
                    elif t > t_in:
                        t_in = t
                        e_in = corner_edge[c]
                if outside or t_out - t_in <= tol or e_in == e_out or not emask[e_in] or not emask[e_out]:
                    continue
                # through a corner of the polygon: the line meets a vertex there (a VEE line)
                corner = False
                for c in range(first, first + corners):
                    r0 = points[c, 0] - p0
                    r1 = points[c, 1] - p1
                    r2 = points[c, 2] - p2
                    x0 = r1 * d[2] - r2 * d[1]
                    x1 = r2 * d[0] - r0 * d[2]
                    x2 = r0 * d[1] - r1 * d[0]
                    if np.sqrt(x0 * x0 + x1 * x1 + x2 * x2) <= tol:
                        corner = True
                        break
                if corner:
                    continue
                ei = crossing[i]
                ej = crossing[j]
                # two edges of one face: the line is where the two faces' planes meet (an FF node), whose
                # swaths all keep two edges of one face (FE pencils, not stored)
                if _shared_face(ef_off, ef_face, ei, ej):
                    continue
                # local visibility at the two crossings: the line must not dive into an edge's object on the
                # side where the other generators are
                for c in range(3):
                    others[0, c] = p[c] + length * d[c]
                    others[1, c] = p[c] + t_in * d[c]
                    others[2, c] = p[c] + t_out * d[c]
                    u[c] = d[c]
                if _enters_object(False, ei, u, others, 3, vertex_object, edge_object, object_offsets,
                                  object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin,
                                  delta):  # fmt: skip
                    continue
                if t_in < 0.0:
                    for c in range(3):
                        u[c] = -d[c]
                    if _enters_object(False, ei, u, others, 3, vertex_object, edge_object, object_offsets,
                                      object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets,
                                      margin, delta):  # fmt: skip
                        continue
                for c in range(3):
                    others[0, c] = p[c]
                    u[c] = -d[c]
                if _enters_object(False, ej, u, others, 3, vertex_object, edge_object, object_offsets,
                                  object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin,
                                  delta):  # fmt: skip
                    continue
                if t_out > length:
                    for c in range(3):
                        u[c] = d[c]
                    if _enters_object(False, ej, u, others, 3, vertex_object, edge_object, object_offsets,
                                      object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets,
                                      margin, delta):  # fmt: skip
                        continue
                if lazy and not _line_meets(p, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                            angle_tol):  # fmt: skip
                    continue
                if count == capacity:
                    out, capacity = _grown_output(out, count)
                _write_edges(out, count, CANDIDATE_FEE, ei, ej, e_in, e_out, p, d)
                count += 1
    return _trim(out, count)


@njit(cache=True, nogil=True)
def _crossing_candidates(
    vmask, vertices, edges, points, offsets, normals, plane_offsets, edge_out, pairs, crossings, planes, n, lazy,
    src, tol, angle_tol,
):  # fmt: skip
    """VEE candidates through the crossing point X of two masked edges (their interiors meet at one point, as
    where the bottom edge of a box stacked with an overhang crosses the top edge of the box under it) and a
    masked vertex v in their plane: the line v X, with edges (e, f). pairs, crossings, planes: _edge_crossings.

    The double wedges of _vertex_candidates see such a triple as coplanar and propose nothing, but the line is
    a node where touching objects meet: the EV and EEE swaths through X end on it (seed 000 section 2.2,
    touching objects). Validation decides, as for every candidate."""
    capacity = 64
    out = _new_output(capacity)
    count = 0
    vertex_ids = np.flatnonzero(vmask)
    d = np.empty(3)
    for k in range(pairs.shape[0]):
        e = pairs[k, 0]
        f = pairs[k, 1]
        x = crossings[k]
        normal = planes[k]
        for v in vertex_ids:
            w = vertices[v]
            if abs(_dot(w - x, normal)) > tol:
                continue
            if edges[e, 0] == v or edges[e, 1] == v or edges[f, 0] == v or edges[f, 1] == v:
                continue
            length = _norm(x - w)
            if length <= tol:
                continue
            for c in range(3):
                d[c] = (x[c] - w[c]) / length
            _, _, _, flipped = _line_cell(d, n)
            if flipped:
                for c in range(3):
                    d[c] = -d[c]
            if lazy and not _line_meets(w, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                        angle_tol):  # fmt: skip
                continue
            if count == capacity:
                out, capacity = _grown_output(out, count)
            _write(out, count, CANDIDATE_VEE, v, -1, min(e, f), max(e, f), -1, -1, w, d)
            count += 1
    return _trim(out, count)


@njit(cache=True)
def _junction_candidates(
    vmask, emask, vertices, edges, ve_off, ve_edge, points, offsets, normals, plane_offsets, edge_out, n, lazy, src,
    tol, angle_tol,
):  # fmt: skip
    """VEE candidates through a masked vertex v lying inside a masked edge `extra` of another element (a box's
    corner on the edge of a box beside or under it: a T-junction) and the point P where a masked edge g strictly
    crosses the plane of `extra` and an edge of v: the line v P, with edges (g, extra).

    The lines of that plane through P meeting `extra` and v's edge turn at v P (their contact on v's edge
    reaches v): that line ends their pencil, as an FXE line ends the pencils through a crossing of two edges'
    interiors. v lies on `extra`, so the double wedges of _vertex_candidates propose nothing here; validation
    takes the vertex on `extra` for the junction it is (its pencils: validation._pencils_at_junction)."""
    capacity = 16
    out = _new_output(capacity)
    count = 0
    vertex_ids = np.flatnonzero(vmask)
    edge_ids = np.flatnonzero(emask)
    d = np.empty(3)
    for v in vertex_ids:
        w = vertices[v]
        w0, w1, w2 = w[0], w[1], w[2]
        for extra in edge_ids:
            ia = edges[extra, 0]
            ib = edges[extra, 1]
            if ia == v or ib == v:
                continue
            # v outside the edge's box grown by tol (most pairs stop here). Coordinates as numbers: row views
            # cost two reference counts each, for every vertex and edge
            if (w0 < min(vertices[ia, 0], vertices[ib, 0]) - tol or w0 > max(vertices[ia, 0], vertices[ib, 0]) + tol
                    or w1 < min(vertices[ia, 1], vertices[ib, 1]) - tol
                    or w1 > max(vertices[ia, 1], vertices[ib, 1]) + tol
                    or w2 < min(vertices[ia, 2], vertices[ib, 2]) - tol
                    or w2 > max(vertices[ia, 2], vertices[ib, 2]) + tol):  # fmt: skip
                continue
            a = vertices[ia]
            b = vertices[ib]
            len_extra = _norm(b - a)
            if len_extra <= tol:
                continue
            along = _dot(w - a, b - a) / len_extra
            if not tol < along < len_extra - tol or _norm(w - a - along * (b - a) / len_extra) > tol:
                continue
            for slot in range(ve_off[v], ve_off[v + 1]):
                e_v = ve_edge[slot]
                if not emask[e_v]:
                    continue
                other = vertices[edges[e_v, 1] if edges[e_v, 0] == v else edges[e_v, 0]]
                normal = _cross(b - a, other - w)
                size = _norm(normal)
                # v's edge along `extra` (boxes side by side) spans no plane
                if size <= angle_tol * len_extra * _norm(other - w):
                    continue
                normal /= size
                offset = -_dot(normal, w)
                for g in edge_ids:
                    if g == extra or edges[g, 0] == v or edges[g, 1] == v:
                        continue
                    if not _towards_piercing(vertices, edges, g, normal, offset, w, n, tol, d):
                        continue
                    if lazy and not _line_meets(w, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                                angle_tol):  # fmt: skip
                        continue
                    if count == capacity:
                        out, capacity = _grown_output(out, count)
                    _write(out, count, CANDIDATE_VEE, v, -1, min(g, extra), max(g, extra), -1, -1, w, d)
                    count += 1
    return _trim(out, count)


@njit_leaf
def _towards_piercing(vertices, edges, g, normal, offset, through, n, tol, d):
    """Whether edge g crosses the plane normal . x + offset = 0 strictly (each end off it by more than tol) at
    a point farther than tol from `through` (3,); if so, d (3,) is the unit direction from `through` to that
    point, turned the way the cube map keeps line directions (_line_cell)."""
    w0 = vertices[edges[g, 0]]
    w1 = vertices[edges[g, 1]]
    h0 = _dot(normal, w0) + offset
    h1 = _dot(normal, w1) + offset
    if h0 * h1 >= 0.0 or abs(h0) <= tol or abs(h1) <= tol:
        return False
    share = h0 / (h0 - h1)
    for c in range(3):
        d[c] = w0[c] + share * (w1[c] - w0[c]) - through[c]
    length = _norm(d)
    if length <= tol:
        return False
    for c in range(3):
        d[c] /= length
    if _line_cell(d, n)[3]:
        for c in range(3):
            d[c] = -d[c]
    return True


@njit_leaf
def _share_vertex(edges, f, g):
    return _ends_shared(edges[f, 0], edges[f, 1], edges[g, 0], edges[g, 1])


@njit_leaf
def _ends_shared(a0, a1, b0, b1):
    """Whether an edge of end vertices a0, a1 and one of ends b0, b1 share a vertex."""
    return a0 == b0 or a0 == b1 or a1 == b0 or a1 == b1


# ----------------------------------------------------------------------------------------------------------
# lines through the crossing of two edges: in their plane (FXE) and across it (E4 with a crossing pair)


def _once_through_crossings(found, crossings, n_edges: int, tol: float, scale: float, proposed: dict):
    """`found` (NodeCandidates fields) without the E4 candidates through a crossing whose line is already in
    `proposed` (four edges -> list of (origin, unit direction)), which gains the lines of those kept. A candidate
    is through a crossing when two of its edges cross (crossings: _edge_crossings) and its line passes through
    that point (within 4 tol). The edge phase may find such a line from either crossing edge: they meet it at one
    point, so which of them is inner, and on which side, is a matter of rounding. Two lines are the same when the
    points of each at its origin and a scene size (scale) along it lie within 4 tol of the other."""
    kind, _, edges, origin, direction = found
    pairs, points, _ = crossings
    keys = pairs[:, 0] * n_edges + pairs[:, 1]
    order = np.argsort(keys)
    rows = np.flatnonzero(kind == CANDIDATE_E4)
    through = np.zeros(len(kind), dtype=bool)
    for i in range(4):
        for j in range(i + 1, 4):
            pair_keys = edges[rows, i] * n_edges + edges[rows, j]
            slot = np.minimum(np.searchsorted(keys, pair_keys, sorter=order), len(keys) - 1)
            match = keys[order[slot]] == pair_keys
            for row, k in zip(rows[match], order[slot[match]], strict=True):
                if _off_line(points[k], origin[row], direction[row]) <= 4.0 * tol:
                    through[row] = True
    keep = np.ones(len(kind), dtype=bool)
    for row in np.flatnonzero(through):
        lines = proposed.setdefault(tuple(edges[row].tolist()), [])
        line = (origin[row], direction[row])
        keep[row] = not any(_same_line(line, other, scale, 4.0 * tol) for other in lines)
        if keep[row]:
            lines.append(line)
    if keep.all():
        return found
    return tuple(column[keep] for column in found)


def _same_line(a: tuple, b: tuple, scale: float, within: float) -> bool:
    """Whether lines a and b, each (origin (3,), unit direction (3,)), are one: the points of each at its origin
    and `scale` along it lie `within` of the other."""
    return all(
        _off_line(origin + along * direction, *other) <= within
        for (origin, direction), other in ((a, b), (b, a))
        for along in (0.0, scale)
    )


def _off_line(point: np.ndarray, origin: np.ndarray, direction: np.ndarray) -> float:
    """The distance from a point (3,) to the line through origin (3,) along the unit direction (3,)."""
    offset = point - origin
    return float(np.linalg.norm(offset - (offset @ direction) * direction))


def _not_proposed(found, proposed: dict):
    """The candidates of `found` (NodeCandidates fields) whose edges are not in `proposed`."""
    keep = np.array([tuple(row) not in proposed for row in found[2].tolist()], dtype=bool)
    return tuple(column[keep] for column in found)


@njit(cache=True)
def _edge_crossings(emask, vertices, edges, tol):
    """The pairs of masked edges whose interiors cross at one point (objects in contact: a box's bottom edge
    across the top edge of the box it stands on): pairs (K, 2) int64 (lower id first), points (K, 3) and unit
    normals (K, 3) of the plane of each pair."""
    edge_ids = np.flatnonzero(emask)
    pairs = np.empty((16, 2), dtype=np.int64)
    at = np.empty((16, 3))
    planes = np.empty((16, 3))
    count = 0
    for ia in range(edge_ids.shape[0]):
        e = edge_ids[ia]
        a = vertices[edges[e, 0]]
        b = vertices[edges[e, 1]]
        len_e = _norm(b - a)
        if len_e <= tol:
            continue
        ux = (b[0] - a[0]) / len_e
        uy = (b[1] - a[1]) / len_e
        uz = (b[2] - a[2]) / len_e
        lo0, hi0 = min(a[0], b[0]) - tol, max(a[0], b[0]) + tol
        lo1, hi1 = min(a[1], b[1]) - tol, max(a[1], b[1]) + tol
        lo2, hi2 = min(a[2], b[2]) - tol, max(a[2], b[2]) + tol
        for ib in range(ia + 1, edge_ids.shape[0]):
            f = edge_ids[ib]
            # boxes apart by more than tol: no crossing (most pairs stop here). Coordinates as numbers: a row
            # view costs two reference counts, for every pair of edges of the scene
            f0 = edges[f, 0]
            f1 = edges[f, 1]
            if (min(vertices[f0, 0], vertices[f1, 0]) > hi0 or max(vertices[f0, 0], vertices[f1, 0]) < lo0
                    or min(vertices[f0, 1], vertices[f1, 1]) > hi1 or max(vertices[f0, 1], vertices[f1, 1]) < lo1
                    or min(vertices[f0, 2], vertices[f1, 2]) > hi2
                    or max(vertices[f0, 2], vertices[f1, 2]) < lo2):  # fmt: skip
                continue
            if _share_vertex(edges, e, f):
                continue
            p = vertices[f0]
            q = vertices[f1]
            ok, t, sf, gap = _meet(a[0], a[1], a[2], ux, uy, uz, p[0], p[1], p[2], q[0], q[1], q[2])
            if not ok or gap > tol:
                continue
            len_f = _norm(q - p)
            if not (tol < t < len_e - tol and tol < sf * len_f < len_f - tol):
                continue
            if count == pairs.shape[0]:
                pairs = np.concatenate((pairs, np.empty_like(pairs)))
                at = np.concatenate((at, np.empty_like(at)))
                planes = np.concatenate((planes, np.empty_like(planes)))
            pairs[count, 0] = e
            pairs[count, 1] = f
            normal = _cross(b - a, q - p)
            for c in range(3):
                at[count, c] = a[c] + t * (b[c] - a[c]) / len_e
                planes[count, c] = normal[c] / _norm(normal)
            count += 1
    return pairs[:count], at[:count], planes[:count]


@njit(cache=True, nogil=True)
def _crossing_plane_candidates(
    emask, vertices, edges, points, offsets, normals, plane_offsets, edge_out, pairs, crossings, planes, n, lazy, src,
    tol, angle_tol,
):  # fmt: skip
    """Lines through the crossing point X of two masked edges e, f (pairs, crossings, planes: _edge_crossings) and
    the point P where a
    third masked edge g strictly crosses the plane of e and f: the line X P, with edges (e, f, g).

    The lines through X meeting g sweep an EEE swath (e, f, g) that turns into the contact plane at X P, as
    the lines through a vertex meeting an edge turn into the plane of a face at the vertex (seed 003's FvE
    node, appendix 7.1): beyond it they would pass into the objects meeting at X. The double wedges see X as
    no vertex and the face planes hold no crossing for _face_candidates, so nothing else proposes X P.
    Validation decides, as for every candidate. Returns candidates (kind CANDIDATE_FXE, edges sorted, one
    -1 last)."""
    capacity = 64
    out = _new_output(capacity)
    count = 0
    edge_ids = np.flatnonzero(emask)
    d = np.empty(3)
    for k in range(pairs.shape[0]):
        e = pairs[k, 0]
        f = pairs[k, 1]
        x = crossings[k]
        normal = planes[k]
        offset = -_dot(normal, x)
        for g in edge_ids:
            # strictly across: an edge ending in the plane meets it at a vertex (_crossing_candidates)
            if g == e or g == f or not _towards_piercing(vertices, edges, g, normal, offset, x, n, tol, d):
                continue
            if lazy and not _line_meets(x, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                        angle_tol):  # fmt: skip
                continue
            three = np.array([e, f, g], dtype=np.int64)
            three.sort()
            if count == capacity:
                out, capacity = _grown_output(out, count)
            _write(out, count, CANDIDATE_FXE, -1, -1, three[0], three[1], three[2], -1, x, d)
            count += 1
    return _trim(out, count)


@njit(cache=True)
def _enters_before_others(e, tau, taus, contacts, d, vertex_object, edge_object, object_offsets, object_polygons,
                          vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin, delta):  # fmt: skip
    """_enters_object for edge e met at position tau of the line along d (unit), towards each side where other
    generators are met (taus (3,), contacts (3, 3): the line's three contact points, its own among them)."""
    others = np.empty((2, 3))
    count = 0
    ahead = False
    behind = False
    for r in range(3):
        if taus[r] == tau:
            continue
        others[count] = contacts[r]
        count += 1
        ahead = ahead or taus[r] > tau
        behind = behind or taus[r] < tau
    if ahead and _enters_object(False, e, d, others, count, vertex_object, edge_object, object_offsets,
                                object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets, margin,
                                delta):  # fmt: skip
        return True
    return behind and _enters_object(False, e, -d, others, count, vertex_object, edge_object, object_offsets,
                                     object_polygons, vf_off, vf_face, ef_off, ef_face, normals, plane_offsets,
                                     margin, delta)  # fmt: skip


@njit(cache=True, nogil=True)
def _crossing_transversal_candidates(
    emask, vertices, edges, points, offsets, normals, plane_offsets, edge_out, vertex_object, edge_object,
    object_offsets, object_polygons, vf_off, vf_face, ef_off, ef_face, pairs, crossings, planes, n, lazy, src, margin,
    delta, tol, angle_tol,
):  # fmt: skip
    """E4 lines through the crossing point X of two masked edges e, f (pairs, crossings, planes: _edge_crossings)
    meeting two more
    masked edges g and h across the plane of e and f: the line through X in the plane of X and g, through the
    point where h crosses that plane, when it meets g.

    Four edges with two of them crossing are a degenerate E4 configuration: their transversals are that line
    and one in the plane of e and f (an FEE / FXE line), and the quadric of _edge_candidates, through X,
    proposes neither. The line is where the EEE swath of the lines through X meeting g reaches h (or the swath
    (g, h, e) reaches the crossing), as a VEE node ends the swaths of a vertex. Pruned by local visibility at
    the four edges (see _enters_object). Returns candidates (kind CANDIDATE_E4, the four edges sorted)."""
    capacity = 64
    out = _new_output(capacity)
    count = 0
    edge_ids = np.flatnonzero(emask)
    d = np.empty(3)
    taus = np.empty(3)
    contacts = np.empty((3, 3))
    for k in range(pairs.shape[0]):
        e = pairs[k, 0]
        f = pairs[k, 1]
        x = crossings[k]
        for ig in range(edge_ids.shape[0]):
            g = edge_ids[ig]
            if g == e or g == f:
                continue
            a = vertices[edges[g, 0]]
            b = vertices[edges[g, 1]]
            len_g = _norm(b - a)
            normal = _cross(a - x, b - x)
            size = _norm(normal)
            # X on the line of g: every line through X meeting g lies along it
            if size <= tol * len_g:
                continue
            normal /= size
            for ih in range(ig + 1, edge_ids.shape[0]):
                h = edge_ids[ih]
                if h == e or h == f or _share_vertex(edges, g, h):
                    continue
                p = vertices[edges[h, 0]]
                q = vertices[edges[h, 1]]
                hp = _dot(normal, p - x)
                hq = _dot(normal, q - x)
                # strictly across: a line through an end of h meets a vertex there
                if hp * hq >= 0.0 or abs(hp) <= tol or abs(hq) <= tol:
                    continue
                share = hp / (hp - hq)
                for c in range(3):
                    d[c] = p[c] + share * (q[c] - p[c]) - x[c]
                length = _norm(d)
                if length <= tol:
                    continue
                for c in range(3):
                    d[c] /= length
                # lines in the plane of e and f are the FEE / FXE lines
                if abs(_dot(planes[k], d)) <= angle_tol:
                    continue
                ok, t, sg, gap = _meet(x[0], x[1], x[2], d[0], d[1], d[2], a[0], a[1], a[2], b[0], b[1], b[2])
                if not ok or gap > tol or not (tol < sg * len_g < len_g - tol) or abs(t) <= tol:
                    continue
                # g and h crossing each other: the line joins two crossings, proposed from the lower pair
                if abs(t - length) <= tol and (min(g, h) < e or (min(g, h) == e and max(g, h) < f)):
                    continue
                taus[0] = 0.0
                taus[1] = t
                taus[2] = length
                for c in range(3):
                    contacts[0, c] = x[c]
                    contacts[1, c] = x[c] + t * d[c]
                    contacts[2, c] = x[c] + length * d[c]
                pruned = False
                for r in range(4):
                    edge = e if r == 0 else f if r == 1 else g if r == 2 else h
                    tau = taus[max(r - 1, 0)]
                    if _enters_before_others(edge, tau, taus, contacts, d, vertex_object, edge_object,
                                             object_offsets, object_polygons, vf_off, vf_face, ef_off, ef_face,
                                             normals, plane_offsets, margin, delta):  # fmt: skip
                        pruned = True
                        break
                if pruned:
                    continue
                _, _, _, flipped = _line_cell(d, n)
                if flipped:
                    for c in range(3):
                        d[c] = -d[c]
                if lazy and not _line_meets(x, d, src, points, offsets, normals, plane_offsets, edge_out, tol,
                                            angle_tol):  # fmt: skip
                    continue
                if count == capacity:
                    out, capacity = _grown_output(out, count)
                _write_edges(out, count, CANDIDATE_E4, e, f, g, h, x, d)
                count += 1
    return _trim(out, count)
