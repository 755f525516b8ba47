"""Exact views of a polygon from a point, hence exact occluded point-to-polygon form factors.

Durand et al. 1999, section 4.2.1 (the form factor is Lambert's sum over the boundary of the *visible* part of
the source, whose corners are the extremal stabbing lines through the point) and Durand et al. 1997, section 2
(EV swaths through the point bound the view; VV and VEE lines through the point are its corners).

The view is computed by central projection: every candidate blocker is clipped to the pyramid (point, source)
-- so coordinates stay bounded, DESIGN.md section 4 -- and projected from the point onto the source's plane;
the projections are subtracted from the source (clipped to the receiver's hemisphere) as convex polygons.
The visible region is a set of disjoint convex pieces; every piece edge carries its generator: an edge of the
source, an edge of a blocker (an EV swath through the point), the intersection of a blocker's face with the
source's plane, or the receiver's horizon. Lambert's sum over the pieces is the exact form factor: the edges
shared by two pieces cancel. Candidate blockers come from shaft culling over the scene's BVH; the faces of a solid
object turned away from the point are skipped (its faces turned towards the point hide everything they would).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit, parallel_chunksize, prange
from numba.typed import List

from .bvh import build_bvh, bvh_collect_in_planes
from .errors import SceneError
from .formfactor import lambert_sum
from .jit import njit_leaf
from .scene import Scene

#: generator polygon of edges created by the receiver's tangent plane (the horizon of the hemisphere)
HORIZON = -1
#: generator edge of edges where a blocker's face crosses the source's plane (interpenetration)
FACE_CROSSING = -1
# pairs a thread of exact_pair_form_factors takes at a time: a view of a wall behind a furnished room costs a
# hundred times a small source's, so static halves of the range would leave one thread waiting
_PAIRS_PER_TASK = 16


@dataclass(frozen=True)
class View:
    """The visible part of `source` seen from `point` (normal `normal`).

    pieces: list of (K, 3) float64 disjoint convex polygons on the source, counter-clockwise around the
        source's normal as seen from the point's side; their union is the visible region.
    segments: (M, 2, 3) float64 boundary segments of the visible region (shared piece edges cancelled).
    generators: (M, 2) int64 per segment: (polygon, local edge) that generates it. polygon == source: an edge
        of the source; another polygon: an edge of a blocker (an EV swath through the point), or, with local
        edge FACE_CROSSING, the line where that blocker's face crosses the source's plane; polygon HORIZON:
        the receiver's tangent plane.
    corners: (C, 3) float64 corners of the boundary, where two generators meet.
    corner_lines: C extremal lines through the point and each corner: ("VV", vertex id) when the corner is
        the image of a scene vertex (the line passes through the point and that vertex), else
        ("VEE", (polygon, edge), (polygon, edge)) with the two generators of the segments meeting there.
    form_factor: the exact occluded form factor (projected solid angle of the visible region over pi).
    """

    point: np.ndarray
    normal: np.ndarray
    source: int
    pieces: list
    segments: np.ndarray
    generators: np.ndarray
    corners: np.ndarray
    corner_lines: list
    form_factor: float


def exact_form_factors(scene: Scene, points, normals, source: int, blockers=None, bvh=None) -> np.ndarray:
    """Exact occluded form factors from differential areas to polygon `source`.

    points: (N, 3) float64; normals: (N, 3) receiver normals (normalised here); source: polygon index;
    blockers: None for every polygon of the scene, or a sequence of polygon ids that may occlude.
    bvh: optional prebuilt core.bvh.BVH of the scene (built and cached on first use otherwise).
    Returns (N,) float64 in [0, 1]. Polygons whose plane holds the point (the receiver itself, its coplanar
    neighbours) can only be seen edge-on and never occlude it.
    """
    pts, nrm = _check_points(points, normals)
    _check_source(scene, source)
    allowed = _allowed_mask(scene, blockers)
    tree = bvh if bvh is not None else scene_bvh(scene)
    arrays = _scene_arrays(scene, allowed, source)
    sources = np.full(len(pts), source, dtype=np.int64)
    return _pair_form_factors(
        pts, nrm, sources, allowed, *arrays, *tree.arrays, scene.tol.length, *_bvh_for_every_point(len(pts))
    )


def exact_pair_form_factors(scene: Scene, points, normals, sources, bvh=None, shafts=None) -> np.ndarray:
    """Exact occluded form factors of N (point, source) pairs, every polygon of the scene a potential blocker:
    exact_form_factors for many sources at once, in one parallel call (the threads are woken once, not once per
    source, and the costly pairs of large sources are shared out among them).

    points, normals: (N, 3) float64 as for exact_form_factors; sources: (N,) int64 polygon indices.
    shafts: optional (shaft_of_point (N,) int64, ShaftBlockers): the blocker candidates of point i are the
    polygons of shaft shaft_of_point[i] (built by shaft_blockers for the point's polygon and its source;
    seed 000 section 5.3: a new vertex's view from the blocker list of its polygon-polygon link, and from no
    blocker at all when the list is empty, the full-visibility case), or the BVH's where it is -1.
    Returns (N,) float64 in [0, 1], element i equal to exact_form_factors(scene, points[i:i + 1],
    normals[i:i + 1], sources[i])[0].
    """
    pts, nrm = _check_points(points, normals)
    ids = np.asarray(sources, dtype=np.int64).reshape(-1)
    if len(ids) != len(pts):
        raise SceneError(f"sources must have one entry per point ({len(pts)}), got {len(ids)}")
    if len(ids) and (ids.min() < 0 or ids.max() >= scene.n_polygons):
        _check_source(scene, int(ids[(ids < 0) | (ids >= scene.n_polygons)][0]))
    if shafts is None:
        listed = _bvh_for_every_point(len(pts))
    else:
        shaft_of_point = np.asarray(shafts[0], dtype=np.int64).reshape(-1)
        lists = shafts[1]
        if len(shaft_of_point) != len(pts):
            raise SceneError(f"shafts must name one shaft per point ({len(pts)}), got {len(shaft_of_point)}")
        if len(shaft_of_point) and (shaft_of_point.min() < -1 or shaft_of_point.max() >= len(lists)):
            raise SceneError(f"shafts name shafts outside 0..{len(lists) - 1}")
        listed = (shaft_of_point, lists.offsets, lists.ids)
    allowed = _allowed_mask(scene, None)
    tree = bvh if bvh is not None else scene_bvh(scene)
    # with every polygon blocking, every object is complete whichever the source: the solids are the same
    arrays = _scene_arrays(scene, allowed, 0)
    with parallel_chunksize(_PAIRS_PER_TASK):
        return _pair_form_factors(pts, nrm, ids, allowed, *arrays, *tree.arrays, scene.tol.length, *listed)


@dataclass(frozen=True)
class ShaftBlockers:
    """Blocker candidates of M (receiver polygon, source polygon) pairs: pair k's are
    ids[offsets[k]:offsets[k + 1]]. offsets (M + 1,) int64, ids (L,) int64."""

    offsets: np.ndarray
    ids: np.ndarray

    def __len__(self) -> int:
        return len(self.offsets) - 1

    def blockers(self, pair: int) -> np.ndarray:
        return self.ids[self.offsets[pair] : self.offsets[pair + 1]]


def shaft_blockers(scene: Scene, receivers, sources, bvh=None) -> ShaftBlockers:
    """The polygons that may hide part of each source polygon from some point of its receiver polygon.

    receivers, sources: (M,) int64 polygon pairs. A polygon is listed when it may reach inside the convex hull
    of the two polygons (every segment from a receiver point to a source point lies in it) farther than
    tol.length from its boundary -- the test is conservative: a listed polygon may miss the hull -- or when it
    lies in the source's plane (it may cover part of the source, see _covers). A polygon touching the hull only
    at its boundary (a wall meeting floor and ceiling) can block only a set of directions without solid angle.
    Pairs of coplanar polygons get every polygon of the BVH's culling.
    """
    receivers = np.asarray(receivers, dtype=np.int64).reshape(-1)
    sources = np.asarray(sources, dtype=np.int64).reshape(-1)
    if len(receivers) != len(sources):
        raise SceneError(f"receivers ({len(receivers)}) and sources ({len(sources)}) must pair up")
    for name, ids in (("receiver", receivers), ("source", sources)):
        bad = ids[(ids < 0) | (ids >= scene.n_polygons)]
        if len(bad):
            raise SceneError(f"{name} {int(bad[0])} is not a polygon of the scene (0..{scene.n_polygons - 1})")
    tree = bvh if bvh is not None else scene_bvh(scene)
    offsets, ids = _shaft_blockers(
        receivers, sources, scene.polygon_offsets, scene.polygon_points, scene.normals, scene.plane_offsets,
        *tree.arrays, scene.tol.length,
    )
    return ShaftBlockers(offsets, ids)


def exact_cut_form_factors(scene: Scene, points, normals, source: int, subdivision, variation, limits, bvh=None):
    """Exact occluded form factors from points to the elements of a subdivision of polygon `source`, each point
    descending as deep as its limit asks (source refinement, seed 000 section 5.3).

    points, normals: (N, 3) as for exact_form_factors; subdivision: (triangles (E, 3, 3) float64 elements lying in
    the source's plane, first_child (E,) int64, child_count (E,) int64, roots (R,) int64: the elements that
    partition the source); variation (E,) float64 >= 0 and limits (N,) float64: an element is replaced by its
    children at a point while its form factor x its variation x the spread of the kernel over it exceeds the
    point's limit -- the error of reading it as its average (the spread is 1 for an element partly hidden or
    nearer than 3 radii, else 2 radius / (distance - radius) from its centroid). The form factor
    to an element is that of the part of the view inside it, so the elements of a point's cut add up to its
    form factor to the source. Returns (point (L,) int64, element (L,) int64, form_factor (L,) float64): the
    cut of every point, elements it cannot see left out.
    """
    pts, nrm = _check_points(points, normals)
    _check_source(scene, source)
    triangles, first_child, child_count, roots = (np.ascontiguousarray(a) for a in subdivision)
    if triangles.ndim != 3 or triangles.shape[1:] != (3, 3):
        raise ValueError(f"subdivision triangles must be (E, 3, 3), got {triangles.shape}")
    variation = np.asarray(variation, dtype=np.float64)
    limits = np.asarray(limits, dtype=np.float64).reshape(-1)
    if len(variation) != len(triangles) or len(limits) != len(pts):
        raise ValueError(f"variation ({len(variation)}) and limits ({len(limits)}) must match the elements "
                         f"({len(triangles)}) and the points ({len(pts)})")  # fmt: skip
    allowed = _allowed_mask(scene, None)
    tree = bvh if bvh is not None else scene_bvh(scene)
    arrays = _scene_arrays(scene, allowed, source)
    return _cut_form_factors(
        pts, nrm, source, allowed, *arrays, *tree.arrays, scene.tol.length, np.asarray(triangles, np.float64),
        np.asarray(first_child, np.int64), np.asarray(child_count, np.int64), np.asarray(roots, np.int64),
        variation, limits,
    )  # fmt: skip


def exact_view(scene: Scene, point, normal, source: int, blockers=None, bvh=None) -> View:
    """The exact view of polygon `source` from one point: visible pieces, labelled boundary, form factor.

    point, normal: (3,) float64. See exact_form_factors for the other arguments.
    """
    pts, nrm = _check_points(np.reshape(point, (1, 3)), np.reshape(normal, (1, 3)))
    _check_source(scene, source)
    allowed = _allowed_mask(scene, blockers)
    tree = bvh if bvh is not None else scene_bvh(scene)
    pieces_xy, pieces_gen, frame = _point_view(
        pts[0], nrm[0], source, allowed, *_scene_arrays(scene, allowed, source), *tree.arrays, scene.tol.length,
        _NOTHING_LISTED, False, False,
    )
    origin, u, v, scale = frame[0], frame[1], frame[2], frame[3][0]
    pieces = [origin + scale * (xy[:, :1] * u + xy[:, 1:2] * v) for xy in pieces_xy]
    total = 0.0
    for piece in pieces:
        total += lambert_sum(pts[0], nrm[0], piece, len(piece))
    segments, generators = _boundary(list(pieces_xy), list(pieces_gen), scene.tol.length / scale)
    segments3 = (origin + scale * (segments[..., :1] * u + segments[..., 1:2] * v)).reshape(-1, 2, 3)
    corners, corner_lines = _corners(scene, pts[0], segments3, generators, scene.tol.length)
    return View(
        point=pts[0],
        normal=nrm[0],
        source=int(source),
        pieces=pieces,
        segments=segments3,
        generators=generators,
        corners=corners,
        corner_lines=corner_lines,
        form_factor=abs(total) / (2.0 * np.pi),
    )


def _corners(scene: Scene, point, segments, generators, eps):
    """Where consecutive boundary segments meet, and the extremal line through the point and that corner."""
    corners = []
    lines = []
    for i in range(len(segments)):
        end = segments[i, 1]
        following = np.flatnonzero(np.linalg.norm(segments[:, 0] - end, axis=1) <= eps)
        for j in following:
            first, second = (int(g) for g in generators[i]), (int(g) for g in generators[j])
            first, second = tuple(first), tuple(second)
            corners.append(end)
            vertex = _shared_vertex(scene, point, end, first, second, eps)
            lines.append(("VV", vertex) if vertex >= 0 else ("VEE", first, second))
    return np.array(corners).reshape(-1, 3), lines


def _shared_vertex(scene: Scene, point, corner, first, second, eps) -> int:
    """The scene vertex both generators end at, when the corner lies on the line (point, that vertex)."""
    candidates = set()
    for polygon, edge in (first, second):
        if polygon < 0 or edge < 0:
            return -1
        ids = scene.polygon_vertices(polygon)
        candidates.add(frozenset((int(ids[edge]), int(ids[(edge + 1) % len(ids)]))))
    shared = set.intersection(*[set(c) for c in candidates]) if len(candidates) == 2 else set()
    if len(candidates) == 1:
        shared = set(next(iter(candidates)))
    for vertex in shared:
        direction = scene.vertices[vertex] - point
        offset = corner - point
        distance = np.linalg.norm(np.cross(direction, offset)) / max(np.linalg.norm(direction), eps)
        if distance <= eps and direction @ offset > 0.0:
            return vertex
    return -1


def _check_points(points, normals):
    pts = np.ascontiguousarray(points, dtype=np.float64)
    nrm = np.array(normals, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise SceneError(f"points must have shape (N, 3), got {pts.shape}")
    if nrm.shape != pts.shape:
        raise SceneError(f"normals must have the shape of points {pts.shape}, got {nrm.shape}")
    if not (np.isfinite(pts).all() and np.isfinite(nrm).all()):
        raise SceneError("points and normals must be finite")
    lengths = np.linalg.norm(nrm, axis=1)
    if np.any(lengths == 0.0):
        raise SceneError(f"normal {int(np.flatnonzero(lengths == 0.0)[0])} is zero")
    return pts, nrm / lengths[:, None]


def _check_source(scene: Scene, source: int) -> None:
    if not (0 <= int(source) < scene.n_polygons):
        raise SceneError(f"source polygon {source} is outside 0..{scene.n_polygons - 1}")


def _allowed_mask(scene: Scene, blockers) -> np.ndarray:
    if blockers is None:
        return np.ones(scene.n_polygons, dtype=np.bool_)
    ids = np.asarray(blockers, dtype=np.int64).reshape(-1)
    if ids.size and (ids.min() < 0 or ids.max() >= scene.n_polygons):
        bad = int(ids[(ids < 0) | (ids >= scene.n_polygons)][0])
        raise SceneError(f"blocker {bad} is not a polygon of the scene (0..{scene.n_polygons - 1})")
    allowed = np.zeros(scene.n_polygons, dtype=np.bool_)
    allowed[ids] = True
    return allowed


_BVH_OF_SCENE: dict[int, tuple] = {}
_CONVEX_OF_SCENE: dict[int, tuple] = {}


def _bvh_for_every_point(count: int):
    """The shaft arguments of _pair_form_factors that send every one of `count` points to the BVH."""
    return np.full(count, -1, dtype=np.int64), np.zeros(2, dtype=np.int64), _NOTHING_LISTED


_NOTHING_LISTED = np.empty(0, dtype=np.int64)


@njit(cache=True)
def _shaft_blockers(
    receivers, sources, offsets, corners, poly_normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps,
):
    count = len(receivers)
    out_offsets = np.zeros(count + 1, dtype=np.int64)
    out_ids = np.empty(max(16, 4 * count), dtype=np.int64)
    found_ids = np.empty(len(order), dtype=np.int64)
    total = 0
    for k in range(count):
        receiver = receivers[k]
        source = sources[k]
        a = corners[offsets[receiver] : offsets[receiver + 1]]
        b = corners[offsets[source] : offsets[source + 1]]
        hull = np.concatenate((a, b))
        planes = _hull_planes(hull, eps)
        found = bvh_collect_in_planes(
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, planes, eps, found_ids
        )
        if total + found > len(out_ids):
            out_ids = np.concatenate((out_ids, np.empty(max(total + found, 2 * len(out_ids)), dtype=np.int64)))
        for index in range(found):
            candidate = found_ids[index]
            if candidate == receiver or candidate == source:
                continue
            polygon = corners[offsets[candidate] : offsets[candidate + 1]]
            if len(planes) == 0 or _lies_in_plane(polygon, poly_normals[source], plane_offsets[source], eps):
                out_ids[total] = candidate
                total += 1
            elif not _separated(polygon, poly_normals[candidate], plane_offsets[candidate], hull, planes, eps):
                out_ids[total] = candidate
                total += 1
        out_offsets[k + 1] = total
    return out_offsets, out_ids[:total].copy()


@njit(cache=True)
def _hull_planes(points, eps):
    """(K, 4) planes (n, d), n unit, of the faces of the convex hull of points (N, 3): n . x + d <= 0 inside.

    Every plane through three of the points with all of them on one side (within eps) is a face plane; points
    with no such plane (all within eps of one plane or line) give K = 0.
    """
    n = len(points)
    planes = np.empty((n * (n - 1) * (n - 2) // 6, 4))
    found = 0
    for i in range(n):
        for j in range(i + 1, n):
            for k in range(j + 1, n):
                normal = np.cross(points[j] - points[i], points[k] - points[i])
                length = np.sqrt((normal * normal).sum())
                if length == 0.0:
                    continue
                normal /= length
                d = -(normal * points[i]).sum()
                highest = -np.inf
                lowest = np.inf
                for m in range(n):
                    h = (normal * points[m]).sum() + d
                    highest = max(highest, h)
                    lowest = min(lowest, h)
                if highest - lowest <= eps:
                    continue  # the points are flat: no solid hull
                if highest <= eps:
                    planes[found, :3] = normal
                    planes[found, 3] = d
                    found += 1
                elif lowest >= -eps:
                    planes[found, :3] = -normal
                    planes[found, 3] = -d
                    found += 1
    return planes[:found]


@njit(cache=True)
def _lies_in_plane(polygon, normal, offset, eps):
    for j in range(len(polygon)):
        if abs((normal * polygon[j]).sum() + offset) > eps:
            return False
    return True


@njit(cache=True)
def _separated(polygon, normal, offset, hull, planes, eps):
    """Whether a convex polygon stays out of the hull's interior shrunk by eps: all its corners on or outside
    one face plane, or all the hull's points on one side of (or within eps of) the polygon's plane."""
    for p in range(len(planes)):
        outside = True
        for j in range(len(polygon)):
            if (planes[p, :3] * polygon[j]).sum() + planes[p, 3] < -eps:
                outside = False
                break
        if outside:
            return True
    above = True
    below = True
    for m in range(len(hull)):
        h = (normal * hull[m]).sum() + offset
        if h < -eps:
            above = False
        if h > eps:
            below = False
    return above or below


def scene_bvh(scene: Scene):
    """The BVH over the scene's polygons, built once per scene and kept for the last scene asked."""
    cached = _BVH_OF_SCENE.get(id(scene))
    if cached is None or cached[0] is not scene:
        _BVH_OF_SCENE.clear()
        cached = (scene, build_bvh(scene))
        _BVH_OF_SCENE[id(scene)] = cached
    return cached[1]


