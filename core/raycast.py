"""Ray casting with grazing classification, and jittered Monte-Carlo form factors.

The Visibility Skeleton finds its nodes by casting the candidate extremal stabbing lines through the scene
(Durand et al. 1997, sections 3.2.1-3.2.2): a candidate survives when nothing blocks it, and the faces at
its ends are recorded. Degenerate scenes make many candidates graze the scene, so the occlusion test must
also classify *grazing* contacts (Durand et al. 1999, section 2.2, "a simple modification to the
point-in-polygon test"): touching a silhouette edge or vertex, or sliding in a face's plane, is not
occlusion. This module provides that test for batches of segments and rays, and the Monte-Carlo form factor
the 1999 paper compares exact form factors against (section 4.2.1, Fig. 10: jittered sampling of the source,
kernel and visibility both by Monte-Carlo).

Contact of a segment s + t (e - s), t in the open range, with a polygon of plane n . x + d = 0 (every
threshold is scene.tol.length, a distance):
* both ends within tol of the plane: SLIDING if the segment overlaps the polygon (grown by tol);
* ends strictly on opposite sides (beyond tol): the crossing point is VERTEX when within tol of a corner (or
  of two edge lines), EDGE when within tol of one edge line, INTERIOR when deeper inside, no contact outside;
* otherwise (an end on the plane, or both on one side) no contact: segments may start and end on surfaces.

A segment is *blocked* when it crosses some polygon's interior, or when the contacts it makes at one point
(within tol) with edges and corners close around it: the faces meeting there, projected along the segment,
cover every direction around it, so every parallel segment nearby would cross the surface. This is what makes
a segment through the shared edge of two coplanar quads, or into a box through its edge or corner, blocked,
while a segment grazing a silhouette edge or corner from outside is not.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .bvh import STACK_SIZE, inverse_direction, segment_box_range
from .jit import njit_leaf
from .scene import EDGE_FLAT, VERTEX_SILHOUETTE

CONTACT_NONE = 0
CONTACT_INTERIOR = 1
CONTACT_EDGE = 2
CONTACT_VERTEX = 3
CONTACT_SLIDING = 4

# directions around a segment are measured in quarter turns (see _quarter_turns): a full turn is 4
_TURN = 4.0
_HALF_TURN = 2.0


@dataclass(frozen=True, eq=False)
class SegmentContacts:
    """Every polygon one open segment meets, sorted by t; at one point (within tol) by kind, then polygon id.

    polygon (K,) int64; t (K,) float64 in (0, 1), the point being start + t (end - start) (for SLIDING, where
    the overlap begins); kind (K,) int8 CONTACT_*; feature (K,) int64: the edge id (EDGE), vertex id (VERTEX),
    -1 otherwise; silhouette (K,) bool: the touched edge is not EDGE_FLAT / the touched vertex is
    VERTEX_SILHOUETTE (False for INTERIOR and SLIDING); blocked: what `segments_occluded` answers.
    """

    polygon: np.ndarray
    t: np.ndarray
    kind: np.ndarray
    feature: np.ndarray
    silhouette: np.ndarray
    blocked: bool


@dataclass(frozen=True, eq=False)
class BatchContacts:
    """The contacts of N segments, CSR: segment i owns entries offsets[i]:offsets[i + 1].

    offsets (N+1,) int64; polygon, t, kind, feature, silhouette (K,) as in SegmentContacts; blocked (N,) bool.
    """

    offsets: np.ndarray
    polygon: np.ndarray
    t: np.ndarray
    kind: np.ndarray
    feature: np.ndarray
    silhouette: np.ndarray
    blocked: np.ndarray

    def segment(self, index: int) -> SegmentContacts:
        """The contacts of segment `index`."""
        window = slice(self.offsets[index], self.offsets[index + 1])
        return SegmentContacts(
            polygon=self.polygon[window],
            t=self.t[window],
            kind=self.kind[window],
            feature=self.feature[window],
            silhouette=self.silhouette[window],
            blocked=bool(self.blocked[index]),
        )


# ----------------------------------------------------------------------------------------------------------
# public functions


def segments_occluded(scene, bvh, starts, ends, exclude=None) -> np.ndarray:
    """Whether each open segment is blocked by the scene (see the module docstring).

    starts, ends (N, 3) float64; exclude: None or (N, 2) int64 polygon ids ignored for each segment (-1 none).
    Returns (N,) bool.
    """
    a = _points(starts, "starts")
    b = _points(ends, "ends")
    _same_length(a, b, "starts", "ends")
    skip = _exclusions(exclude, len(a), scene.n_polygons)
    return _occluded_batch(*_geometry(scene), *bvh.arrays, a, b, skip, scene.tol.length, scene.tol.cosine)


def first_hits(scene, bvh, origins, directions, t_max=None):
    """The first polygon each ray origin + t direction meets for t in (0, t_max], of any contact kind.

    origins, directions (N, 3) float64 (directions nonzero, any length; t is in units of each direction);
    t_max: None (past the scene: to its bounding box grown by its diagonal), a float, or (N,) floats > 0.
    Contacts within tol.length of the origin are ignored (origins may lie on surfaces). Ties within tol.length
    go to the lower contact kind (INTERIOR first), then the lower polygon id.
    Returns polygon (N,) int64 (-1 none), t (N,) float64 (inf for none), contact (N,) int8 CONTACT_*.
    """
    o = _points(origins, "origins")
    d = _points(directions, "directions")
    _same_length(o, d, "origins", "directions")
    lengths = np.linalg.norm(d, axis=1)
    if np.any(lengths == 0.0):
        raise ValueError(f"directions[{int(np.flatnonzero(lengths == 0.0)[0])}] is zero")
    if t_max is None:
        # far past the scene, so no crossing inside it sits within tol of the ray's end
        reach = _box_exit(o, d, scene.bbox_min - scene.diagonal, scene.bbox_max + scene.diagonal)
    else:
        try:
            reach = np.array(np.broadcast_to(np.asarray(t_max, dtype=np.float64), (len(o),)), copy=True)
        except (TypeError, ValueError):
            raise ValueError(f"t_max must be None, a number or ({len(o)},) numbers") from None
        if not np.all(reach > 0.0) or not np.isfinite(reach).all():
            raise ValueError("t_max must be finite and > 0")
    polygon, t, contact = _first_hits_batch(*_geometry(scene), *bvh.arrays, o, d, reach, scene.tol.length)
    return polygon, t, contact


def segment_contacts(scene, bvh, start, end) -> SegmentContacts:
    """Every contact of one open segment start-end (3,) float64 with the scene, sorted along it."""
    a = _points(np.reshape(np.asarray(start, dtype=np.float64), (-1,)), "start", single=True)
    b = _points(np.reshape(np.asarray(end, dtype=np.float64), (-1,)), "end", single=True)
    return batch_segment_contacts(scene, bvh, a, b).segment(0)


def batch_segment_contacts(scene, bvh, starts, ends) -> BatchContacts:
    """`segment_contacts` for N segments starts, ends (N, 3) float64, as CSR arrays (BatchContacts)."""
    a = _points(starts, "starts")
    b = _points(ends, "ends")
    _same_length(a, b, "starts", "ends")
    geometry = _geometry(scene)
    offsets, polygon, t, kind, local, blocked = _contacts_batch(
        *geometry, *bvh.arrays, a, b, scene.tol.length, scene.tol.cosine
    )
    corner = scene.polygon_offsets[polygon] + np.maximum(local, 0)
    feature = np.full(len(polygon), -1, dtype=np.int64)
    silhouette = np.zeros(len(polygon), dtype=bool)
    on_edge = kind == CONTACT_EDGE
    on_vertex = kind == CONTACT_VERTEX
    feature[on_edge] = scene.polygon_edge_ids[corner[on_edge]]
    feature[on_vertex] = scene.polygon_vertex_ids[corner[on_vertex]]
    silhouette[on_edge] = scene.edge_kind[feature[on_edge]] != EDGE_FLAT
    silhouette[on_vertex] = scene.vertex_kind[feature[on_vertex]] == VERTEX_SILHOUETTE
    return BatchContacts(offsets, polygon, t, kind, feature, silhouette, blocked)


def jittered_form_factors(scene, bvh, points, normals, source: int, rays: int, seed: int = 0) -> np.ndarray:
    """Monte-Carlo occluded form factors from differential areas to polygon `source` (1999, section 4.2.1).

    points, normals (N, 3) float64 receivers (normals nonzero, normalised here); rays > 0 samples per point,
    one in each of `rays` equal-area strata of the source. The strata come from an area-preserving map of the
    unit square onto the polygon (a fan from its first corner, angle by area, radius by square root), cut
    into near-square cells of area 1 / rays. Estimate: (A / n) sum cos_p |cos_s| / (pi r^2) V, the source
    taken as two-sided like Blender emitters, samples behind the receiver's tangent plane contributing 0 and
    V given by `segments_occluded` with the source excluded. Deterministic for a given seed.
    Returns (N,) float64 >= 0.
    """
    p = _points(points, "points")
    n = _points(normals, "normals")
    _same_length(p, n, "points", "normals")
    lengths = np.linalg.norm(n, axis=1)
    if np.any(lengths == 0.0):
        raise ValueError(f"normals[{int(np.flatnonzero(lengths == 0.0)[0])}] is zero")
    n = n / lengths[:, None]
    if isinstance(source, bool) or not isinstance(source, (int, np.integer)):
        raise ValueError(f"source must be a polygon index, got {source!r}")
    if not 0 <= source < scene.n_polygons:
        raise ValueError(f"source {source} is outside 0..{scene.n_polygons - 1}")
    if isinstance(rays, bool) or not isinstance(rays, (int, np.integer)) or rays < 1:
        raise ValueError(f"rays must be a positive integer, got {rays!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)):
        raise ValueError(f"seed must be an integer, got {seed!r}")
    return _jittered_batch(
        *_geometry(scene),
        *bvh.arrays,
        p,
        n,
        int(source),
        int(rays),
        np.uint64(int(seed) & 0xFFFFFFFFFFFFFFFF),
        float(scene.areas[source]),
        scene.tol.length,
        scene.tol.cosine,
    )


# ----------------------------------------------------------------------------------------------------------
# validation


def _points(values, name: str, single: bool = False) -> np.ndarray:
    array = np.array(values, dtype=np.float64, copy=True)
    if single:
        if array.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {array.shape}")
        array = array.reshape(1, 3)
    elif array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"{name} must have shape (N, 3), got {array.shape}")
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        raise ValueError(f"{name}[{int(np.flatnonzero(~finite)[0])}] is not finite")
    return array


def _same_length(a: np.ndarray, b: np.ndarray, name_a: str, name_b: str) -> None:
    if len(a) != len(b):
        raise ValueError(f"{name_a} ({len(a)}) and {name_b} ({len(b)}) must have the same length")


def _exclusions(exclude, count: int, n_polygons: int) -> np.ndarray:
    if exclude is None:
        return np.full((count, 2), -1, dtype=np.int64)
    array = np.array(exclude, copy=True)
    if array.shape != (count, 2) or (array.size and not np.issubdtype(array.dtype, np.integer)):
        raise ValueError(f"exclude must be a ({count}, 2) integer array, got {array.shape} {array.dtype}")
    array = array.astype(np.int64)
    if np.any((array < -1) | (array >= n_polygons)):
        raise ValueError(f"exclude holds a polygon id outside -1..{n_polygons - 1}")
    return array


def _geometry(scene) -> tuple:
    """The scene arrays every kernel takes first: corners, CSR offsets, normals, plane offsets."""
    return scene.polygon_points, scene.polygon_offsets, scene.normals, scene.plane_offsets


def _box_exit(origins: np.ndarray, directions: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Ray parameter where each ray leaves the box lo-hi (1 for rays that never meet it going forward)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        a = (lo[None, :] - origins) / directions
        b = (hi[None, :] - origins) / directions
    far = np.where(directions == 0.0, np.inf, np.maximum(a, b))
    exit_t = far.min(axis=1)
    # a ray leaving (or outside) the box reaches no polygon: any positive parameter will do
    return np.where(np.isfinite(exit_t) & (exit_t > 0.0), exit_t, 1.0)


# ----------------------------------------------------------------------------------------------------------
# kernels: one polygon


@njit_leaf
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True)
def _edge_normal(points, a, b, normal):
    """Unit vector in the polygon's plane, perpendicular to edge points[a]-points[b] and pointing out of the
    polygon. Points are read by component: a row view would cost two atomic reference counts."""
    ex = points[b, 0] - points[a, 0]
    ey = points[b, 1] - points[a, 1]
    ez = points[b, 2] - points[a, 2]
    mx = ey * normal[2] - ez * normal[1]
    my = ez * normal[0] - ex * normal[2]
    mz = ex * normal[1] - ey * normal[0]
    norm = np.sqrt(mx * mx + my * my + mz * mz)
    return mx / norm, my / norm, mz / norm


@njit_leaf
def _classify_point(points, first, count, normal, px, py, pz, tol):
    """Where a point of the polygon's plane lies: (CONTACT_* or CONTACT_NONE, local feature index).

    The point-in-polygon test of the skeleton's ray caster with the grazing cases of 1999 section 2.2:
    within tol of a corner -> VERTEX k; within tol of one edge line k (k -> k+1) -> EDGE k; within tol of
    two edge lines (a sharp corner) -> VERTEX at the nearest corner; inside beyond tol -> INTERIOR.
    """
    tol2 = tol * tol
    for k in range(count):
        dx = px - points[first + k, 0]
        dy = py - points[first + k, 1]
        dz = pz - points[first + k, 2]
        if dx * dx + dy * dy + dz * dz <= tol2:
            return CONTACT_VERTEX, k
    near = 0
    near_edge = -1
    for k in range(count):
        a = first + k
        mx, my, mz = _edge_normal(points, a, first + (k + 1) % count, normal)
        distance = (px - points[a, 0]) * mx + (py - points[a, 1]) * my + (pz - points[a, 2]) * mz
        if distance > tol:
            return CONTACT_NONE, -1
        if distance >= -tol:
            near += 1
            near_edge = k
    if near == 0:
        return CONTACT_INTERIOR, -1
    if near == 1:
        return CONTACT_EDGE, near_edge
    nearest = 0
    best = np.inf
    for k in range(count):
        dx = px - points[first + k, 0]
        dy = py - points[first + k, 1]
        dz = pz - points[first + k, 2]
        distance2 = dx * dx + dy * dy + dz * dz
        if distance2 < best:
            best = distance2
            nearest = k
    return CONTACT_VERTEX, nearest


@njit_leaf
def _polygon_contact(points, offsets, normals, plane_offsets, polygon, start, end, tol):
    """Contact of the open segment start-end with one polygon: (CONTACT_*, t, local feature index or -1)."""
    normal = (normals[polygon, 0], normals[polygon, 1], normals[polygon, 2])
    d_start = _dot(normal, start) + plane_offsets[polygon]
    d_end = _dot(normal, end) + plane_offsets[polygon]
    first = offsets[polygon]
    count = offsets[polygon + 1] - first
    if abs(d_start) <= tol and abs(d_end) <= tol:
        return _sliding_contact(points, first, count, normal, start, end, tol)
    if not ((d_start > tol and d_end < -tol) or (d_start < -tol and d_end > tol)):
        return CONTACT_NONE, 0.0, -1
    t = d_start / (d_start - d_end)
    px = start[0] + t * (end[0] - start[0])
    py = start[1] + t * (end[1] - start[1])
    pz = start[2] + t * (end[2] - start[2])
    kind, local = _classify_point(points, first, count, normal, px, py, pz, tol)
    return kind, t, local


@njit_leaf
def _sliding_contact(points, first, count, normal, start, end, tol):
    """A segment lying in the polygon's plane: SLIDING when it overlaps the polygon grown by tol.

    t is where it enters the polygon itself (not the grown one, so that contacts at one point agree on t),
    or, when it only grazes the polygon within tol, the nearest point of the grown overlap.
    """
    dx = end[0] - start[0]
    dy = end[1] - start[1]
    dz = end[2] - start[2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= 2.0 * tol:
        return CONTACT_NONE, 0.0, -1
    lo = tol / length
    hi = 1.0 - lo
    entry = lo
    for k in range(count):
        a = first + k
        mx, my, mz = _edge_normal(points, a, first + (k + 1) % count, normal)
        offset = (start[0] - points[a, 0]) * mx + (start[1] - points[a, 1]) * my + (start[2] - points[a, 2]) * mz
        rate = dx * mx + dy * my + dz * mz
        if rate == 0.0:
            if offset > tol:
                return CONTACT_NONE, 0.0, -1
        elif rate > 0.0:
            hi = min(hi, (tol - offset) / rate)
        else:
            lo = max(lo, (tol - offset) / rate)
            entry = max(entry, -offset / rate)
        if lo > hi:
            return CONTACT_NONE, 0.0, -1
    return CONTACT_SLIDING, min(max(entry, lo), hi), -1


# ----------------------------------------------------------------------------------------------------------
# kernels: blocking by contacts that close around the segment


@njit(cache=True)
def _wrap_angle(angle):
    while angle < 0.0:
        angle += _TURN
    while angle >= _TURN:
        angle -= _TURN
    return angle


@njit_leaf
def _quarter_turns(y, x):
    """The direction of (x, y) as a number in [0, 4) that grows with its angle from +x, a quarter turn per unit
    and the opposite direction 2 apart (the "diamond angle"); 0 for (0, 0). It orders directions as the angle
    does, at the cost of a division, against arc tangents that took 3 % of a build; its gaps are between half
    and all of the angle's."""
    if y >= 0.0:
        if x >= 0.0:
            return 0.0 if x + y == 0.0 else y / (x + y)
        return 1.0 - x / (y - x)
    if x < 0.0:
        return 2.0 - y / (-x - y)
    # a direction just below +x rounds to a full turn: it is +x
    turns = 3.0 + x / (x - y)
    return turns if turns < _TURN else 0.0