def _scene_arrays(scene: Scene, allowed, source: int):
    solid = _complete_solids(scene, allowed, source)
    return (
        scene.polygon_offsets,
        scene.polygon_points,
        scene.normals,
        scene.plane_offsets,
        scene.areas,
        solid,
        np.where(solid & _convex_objects(scene), scene.object_ids, -1).astype(np.int64),
    )


def _convex_objects(scene: Scene) -> np.ndarray:
    """(P,) bool: polygons of solid objects that are convex (every vertex of the object on or behind the plane of
    each of its faces, within tol.length), computed once per scene."""
    cached = _CONVEX_OF_SCENE.get(id(scene))
    if cached is None or cached[0] is not scene:
        convex = scene.solid.copy()
        for obj in np.unique(scene.object_ids[scene.solid]):
            faces = np.flatnonzero(scene.object_ids == obj)
            corners = np.concatenate([scene.polygon(int(f)) for f in faces])
            heights = corners @ scene.normals[faces].T + scene.plane_offsets[faces]
            convex[faces] = heights.max() <= scene.tol.length
        _CONVEX_OF_SCENE.clear()
        cached = (scene, convex)
        _CONVEX_OF_SCENE[id(scene)] = cached
    return cached[1]


def _complete_solids(scene: Scene, allowed, source: int) -> np.ndarray:
    """(P,) bool: scene.solid, kept only for objects whose faces all block (or are the source): skipping a solid's
    faces turned away from the point relies on the faces turned towards it being there to block first."""
    present = allowed.copy()
    present[source] = True
    incomplete = np.zeros(int(scene.object_ids.max()) + 1, dtype=np.bool_)
    incomplete[scene.object_ids[~present]] = True
    return scene.solid & ~incomplete[scene.object_ids]