@njit_leaf
def _contact_arc(points, offsets, normals, polygon, kind, local, e1, e2):
    """The directions around the segment (start, length, in quarter turns: _quarter_turns) in which the face
    extends from the contact.

    Projected along the segment onto the plane (e1, e2), a face touched along edge k is a half-plane and a
    face touched at corner k is the convex sector between its two edges. Points are read by component: a
    row view of the arrays would cost two atomic reference counts, a difference a heap allocation.
    """
    first = offsets[polygon]
    count = offsets[polygon + 1] - first
    corner = first + local
    if kind == CONTACT_EDGE:
        following = first + (local + 1) % count
        ex = points[following, 0] - points[corner, 0]
        ey = points[following, 1] - points[corner, 1]
        ez = points[following, 2] - points[corner, 2]
        # inward direction of the face, across the edge
        wx = normals[polygon, 1] * ez - normals[polygon, 2] * ey
        wy = normals[polygon, 2] * ex - normals[polygon, 0] * ez
        wz = normals[polygon, 0] * ey - normals[polygon, 1] * ex
        cu = ex * e1[0] + ey * e1[1] + ez * e1[2]
        cv = ex * e2[0] + ey * e2[1] + ez * e2[2]
        wu = wx * e1[0] + wy * e1[1] + wz * e1[2]
        wv = wx * e2[0] + wy * e2[1] + wz * e2[2]
        if cu * wv - cv * wu < 0.0:
            cu = -cu
            cv = -cv
        return _quarter_turns(cv, cu), _HALF_TURN
    previous = first + (local - 1) % count
    following = first + (local + 1) % count
    alpha = _quarter_turns(_corner_dot(points, previous, corner, e2), _corner_dot(points, previous, corner, e1))
    beta = _quarter_turns(_corner_dot(points, following, corner, e2), _corner_dot(points, following, corner, e1))
    sweep = _wrap_angle(beta - alpha)
    if sweep <= _HALF_TURN:
        return alpha, sweep
    return beta, _TURN - sweep