@njit(cache=True)
def _cut_form_factors(
    points, normals, source, allowed, offsets, corners, poly_normals, plane_offsets, areas, solid, hull_group,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps,
    triangles, first_child, child_count, roots, variation, limits,
):
    out_point = np.empty(64, dtype=np.int64)
    out_element = np.empty(64, dtype=np.int64)
    out_ff = np.empty(64)
    found = 0
    window = np.empty((3, 2))
    stack = np.empty(len(triangles) + len(roots), dtype=np.int64)
    nothing = np.empty(0, dtype=np.int64)
    for i in range(len(points)):
        pieces_xy, _, frame = _point_view(
            points[i], normals[i], source, allowed, offsets, corners, poly_normals, plane_offsets, areas, solid,
            hull_group, node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps, nothing,
            False, True,
        )
        if len(pieces_xy) == 0:
            continue
        depth = 0
        for r in roots:
            stack[depth] = r
            depth += 1
        while depth > 0:
            depth -= 1
            element = stack[depth]
            for j in range(3):
                _to_frame(triangles[element, j] - frame[0], frame[1], frame[2], frame[3, 0], window[j])
            ff, seen = _window_form_factor(points[i], normals[i], pieces_xy, frame, window)
            if ff <= 0.0:
                continue
            if child_count[element] > 0 and ff * variation[element] * _kernel_spread(
                points[i], triangles[element], seen
            ) > limits[i]:
                for c in range(first_child[element], first_child[element] + child_count[element]):
                    stack[depth] = c
                    depth += 1
                continue
            if found == len(out_ff):
                out_point = np.concatenate((out_point, np.empty(found, dtype=np.int64)))
                out_element = np.concatenate((out_element, np.empty(found, dtype=np.int64)))
                out_ff = np.concatenate((out_ff, np.empty(found)))
            out_point[found] = i
            out_element[found] = element
            out_ff[found] = ff
            found += 1
    return out_point[:found], out_element[:found], out_ff[:found]