@njit(cache=True)
def _corner_dot(points, tip, corner, axis):
    """Dot product of points[tip] - points[corner] with the 3-vector axis."""
    return (
        (points[tip, 0] - points[corner, 0]) * axis[0]
        + (points[tip, 1] - points[corner, 1]) * axis[1]
        + (points[tip, 2] - points[corner, 2]) * axis[2]
    )


@njit(cache=True)
def _arcs_cover_circle(arc_start, arc_length, count, angle_tol):
    """Whether the union of `count` arcs covers the whole circle (gaps up to angle_tol are closed)."""
    return _arcs_cover_circle_with(arc_start, arc_length, count, angle_tol, np.empty(2 * count))


@njit_leaf
def _arcs_cover_circle_with(arc_start, arc_length, count, angle_tol, bounds):
    """_arcs_cover_circle with a scratch array bounds (at least 2 count,) float64 for the arcs' ends."""
    total = 0.0
    for i in range(count):
        total += arc_length[i]
    if total < _TURN - angle_tol:
        return False
    for i in range(count):
        bounds[2 * i] = arc_start[i]
        bounds[2 * i + 1] = _wrap_angle(arc_start[i] + arc_length[i])
    # insertion sort (a few ends, no work array), NaN last as in np.sort
    for i in range(1, 2 * count):
        value = bounds[i]
        j = i
        while j > 0 and (value < bounds[j - 1] or (np.isnan(bounds[j - 1]) and not np.isnan(value))):
            bounds[j] = bounds[j - 1]
            j -= 1
        bounds[j] = value
    for i in range(2 * count):
        lo = bounds[i]
        hi = bounds[i + 1] if i + 1 < 2 * count else bounds[0] + _TURN
        if hi - lo <= angle_tol:
            continue
        middle = _wrap_angle(0.5 * (lo + hi))
        covered = False
        for j in range(count):
            if _wrap_angle(middle - arc_start[j]) < arc_length[j]:
                covered = True
                break
        if not covered:
            return False
    return True


@njit_leaf
def _perpendicular_frame(direction):
    """Two unit 3-vectors (tuples) spanning the plane perpendicular to a nonzero direction (3,)."""
    length = np.sqrt(_dot(direction, direction))
    dx = direction[0] / length
    dy = direction[1] / length
    dz = direction[2] / length
    ax = abs(dx)
    ay = abs(dy)
    az = abs(dz)
    # the axis least aligned with the direction
    hx = 0.0
    hy = 0.0
    hz = 0.0
    if ax <= ay and ax <= az:
        hx = 1.0
    elif ay <= az:
        hy = 1.0
    else:
        hz = 1.0
    cx = hy * dz - hz * dy
    cy = hz * dx - hx * dz
    cz = hx * dy - hy * dx
    norm = np.sqrt(cx * cx + cy * cy + cz * cz)
    e1 = (cx / norm, cy / norm, cz / norm)
    e2 = (dy * e1[2] - dz * e1[1], dz * e1[0] - dx * e1[2], dx * e1[1] - dy * e1[0])
    return e1, e2


@njit(cache=True)
def _boundary_contacts_block(points, offsets, normals, start, end, polygon, t, kind, local, count, tol, angle_tol):
    """Whether edge/corner contacts at one point close around the segment; contacts sorted by t.

    Contacts of other kinds in the arrays are skipped; contacts within tol (along the segment) form a group.
    """
    direction = end - start
    length = np.sqrt(_dot(direction, direction))
    same_point = tol / length
    e1, e2 = _perpendicular_frame(direction)
    arc_start = np.empty(count)
    arc_length = np.empty(count)
    i = 0
    while i < count:
        if kind[i] != CONTACT_EDGE and kind[i] != CONTACT_VERTEX:
            i += 1
            continue
        members = 0
        previous_t = t[i]
        j = i
        while j < count and t[j] - previous_t <= same_point:
            if kind[j] == CONTACT_EDGE or kind[j] == CONTACT_VERTEX:
                arc_start[members], arc_length[members] = _contact_arc(
                    points, offsets, normals, polygon[j], kind[j], local[j], e1, e2
                )
                members += 1
                previous_t = t[j]
            j += 1
        if members >= 2 and _arcs_cover_circle(arc_start, arc_length, members, angle_tol):
            return True
        i = j
    return False