@njit(cache=True)
def _kernel_spread(point, triangle, seen):
    """How much the point-to-area kernel cos cos / (pi r^2) can vary, relatively, over a triangle (3, 3) of
    which the fraction `seen` is visible: 1 when partly hidden (visibility steps inside it) or near, else
    2 rho / (d - rho) for its radius rho about its centroid at distance d (first order in rho / d)."""
    if seen < 1.0 - 1e-9:
        return 1.0
    centre = (triangle[0] + triangle[1] + triangle[2]) / 3.0
    radius = 0.0
    for j in range(3):
        radius = max(radius, np.sqrt(((triangle[j] - centre) ** 2).sum()))
    distance = np.sqrt(((point - centre) ** 2).sum())
    if distance <= 3.0 * radius:
        return 1.0
    return 2.0 * radius / (distance - radius)


@njit(cache=True)
def _window_form_factor(point, normal, pieces_xy, frame, window):
    """Form factor of the part of the visible pieces (convex, 2-D frame) inside the triangle window (3, 2), and
    the fraction of the window they cover."""
    area = (window[1, 0] - window[0, 0]) * (window[2, 1] - window[0, 1]) - (window[1, 1] - window[0, 1]) * (
        window[2, 0] - window[0, 0]
    )
    if area == 0.0:
        return 0.0, 0.0
    covered = 0.0
    clipped = List()
    for xy in pieces_xy:
        piece = xy
        for j in range(3):
            a = window[j] if area > 0.0 else window[2 - j]
            b = window[(j + 1) % 3] if area > 0.0 else window[(4 - j) % 3]
            piece = _clip_half_plane(piece, a[0], a[1], b[0], b[1])
            if len(piece) < 3:
                break
        if len(piece) >= 3:
            clipped.append(piece)
            for j in range(len(piece)):
                k = (j + 1) % len(piece)
                covered += piece[j, 0] * piece[k, 1] - piece[k, 0] * piece[j, 1]
    if len(clipped) == 0:
        return 0.0, 0.0
    return _pieces_form_factor(point, normal, clipped, frame), abs(covered) / abs(area)


@njit(cache=True)
def _clip_half_plane(xy, ax, ay, bx, by):
    """The part of convex polygon xy (K, 2) left of the directed line a -> b (Sutherland-Hodgman, one plane)."""
    k = len(xy)
    out = np.empty((k + 1, 2))
    count = 0
    for j in range(k):
        px, py = xy[j, 0], xy[j, 1]
        qx, qy = xy[(j + 1) % k, 0], xy[(j + 1) % k, 1]
        hp = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        hq = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
        if hp >= 0.0:
            out[count, 0] = px
            out[count, 1] = py
            count += 1
        if (hp > 0.0 and hq < 0.0) or (hp < 0.0 and hq > 0.0):
            t = hp / (hp - hq)
            out[count, 0] = px + t * (qx - px)
            out[count, 1] = py + t * (qy - py)
            count += 1
    return out[:count]


@njit(cache=True, parallel=True)
def _pair_form_factors(
    points, normals, sources, allowed, offsets, corners, poly_normals, plane_offsets, areas, solid, hull_group,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps,
    shaft_of_point, shaft_offsets, shaft_ids,
):
    """shaft_of_point (N,) int64: the shaft list (of shaft_offsets, shaft_ids) whose polygons are point i's
    candidate blockers, -1 for the BVH."""
    count = len(points)
    result = np.empty(count)
    for i in prange(count):
        shaft = shaft_of_point[i]
        listed = shaft_ids[shaft_offsets[max(shaft, 0)] : shaft_offsets[max(shaft, 0) + 1]]
        pieces_xy, _, frame = _point_view(
            points[i], normals[i], sources[i], allowed, offsets, corners, poly_normals, plane_offsets, areas, solid,
            hull_group, node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps,
            listed, shaft >= 0, True,
        )
        result[i] = _pieces_form_factor(points[i], normals[i], pieces_xy, frame)
    return result


@njit(cache=True)
def _pieces_form_factor(point, normal, pieces_xy, frame):
    origin = frame[0]
    u = frame[1]
    v = frame[2]
    scale = frame[3, 0]
    total = 0.0
    for xy in pieces_xy:
        lifted = np.empty((len(xy), 3))
        for j in range(len(xy)):
            for c in range(3):
                lifted[j, c] = origin[c] + scale * (xy[j, 0] * u[c] + xy[j, 1] * v[c])
        total += lambert_sum(point, normal, lifted, len(lifted))
    return min(abs(total) / (2.0 * np.pi), 1.0)


@njit(cache=True)
def _source_frame(polygon):
    """Origin (area-independent centroid of the corners), in-plane axes u, v and the polygon's radius."""
    origin = np.zeros(3)
    for j in range(len(polygon)):
        origin += polygon[j]
    origin /= len(polygon)
    normal = np.zeros(3)
    k = len(polygon)
    for j in range(k):
        a = polygon[j]
        b = polygon[(j + 1) % k]
        normal[0] += a[1] * b[2] - a[2] * b[1]
        normal[1] += a[2] * b[0] - a[0] * b[2]
        normal[2] += a[0] * b[1] - a[1] * b[0]
    normal /= np.sqrt((normal * normal).sum())
    helper = np.zeros(3)
    helper[np.argmin(np.abs(normal))] = 1.0
    u = np.cross(helper, normal)
    u /= np.sqrt((u * u).sum())
    v = np.cross(normal, u)
    radius = 0.0
    for j in range(k):
        d = polygon[j] - origin
        radius = max(radius, np.sqrt((d * d).sum()))
    frame = np.zeros((4, 3))
    frame[0] = origin
    frame[1] = u
    frame[2] = v
    frame[3, 0] = radius
    return frame


@njit(cache=True)
def _keep_positive(points, labels, side, sign, cut_polygon, cut_edge):
    """The part of a convex polygon (K, D) where the signed side sign * side[i] of its corners (side (K,),
    sign +-1.0) is >= 0.

    labels (K, 2) int64: generator of the edge starting at each corner; the new edge along the cut gets
    (cut_polygon, cut_edge). Returns the kept corners and their labels (possibly fewer than 3 corners).
    Rounding can make the signs of a convex polygon change more than twice (a blocker sharing an edge with the
    source lies along a side of the pyramid (point, source)): each such crossing adds a corner within rounding
    of the plane, which _cleanup drops. The corners are counted first, so that the result is allocated once
    (this runs for every blocker of every view).
    """
    k = len(points)
    count = 0
    for i in range(k):
        si = sign * side[i]
        sj = sign * side[(i + 1) % k]
        if si >= 0.0:
            count += 1
        if (si > 0.0 and sj < 0.0) or (si < 0.0 and sj > 0.0):
            count += 1
    out = np.empty((count, points.shape[1]))
    out_labels = np.empty((count, 2), dtype=np.int64)
    count = 0
    for i in range(k):
        j = (i + 1) % k
        si = sign * side[i]
        sj = sign * side[j]
        if si >= 0.0:
            out[count] = points[i]
            if si == 0.0 and sj < 0.0:
                out_labels[count, 0] = cut_polygon
                out_labels[count, 1] = cut_edge
            else:
                out_labels[count] = labels[i]
            count += 1
        if (si > 0.0 and sj < 0.0) or (si < 0.0 and sj > 0.0):
            t = si / (si - sj)
            for c in range(points.shape[1]):
                out[count, c] = points[i, c] + t * (points[j, c] - points[i, c])
            if si > 0.0:
                out_labels[count, 0] = cut_polygon
                out_labels[count, 1] = cut_edge
            else:
                out_labels[count] = labels[i]
            count += 1
    return out, out_labels


@njit(cache=True)
def _clip3(polygon, labels, plane_normal, plane_offset, cut_polygon, cut_edge):
    """Keep the part of a convex (K, 3) polygon where plane_normal . x + plane_offset >= 0 (see _keep_positive)."""
    side = np.empty(len(polygon))
    for i in range(len(polygon)):
        p = polygon[i]
        side[i] = plane_normal[0] * p[0] + plane_normal[1] * p[1] + plane_normal[2] * p[2] + plane_offset
    return _keep_positive(polygon, labels, side, 1.0, cut_polygon, cut_edge)


@njit(cache=True)
def _clip_into(points, labels, count, plane_normal, plane_offset, cut_polygon, cut_edge, out, out_labels):
    """_clip3 of the first `count` corners of points (C, 3) and labels (C, 2) into out and out_labels (at least
    2 count rows each, as rounding may add a corner per edge, see _keep_positive); returns the corners kept."""
    kept = 0
    for i in range(count):
        j = (i + 1) % count
        si = plane_normal[0] * points[i, 0] + plane_normal[1] * points[i, 1] + plane_normal[2] * points[i, 2]
        si += plane_offset
        sj = plane_normal[0] * points[j, 0] + plane_normal[1] * points[j, 1] + plane_normal[2] * points[j, 2]
        sj += plane_offset
        if si >= 0.0:
            for c in range(3):
                out[kept, c] = points[i, c]
            if si == 0.0 and sj < 0.0:
                out_labels[kept, 0] = cut_polygon
                out_labels[kept, 1] = cut_edge
            else:
                out_labels[kept, 0] = labels[i, 0]
                out_labels[kept, 1] = labels[i, 1]
            kept += 1
        if (si > 0.0 and sj < 0.0) or (si < 0.0 and sj > 0.0):
            t = si / (si - sj)
            for c in range(3):
                out[kept, c] = points[i, c] + t * (points[j, c] - points[i, c])
            if si > 0.0:
                out_labels[kept, 0] = cut_polygon
                out_labels[kept, 1] = cut_edge
            else:
                out_labels[kept, 0] = labels[i, 0]
                out_labels[kept, 1] = labels[i, 1]
            kept += 1
    return kept


@njit(cache=True)
def _split(xy, labels, ax, ay, bx, by, cut_polygon, cut_edge, eps):
    """Split a convex counter-clockwise 2-D polygon by the directed line a->b.

    Returns (inside_xy, inside_labels, outside_xy, outside_labels): inside is left of a->b. Corners within
    eps of the line count as on it; parts of zero width are returned empty. The polygon is clean (_cleanup):
    when the line does not cross it, it comes back whole, uncopied, on its side.
    """
    dx = bx - ax
    dy = by - ay
    length = np.sqrt(dx * dx + dy * dy)
    side = np.empty(len(xy))
    left = False
    right = False
    for i in range(len(xy)):
        value = (dx * (xy[i, 1] - ay) - dy * (xy[i, 0] - ax)) / length
        side[i] = 0.0 if abs(value) <= eps else value
        left = left or side[i] > 0.0
        right = right or side[i] < 0.0
    if not right or not left:
        # the other part would be corners on the line only, without area
        empty_xy = np.empty((0, 2))
        empty_labels = np.empty((0, 2), dtype=np.int64)
        if not right and left:
            return xy, labels, empty_xy, empty_labels
        if not left and right:
            return empty_xy, empty_labels, xy, labels
    inside, inside_labels = _keep_positive(xy, labels, side, 1.0, cut_polygon, cut_edge)
    outside, outside_labels = _keep_positive(xy, labels, side, -1.0, cut_polygon, cut_edge)
    in_xy, in_labels = _cleanup(inside, inside_labels, eps)
    out_xy, out_labels = _cleanup(outside, outside_labels, eps)
    return in_xy, in_labels, out_xy, out_labels


@njit(cache=True)
def _cleanup(xy, labels, eps):
    """Drop zero-length edges; return empty arrays when the polygon is thinner than eps."""
    k = len(xy)
    keep = np.ones(k, dtype=np.bool_)
    for i in range(k):
        j = (i + 1) % k
        dx = xy[j, 0] - xy[i, 0]
        dy = xy[j, 1] - xy[i, 1]
        if dx * dx + dy * dy <= eps * eps:
            # the edge i -> j is degenerate: corner i goes, corner j keeps its outgoing generator
            keep[i] = False
    count = 0
    for i in range(k):
        if keep[i]:
            count += 1
    if count < 3:
        return np.empty((0, 2)), np.empty((0, 2), dtype=np.int64)
    out = np.empty((count, 2))
    out_labels = np.empty((count, 2), dtype=np.int64)
    n = 0
    for i in range(k):
        if keep[i]:
            out[n] = xy[i]
            out_labels[n] = labels[i]
            n += 1
    area2 = 0.0
    perimeter = 0.0
    for i in range(count):
        j = (i + 1) % count
        area2 += out[i, 0] * out[j, 1] - out[j, 0] * out[i, 1]
        dx = out[j, 0] - out[i, 0]
        dy = out[j, 1] - out[i, 1]
        perimeter += np.sqrt(dx * dx + dy * dy)
    # width = 2 area / perimeter: a sliver thinner than eps has no area to speak of
    if area2 <= eps * perimeter:
        return np.empty((0, 2)), np.empty((0, 2), dtype=np.int64)
    return out, out_labels