# ----------------------------------------------------------------------------------------------------------
# kernels: one segment against the BVH


@njit_leaf
def _gather_contacts(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    start, end, skip_a, skip_b, tol, stop_at_interior, boundary_only,
    out_polygon, out_t, out_kind, out_local, stack,
):  # fmt: skip
    """Contacts of the open segment with every polygon but skip_a, skip_b, in traversal order.

    Writes at most len(out_polygon) contacts and returns how many there are; with stop_at_interior it
    returns -1 at the first INTERIOR contact; with boundary_only it keeps only EDGE and VERTEX contacts.
    """
    direction = (end[0] - start[0], end[1] - start[1], end[2] - start[2])
    inv = inverse_direction(direction)
    capacity = out_polygon.shape[0]
    found = 0
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        entry, leave = segment_box_range(start, inv, direction, node_min[node], node_max[node], 0.0, 1.0)
        if entry > leave:
            continue
        child = node_child[node]
        if child >= 0:
            stack[top] = child
            stack[top + 1] = child + 1
            top += 2
            continue
        first = node_first[node]
        for i in range(first, first + node_count[node]):
            polygon = order[i]
            if polygon == skip_a or polygon == skip_b:
                continue
            entry, leave = segment_box_range(start, inv, direction, box_min[polygon], box_max[polygon], 0.0, 1.0)
            if entry > leave:
                continue
            kind, t, local = _polygon_contact(points, offsets, normals, plane_offsets, polygon, start, end, tol)
            if kind == CONTACT_NONE:
                continue
            if kind == CONTACT_INTERIOR and stop_at_interior:
                return -1
            if boundary_only and kind != CONTACT_EDGE and kind != CONTACT_VERTEX:
                continue
            if found < capacity:
                out_polygon[found] = polygon
                out_t[found] = t
                out_kind[found] = kind
                out_local[found] = local
            found += 1
    return found