@njit_leaf
def _side_range(polygon, edge_owner, e):
    """Highest and lowest signed distance of `polygon`'s corners (K, 2) to the line of edge e of `edge_owner`."""
    ax = edge_owner[e, 0]
    ay = edge_owner[e, 1]
    dx = edge_owner[(e + 1) % len(edge_owner), 0] - ax
    dy = edge_owner[(e + 1) % len(edge_owner), 1] - ay
    length = np.sqrt(dx * dx + dy * dy)
    highest = -np.inf
    lowest = np.inf
    for i in range(len(polygon)):
        s = (dx * (polygon[i, 1] - ay) - dy * (polygon[i, 0] - ax)) / length
        highest = max(highest, s)
        lowest = min(lowest, s)
    return highest, lowest


@njit_leaf
def _relation(piece, blocker, eps):
    """0: disjoint (a separating edge line exists), 1: piece inside blocker, 2: they overlap."""
    inside_all = True
    for e in range(len(blocker)):
        highest, lowest = _side_range(piece, blocker, e)
        if highest <= eps:
            return 0
        if lowest < -eps:
            inside_all = False
    if inside_all:
        return 1
    for e in range(len(piece)):
        highest, _ = _side_range(blocker, piece, e)
        if highest <= eps:
            return 0
    return 2


@njit(cache=True)
def _subtract(pieces_xy, pieces_labels, boxes, blocker, blocker_labels, eps):
    """Remove a convex counter-clockwise blocker from every piece, in place; return the piece lists and boxes.

    boxes (C, 4) float64, C >= the number of pieces: the bounding box of each piece (_bounds), grown (a new
    array returned) when the pieces outgrow it. A piece the blocker touches is replaced by its first fragment
    outside the blocker, the others go to the end, and the pieces it covers are removed (the last piece takes
    their place): the work is proportional to the pieces the blocker meets, not to all of them (a wall seen
    behind a furnished room keeps a hundred).
    """
    around = _bounds(blocker)
    removed = np.zeros(len(pieces_xy), dtype=np.bool_)
    any_removed = False
    for index in range(len(removed)):
        # boxes apart by more than eps: a separating line exists, the relation below would be 0
        if (boxes[index, 1] < around[0] - eps or boxes[index, 0] > around[1] + eps
                or boxes[index, 3] < around[2] - eps or boxes[index, 2] > around[3] + eps):  # fmt: skip
            continue
        piece = pieces_xy[index]
        relation = _relation(piece, blocker, eps)
        if relation == 0:
            continue
        removed[index] = True
        any_removed = True
        if relation == 1:
            continue
        remainder = piece
        remainder_labels = pieces_labels[index]
        k = len(blocker)
        for e in range(k):
            f = (e + 1) % k
            in_xy, in_labels, out_xy, out_labels = _split(
                remainder,
                remainder_labels,
                blocker[e, 0],
                blocker[e, 1],
                blocker[f, 0],
                blocker[f, 1],
                blocker_labels[e, 0],
                blocker_labels[e, 1],
                eps,
            )
            if len(out_xy) > 0:
                if removed[index]:
                    pieces_xy[index] = out_xy
                    pieces_labels[index] = out_labels
                    boxes[index] = _bounds(out_xy)
                    removed[index] = False
                else:
                    if len(pieces_xy) == len(boxes):
                        grown = np.empty((2 * len(boxes), 4))
                        grown[: len(boxes)] = boxes
                        boxes = grown
                    boxes[len(pieces_xy)] = _bounds(out_xy)
                    pieces_xy.append(out_xy)
                    pieces_labels.append(out_labels)
            if len(in_xy) == 0:
                break
            remainder = in_xy
            remainder_labels = in_labels
    if any_removed:
        # from the highest index down, so that the last piece moved into a hole is never one still to remove
        for index in range(len(removed) - 1, -1, -1):
            if removed[index]:
                last = len(pieces_xy) - 1
                if index != last:
                    pieces_xy[index] = pieces_xy[last]
                    pieces_labels[index] = pieces_labels[last]
                    boxes[index] = boxes[last]
                pieces_xy.pop()
                pieces_labels.pop()
    return pieces_xy, pieces_labels, boxes


@njit(cache=True)
def _bounds(xy):
    """Bounding box (low x, high x, low y, high y) of a (K, 2) polygon, as a (4,) array."""
    box = np.empty(4)
    box[0] = np.inf
    box[1] = -np.inf
    box[2] = np.inf
    box[3] = -np.inf
    for i in range(len(xy)):
        box[0] = min(box[0], xy[i, 0])
        box[1] = max(box[1], xy[i, 0])
        box[2] = min(box[2], xy[i, 1])
        box[3] = max(box[3], xy[i, 1])
    return box


@njit(cache=True)
def _point_view(
    point, normal, source, allowed, offsets, corners, poly_normals, plane_offsets, areas, solid, hull_group,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, eps, listed, use_listed,
    merge_hulls,
):
    """Visible pieces of `source` from `point`, in the source's 2-D frame.

    Candidate blockers: with use_listed, the polygons of `listed` (K,) int64 (a shaft list of the point's
    polygon and the source, see shaft_blockers); otherwise the BVH's polygons in the pyramid. With merge_hulls,
    the faces of a complete convex solid (hull_group (P,) int64 its object, -1 for other polygons) are removed
    at once as the convex hull of their projections (what the solid hides is convex); the pieces' labels then
    do not name those generators, so only form factors use it.

    Returns (pieces_xy: list of (K, 2), pieces_labels: list of (K, 2) int64 generators, frame (4, 3): origin,
    u, v, (radius, 0, 0)); 2-D coordinates are in units of the radius.
    """
    source_polygon = corners[offsets[source] : offsets[source + 1]]
    frame = _source_frame(source_polygon)
    origin = frame[0]
    u = frame[1]
    v = frame[2]
    radius = frame[3, 0]
    eps2 = eps / radius
    n_source = poly_normals[source]
    height = n_source[0] * point[0] + n_source[1] * point[1] + n_source[2] * point[2] + plane_offsets[source]
    if abs(height) <= eps:
        return _empty_pieces(frame)
    sign = 1.0 if height > 0.0 else -1.0
    height = abs(height)

    labels = _own_edges(source, len(source_polygon))
    plane_n = normal.copy()
    plane_c = -(normal[0] * point[0] + normal[1] * point[1] + normal[2] * point[2])
    visible3, side_labels = _clip3(source_polygon, labels, plane_n, plane_c, HORIZON, 0)
    if len(visible3) < 3:
        return _empty_pieces(frame)

    xy = np.empty((len(visible3), 2))
    for j in range(len(visible3)):
        d0 = visible3[j, 0] - origin[0]
        d1 = visible3[j, 1] - origin[1]
        d2 = visible3[j, 2] - origin[2]
        xy[j, 0] = (d0 * u[0] + d1 * u[1] + d2 * u[2]) / radius
        xy[j, 1] = (d0 * v[0] + d1 * v[1] + d2 * v[2]) / radius
    xy, visible_labels = _orient_ccw(xy, side_labels)
    xy, visible_labels = _cleanup(xy, visible_labels, eps2)
    if len(xy) == 0:
        return _empty_pieces(frame)
    pieces_xy = List()
    pieces_labels = List()
    pieces_xy.append(xy)
    pieces_labels.append(visible_labels)
    boxes = np.empty((16, 4))
    boxes[0] = _bounds(xy)

    # the pyramid (point, visible source): inward side planes, then the source plane itself
    m = len(visible3)
    centre = np.zeros(3)
    for j in range(m):
        centre += visible3[j]
    centre /= m
    side_normals = np.empty((m, 3))
    side_offsets = np.empty(m)
    # the shaft for the BVH, as outward half-spaces n . x + d <= 0: the sides, the source plane, the point's
    shaft = np.empty((m + 2, 4))
    # by component: array expressions here would allocate eight temporaries per side
    for j in range(m):
        k = (j + 1) % m
        a0 = visible3[j, 0] - point[0]
        a1 = visible3[j, 1] - point[1]
        a2 = visible3[j, 2] - point[2]
        b0 = visible3[k, 0] - point[0]
        b1 = visible3[k, 1] - point[1]
        b2 = visible3[k, 2] - point[2]
        w0 = a1 * b2 - a2 * b1
        w1 = a2 * b0 - a0 * b2
        w2 = a0 * b1 - a1 * b0
        length = np.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        if length == 0.0:
            w0 = w1 = w2 = 0.0
        else:
            w0 /= length
            w1 /= length
            w2 /= length
        if w0 * (centre[0] - point[0]) + w1 * (centre[1] - point[1]) + w2 * (centre[2] - point[2]) < 0.0:
            w0 = -w0
            w1 = -w1
            w2 = -w2
        side_normals[j, 0] = w0
        side_normals[j, 1] = w1
        side_normals[j, 2] = w2
        side_offsets[j] = -(w0 * point[0] + w1 * point[1] + w2 * point[2])
        shaft[j, 0] = -w0
        shaft[j, 1] = -w1
        shaft[j, 2] = -w2
        shaft[j, 3] = -side_offsets[j]
    oriented = n_source * sign
    shaft[m, :3] = -oriented
    shaft[m, 3] = -sign * plane_offsets[source]
    shaft[m + 1, :3] = oriented
    shaft[m + 1, 3] = sign * plane_offsets[source] - height

    if use_listed:
        candidates = listed
        found = len(listed)
    else:
        candidates = np.empty(len(order), dtype=np.int64)
        found = bvh_collect_in_planes(
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, shaft, eps, candidates
        )
    # polygons lying on the source (rugs, posters, feet standing on a floor) cut holes that break the view into
    # many pieces: they go after the blockers in front, which leave fewer pieces to cut and may hide them
    lying = np.empty(found, dtype=np.int64)
    n_lying = 0
    hull_xy = np.empty((64, 2))
    hull_of = np.empty(64, dtype=np.int64)
    n_hull = 0
    for index in range(found):
        blocker = candidates[index]
        if blocker == source or not allowed[blocker]:
            continue
        polygon = corners[offsets[blocker] : offsets[blocker + 1]]
        nb = poly_normals[blocker]
        facing = nb[0] * point[0] + nb[1] * point[1] + nb[2] * point[2] + plane_offsets[blocker]
        if abs(facing) <= eps:
            continue
        below = True
        above = True
        on_plane = True
        for j in range(len(polygon)):
            h = sign * (
                n_source[0] * polygon[j, 0]
                + n_source[1] * polygon[j, 1]
                + n_source[2] * polygon[j, 2]
                + plane_offsets[source]
            )
            if h > eps:
                below = False
            if h < height:
                above = False
            if abs(h) > eps:
                on_plane = False
        if on_plane:
            if _covers(blocker, source, areas):
                lying[n_lying] = blocker
                n_lying += 1
            continue
        elif below or above:
            continue
        elif solid[blocker] and facing < 0.0:
            # a solid's faces turned away from the point are behind the faces turned towards it
            continue
        else:
            projected, projected_labels = _project_blocker(
                polygon, blocker, point, n_source * sign, sign * plane_offsets[source], height,
                side_normals, side_offsets, side_labels, origin, u, v, radius, eps2,
            )
        if len(projected) == 0:
            continue
        if merge_hulls and hull_group[blocker] >= 0:
            if n_hull + len(projected) > len(hull_of):
                hull_xy = np.concatenate((hull_xy, np.empty((n_hull + len(projected), 2))))
                hull_of = np.concatenate((hull_of, np.empty(n_hull + len(projected), dtype=np.int64)))
            hull_xy[n_hull : n_hull + len(projected)] = projected
            hull_of[n_hull : n_hull + len(projected)] = hull_group[blocker]
            n_hull += len(projected)
            continue
        pieces_xy, pieces_labels, boxes = _subtract(pieces_xy, pieces_labels, boxes, projected, projected_labels, eps2)
        if len(pieces_xy) == 0:
            return pieces_xy, pieces_labels, frame
    by_object = np.argsort(hull_of[:n_hull], kind="mergesort")
    start = 0
    while start < n_hull:
        stop = start
        while stop < n_hull and hull_of[by_object[stop]] == hull_of[by_object[start]]:
            stop += 1
        hull, hull_labels = _convex_hull(hull_xy[by_object[start:stop]], hull_of[by_object[start]], eps2)
        start = stop
        if len(hull) == 0:
            continue
        pieces_xy, pieces_labels, boxes = _subtract(pieces_xy, pieces_labels, boxes, hull, hull_labels, eps2)
        if len(pieces_xy) == 0:
            return pieces_xy, pieces_labels, frame
    for index in range(n_lying):
        blocker = lying[index]
        polygon = corners[offsets[blocker] : offsets[blocker + 1]]
        projected, projected_labels = _footprint(polygon, blocker, origin, u, v, radius, eps2)
        if len(projected) == 0:
            continue
        pieces_xy, pieces_labels, boxes = _subtract(pieces_xy, pieces_labels, boxes, projected, projected_labels, eps2)
        if len(pieces_xy) == 0:
            break
    return pieces_xy, pieces_labels, frame


@njit(cache=True)
def _convex_hull(xy, group, eps2):
    """The convex hull (K, 2) of points (N, 2), counter-clockwise (Andrew's monotone chain), cleaned (_cleanup),
    its edges labelled (-2 - group, 0): generators that name no polygon."""
    by_y = np.argsort(xy[:, 1], kind="mergesort")
    order = by_y[np.argsort(xy[by_y, 0], kind="mergesort")]  # by x, then y
    points = xy[order]
    count = len(points)
    chain = np.empty((2 * count + 1, 2))
    k = 0
    for i in range(count):  # lower chain, left to right
        while k >= 2 and _turn(chain[k - 2], chain[k - 1], points[i]) <= 0.0:
            k -= 1
        chain[k] = points[i]
        k += 1
    lower = k + 1
    for i in range(count - 2, -1, -1):  # upper chain, right to left
        while k >= lower and _turn(chain[k - 2], chain[k - 1], points[i]) <= 0.0:
            k -= 1
        chain[k] = points[i]
        k += 1
    hull = chain[: max(k - 1, 0)].copy()
    labels = np.empty((len(hull), 2), dtype=np.int64)
    labels[:, 0] = -2 - group
    labels[:, 1] = 0
    return _cleanup(hull, labels, eps2)