@njit_leaf
def _sort_contacts(polygon, t, kind, local, count, same_point):
    """Sort the first `count` contacts in place by t; contacts at one point (t chained within same_point)
    by kind, then polygon, so that rounding in t never decides their order. Insertion sorts: counts are small.
    """
    for i in range(1, count):
        j = i
        while j > 0 and t[j - 1] > t[j]:
            _swap_contacts(polygon, t, kind, local, j - 1, j)
            j -= 1
    group = 0
    while group < count:
        end = group + 1
        while end < count and t[end] - t[end - 1] <= same_point:
            end += 1
        for i in range(group + 1, end):
            j = i
            while j > group and (kind[j - 1] > kind[j] or (kind[j - 1] == kind[j] and polygon[j - 1] > polygon[j])):
                _swap_contacts(polygon, t, kind, local, j - 1, j)
                j -= 1
        group = end


@njit_leaf
def _swap_contacts(polygon, t, kind, local, i, j):
    polygon[i], polygon[j] = polygon[j], polygon[i]
    t[i], t[j] = t[j], t[i]
    kind[i], kind[j] = kind[j], kind[i]
    local[i], local[j] = local[j], local[i]


@njit_leaf
def segment_blocked(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    start, end, skip_a, skip_b, tol, angle_tol,
):  # fmt: skip
    """Numba-callable occlusion test of one open segment; the kernel of `segments_occluded`.

    points (N, 3), offsets (P+1,), normals (P, 3), plane_offsets (P,): scene.polygon_points,
    scene.polygon_offsets, scene.normals, scene.plane_offsets; then the eight arrays of `BVH.arrays`;
    start, end (3,) float64; skip_a, skip_b: polygon ids to ignore (-1 none); tol = scene.tol.length,
    angle_tol = scene.tol.cosine. Returns True when the segment is blocked. Loops over many segments should
    call `_segment_blocked_with` with one `_workspace()` instead, to allocate once.
    """
    stack, none_i, none_f, none_k = _workspace()
    return _segment_blocked_with(
        points, offsets, normals, plane_offsets,
        node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
        start, end, skip_a, skip_b, tol, angle_tol, stack, none_i, none_f, none_k,
    )  # fmt: skip


@njit(cache=True)
def _workspace():
    """A traversal stack and the empty buffers of a counting pass, reusable for any number of segments."""
    return (
        np.empty(STACK_SIZE, dtype=np.int64),
        np.empty(0, dtype=np.int64),
        np.empty(0),
        np.empty(0, dtype=np.int8),
    )


@njit(cache=True)
def _segment_blocked_with(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    start, end, skip_a, skip_b, tol, angle_tol, stack, none_i, none_f, none_k,
):  # fmt: skip
    found = _gather_contacts(
        points, offsets, normals, plane_offsets,
        node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
        start, end, skip_a, skip_b, tol, True, True, none_i, none_f, none_k, none_i, stack,
    )  # fmt: skip
    if found < 0:
        return True
    if found < 2:
        return False
    # rare: the segment touches edges or corners; look at them again, now storing them
    polygon = np.empty(found, dtype=np.int64)
    t = np.empty(found)
    kind = np.empty(found, dtype=np.int8)
    local = np.empty(found, dtype=np.int64)
    _gather_contacts(
        points, offsets, normals, plane_offsets,
        node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
        start, end, skip_a, skip_b, tol, False, True, polygon, t, kind, local, stack,
    )  # fmt: skip
    direction = end - start
    _sort_contacts(polygon, t, kind, local, found, tol / np.sqrt(_dot(direction, direction)))
    return _boundary_contacts_block(
        points, offsets, normals, start, end, polygon, t, kind, local, found, tol, angle_tol
    )


# ----------------------------------------------------------------------------------------------------------
# kernels: batches


@njit(cache=True)
def _occluded_batch(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    starts, ends, skip, tol, angle_tol,
):  # fmt: skip
    result = np.zeros(starts.shape[0], dtype=np.bool_)
    stack, none_i, none_f, none_k = _workspace()
    for i in range(starts.shape[0]):
        result[i] = _segment_blocked_with(
            points, offsets, normals, plane_offsets,
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
            starts[i], ends[i], skip[i, 0], skip[i, 1], tol, angle_tol, stack, none_i, none_f, none_k,
        )  # fmt: skip
    return result


@njit(cache=True)
def _contacts_batch(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    starts, ends, tol, angle_tol,
):  # fmt: skip
    n = starts.shape[0]
    stack, none_i, none_f, none_k = _workspace()
    csr = np.zeros(n + 1, dtype=np.int64)
    for i in range(n):
        found = _gather_contacts(
            points, offsets, normals, plane_offsets,
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
            starts[i], ends[i], -1, -1, tol, False, False, none_i, none_f, none_k, none_i, stack,
        )  # fmt: skip
        csr[i + 1] = csr[i] + found
    total = csr[n]
    polygon = np.empty(total, dtype=np.int64)
    t = np.empty(total)
    kind = np.empty(total, dtype=np.int8)
    local = np.empty(total, dtype=np.int64)
    blocked = np.zeros(n, dtype=np.bool_)
    for i in range(n):
        lo = csr[i]
        hi = csr[i + 1]
        _gather_contacts(
            points, offsets, normals, plane_offsets,
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
            starts[i], ends[i], -1, -1, tol, False, False,
            polygon[lo:hi], t[lo:hi], kind[lo:hi], local[lo:hi], stack,
        )  # fmt: skip
        segment = ends[i] - starts[i]
        same_point = tol / np.sqrt(_dot(segment, segment))
        _sort_contacts(polygon[lo:hi], t[lo:hi], kind[lo:hi], local[lo:hi], hi - lo, same_point)
        for j in range(lo, hi):
            if kind[j] == CONTACT_INTERIOR:
                blocked[i] = True
        if not blocked[i] and hi - lo >= 2:
            blocked[i] = _boundary_contacts_block(
                points, offsets, normals, starts[i], ends[i],
                polygon[lo:hi], t[lo:hi], kind[lo:hi], local[lo:hi], hi - lo, tol, angle_tol,
            )  # fmt: skip
    return csr, polygon, t, kind, local, blocked


@njit(cache=True, nogil=True)
def _first_hits_batch(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    origins, directions, reach, tol,
):  # fmt: skip
    n = origins.shape[0]
    hit_polygon = np.full(n, -1, dtype=np.int64)
    hit_t = np.full(n, np.inf)
    hit_kind = np.zeros(n, dtype=np.int8)
    stack = np.empty(STACK_SIZE, dtype=np.int64)
    end = np.empty(3)
    for r in range(n):
        start = origins[r]
        for k in range(3):
            end[k] = start[k] + reach[r] * directions[r, k]
        segment = end - start
        inv = inverse_direction(segment)
        length = np.sqrt(_dot(segment, segment))
        same_point = tol / length
        best_t = np.inf
        best_kind = CONTACT_NONE
        best_polygon = -1
        stack[0] = 0
        top = 1
        while top > 0:
            top -= 1
            node = stack[top]
            limit = min(1.0, best_t + same_point)
            entry, leave = segment_box_range(start, inv, segment, node_min[node], node_max[node], 0.0, limit)
            if entry > leave:
                continue
            child = node_child[node]
            if child >= 0:
                near_entry, near_leave = segment_box_range(
                    start, inv, segment, node_min[child], node_max[child], 0.0, limit
                )
                far_entry, far_leave = segment_box_range(
                    start, inv, segment, node_min[child + 1], node_max[child + 1], 0.0, limit
                )
                # visit the nearer child first: it tightens best_t before the other is opened
                if near_entry <= far_entry:
                    stack[top] = child + 1
                    stack[top + 1] = child
                else:
                    stack[top] = child
                    stack[top + 1] = child + 1
                top += 2
                continue
            first = node_first[node]
            for i in range(first, first + node_count[node]):
                polygon = order[i]
                entry, leave = segment_box_range(start, inv, segment, box_min[polygon], box_max[polygon], 0.0, limit)
                if entry > leave:
                    continue
                kind, t, local = _polygon_contact(points, offsets, normals, plane_offsets, polygon, start, end, tol)
                if kind == CONTACT_NONE:
                    continue
                if t < best_t - same_point:
                    better = True
                elif t <= best_t + same_point:
                    better = kind < best_kind or (kind == best_kind and polygon < best_polygon)
                else:
                    better = False
                if better:
                    best_t = t
                    best_kind = kind
                    best_polygon = polygon
        if best_polygon >= 0:
            hit_polygon[r] = best_polygon
            hit_t[r] = best_t * reach[r]
            hit_kind[r] = best_kind
    return hit_polygon, hit_t, hit_kind