@njit_leaf
def _turn(a, b, c):
    return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])


@njit(cache=True)
def _own_edges(polygon, count):
    """Generator labels (count, 2) int64 of a polygon's own edges: (polygon, local edge)."""
    labels = np.empty((count, 2), dtype=np.int64)
    for j in range(count):
        labels[j, 0] = polygon
        labels[j, 1] = j
    return labels


@njit_leaf
def _to_frame(offset, u, v, radius, out):
    """Write the 2-D frame coordinates of a 3-D offset from the frame's origin into out (2,)."""
    out[0] = (offset[0] * u[0] + offset[1] * u[1] + offset[2] * u[2]) / radius
    out[1] = (offset[0] * v[0] + offset[1] * v[1] + offset[2] * v[2]) / radius


@njit_leaf
def _covers(blocker, source, areas):
    """Contact rule for two coplanar polygons that overlap: the smaller one lies on the larger one.

    A rug on a floor, a poster on a wall, a box bottom resting on a floor: the covered part of the larger polygon
    can never be seen, and counting both would see that region twice. Equal areas (duplicated faces): the lower
    index covers, so exactly one of the two is seen.
    """
    return areas[blocker] < areas[source] or (areas[blocker] == areas[source] and blocker < source)


@njit(cache=True)
def _footprint(polygon, blocker, origin, u, v, radius, eps2):
    """A polygon lying in the source's plane, in the source's 2-D frame, counter-clockwise, with generators."""
    xy = np.empty((len(polygon), 2))
    for j in range(len(polygon)):
        _to_frame(polygon[j] - origin, u, v, radius, xy[j])
    labels = _own_edges(blocker, len(polygon))
    xy, labels = _orient_ccw(xy, labels)
    return _cleanup(xy, labels, eps2)


@njit(cache=True)
def _empty_pieces(frame):
    pieces_xy = List()
    pieces_labels = List()
    pieces_xy.append(np.empty((0, 2)))
    pieces_labels.append(np.empty((0, 2), dtype=np.int64))
    pieces_xy.pop()
    pieces_labels.pop()
    return pieces_xy, pieces_labels, frame


@njit(cache=True)
def _orient_ccw(xy, labels):
    area2 = 0.0
    k = len(xy)
    for i in range(k):
        j = (i + 1) % k
        area2 += xy[i, 0] * xy[j, 1] - xy[j, 0] * xy[i, 1]
    if area2 >= 0.0:
        return xy, labels
    # reversed walk: the edge from corner j back to corner j-1 is the old edge j-1
    out = np.empty_like(xy)
    out_labels = np.empty_like(labels)
    for i in range(k):
        j = k - 1 - i
        out[i] = xy[j]
        out_labels[i] = labels[(j - 1) % k]
    return out, out_labels


@njit(cache=True)
def _project_blocker(
    polygon, blocker, point, source_normal, source_offset, height,
    side_normals, side_offsets, side_labels, origin, u, v, radius, eps2,
):
    """Clip a blocker to the pyramid (point, visible source) and project it from the point onto the source.

    source_normal/source_offset are oriented so the point is on the positive side at distance `height`.
    Returns the projection as a counter-clockwise (K, 2) polygon in the source frame with its generators, or
    empty arrays when nothing of the blocker is inside the pyramid.
    """
    # the clips go back and forth between two buffers (each clip at most doubles the corners)
    count = len(polygon)
    clipped = np.empty((2 * count + 2 * len(side_normals) + 2, 3))
    labels = np.empty((len(clipped), 2), dtype=np.int64)
    spare = np.empty_like(clipped)
    spare_labels = np.empty_like(labels)
    for j in range(count):
        for c in range(3):
            clipped[j, c] = polygon[j, c]
        labels[j, 0] = blocker
        labels[j, 1] = j
    for j in range(len(side_normals) + 1):
        if 2 * count > len(spare):
            spare = np.empty((2 * count, 3))
            spare_labels = np.empty((2 * count, 2), dtype=np.int64)
        if j < len(side_normals):
            count = _clip_into(
                clipped, labels, count, side_normals[j], side_offsets[j], side_labels[j, 0], side_labels[j, 1],
                spare, spare_labels,
            )
        else:
            count = _clip_into(
                clipped, labels, count, source_normal, source_offset, blocker, FACE_CROSSING, spare, spare_labels
            )
        if count < 3:
            return np.empty((0, 2)), np.empty((0, 2), dtype=np.int64)
        clipped, spare = spare, clipped
        labels, spare_labels = spare_labels, labels
    xy = np.empty((count, 2))
    # by component: array expressions here would allocate four temporaries per corner
    for j in range(count):
        w0 = clipped[j, 0] - point[0]
        w1 = clipped[j, 1] - point[1]
        w2 = clipped[j, 2] - point[2]
        depth = -(source_normal[0] * w0 + source_normal[1] * w1 + source_normal[2] * w2)
        if depth <= 0.0:
            return np.empty((0, 2)), np.empty((0, 2), dtype=np.int64)
        t = height / depth
        d0 = point[0] + t * w0 - origin[0]
        d1 = point[1] + t * w1 - origin[1]
        d2 = point[2] + t * w2 - origin[2]
        xy[j, 0] = (d0 * u[0] + d1 * u[1] + d2 * u[2]) / radius
        xy[j, 1] = (d0 * v[0] + d1 * v[1] + d2 * v[2]) / radius
    xy, corner_labels = _orient_ccw(xy, labels[:count].copy())
    return _cleanup(xy, corner_labels, eps2)


def _boundary(pieces_xy, pieces_labels, eps):
    """Boundary segments of the union of disjoint pieces: piece edges not shared by two pieces.

    Edges on the same generator line are compared along the line; portions covered once in each direction
    cancel. Returns segments (M, 2, 2) in the 2-D frame and generators (M, 2) int64.
    """
    groups: dict[tuple[int, int], list] = {}
    for xy, labels in zip(pieces_xy, pieces_labels, strict=True):
        for i in range(len(xy)):
            key = (int(labels[i, 0]), int(labels[i, 1]))
            groups.setdefault(key, []).append((xy[i], xy[(i + 1) % len(xy)]))
    segments = []
    generators = []
    for key, edges in groups.items():
        a0, b0 = edges[0]
        direction = b0 - a0
        direction = direction / np.linalg.norm(direction)
        events = []
        for a, b in edges:
            ta = float((a - a0) @ direction)
            tb = float((b - a0) @ direction)
            orientation = 1 if tb > ta else -1
            events.append((min(ta, tb), orientation))
            events.append((max(ta, tb), -orientation))
        events.sort()
        cover = 0
        start = None
        position = 0
        while position < len(events):
            t = events[position][0]
            while position < len(events) and events[position][0] <= t + eps:
                cover += events[position][1]
                position += 1
            if start is not None and (cover != start[1]):
                if t - start[0] > eps and start[1] != 0:
                    p, q = a0 + start[0] * direction, a0 + t * direction
                    segments.append((p, q) if start[1] > 0 else (q, p))
                    generators.append(key)
                start = (t, cover) if cover != 0 else None
            elif start is None and cover != 0:
                start = (t, cover)
    if not segments:
        return np.empty((0, 2, 2)), np.empty((0, 2), dtype=np.int64)
    return np.array(segments), np.array(generators, dtype=np.int64)