# ----------------------------------------------------------------------------------------------------------
# kernels: jittered form factors


@njit(cache=True)
def _mix(value):
    """SplitMix64 finaliser: a well-spread uint64 hash of a uint64."""
    value = value + np.uint64(0x9E3779B97F4A7C15)
    value = (value ^ (value >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    value = (value ^ (value >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return value ^ (value >> np.uint64(31))


@njit(cache=True)
def _uniform(seed, point, sample, axis):
    """A uniform float64 in [0, 1) that depends only on (seed, point, sample, axis)."""
    h = _mix(seed)
    h = _mix(h ^ np.uint64(point))
    h = _mix(h ^ np.uint64(2 * sample + axis))
    return np.float64(h >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _stratum(index, rays, columns):
    """Cell `index` of the unit square cut into `rays` cells of equal area: (u0, v0, du, dv).

    `columns` vertical strips; strip j holds rays // columns cells, one more for the first rays % columns
    strips, and is as wide as its share of cells, so every cell has area 1 / rays.
    """
    base = rays // columns
    extra = rays % columns
    column = 0
    first_cell = 0
    while True:
        cells = base + (1 if column < extra else 0)
        if index < first_cell + cells:
            break
        first_cell += cells
        column += 1
    u0 = 0.0
    for j in range(column):
        u0 += (base + (1 if j < extra else 0)) / rays
    du = cells / rays
    dv = 1.0 / cells
    return u0, (index - first_cell) * dv, du, dv


@njit(cache=True)
def _jittered_batch(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    receivers, receiver_normals, source, rays, seed, area, tol, angle_tol,
):  # fmt: skip
    first = offsets[source]
    corners = offsets[source + 1] - first
    apex = points[first]
    # fan triangles (apex, k, k+1): cumulative area fractions select a triangle by the angular coordinate
    cumulative = np.zeros(corners - 1)
    for k in range(1, corners - 1):
        a = points[first + k] - apex
        b = points[first + k + 1] - apex
        cx = a[1] * b[2] - a[2] * b[1]
        cy = a[2] * b[0] - a[0] * b[2]
        cz = a[0] * b[1] - a[1] * b[0]
        cumulative[k] = cumulative[k - 1] + np.sqrt(cx * cx + cy * cy + cz * cz)
    total = cumulative[corners - 2]
    for k in range(1, corners - 1):
        cumulative[k] /= total
    columns = max(1, int(np.sqrt(rays) + 0.5))
    source_normal = normals[source]
    weight = area / (rays * np.pi)
    tol2 = tol * tol
    sample = np.empty(3)
    stack, none_i, none_f, none_k = _workspace()
    result = np.zeros(receivers.shape[0])
    for i in range(receivers.shape[0]):
        p = receivers[i]
        n = receiver_normals[i]
        accumulated = 0.0
        for s in range(rays):
            u0, v0, du, dv = _stratum(s, rays, columns)
            angular = u0 + du * _uniform(seed, i, s, 0)
            radial = np.sqrt(v0 + dv * _uniform(seed, i, s, 1))
            triangle = 1
            while triangle < corners - 2 and angular >= cumulative[triangle]:
                triangle += 1
            lo = cumulative[triangle - 1]
            span = cumulative[triangle] - lo
            along = min(max((angular - lo) / span, 0.0), 1.0) if span > 0.0 else 0.0
            b = points[first + triangle]
            c = points[first + triangle + 1]
            for k in range(3):
                sample[k] = apex[k] + radial * ((1.0 - along) * (b[k] - apex[k]) + along * (c[k] - apex[k]))
            rx = sample[0] - p[0]
            ry = sample[1] - p[1]
            rz = sample[2] - p[2]
            r2 = rx * rx + ry * ry + rz * rz
            if r2 <= tol2:
                continue
            cos_p = (n[0] * rx + n[1] * ry + n[2] * rz) / np.sqrt(r2)
            if cos_p <= 0.0:
                continue
            cos_s = abs(source_normal[0] * rx + source_normal[1] * ry + source_normal[2] * rz) / np.sqrt(r2)
            kernel = cos_p * cos_s / r2
            if kernel <= 0.0:
                continue
            if _segment_blocked_with(
                points, offsets, normals, plane_offsets,
                node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
                p, sample, source, -1, tol, angle_tol, stack, none_i, none_f, none_k,
            ):  # fmt: skip
                continue
            accumulated += kernel
        result[i] = accumulated * weight
    return result
