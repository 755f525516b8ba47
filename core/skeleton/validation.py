"""Node validation and arc derivation: ray cast each candidate line, keep the extremal stabbing lines, and
derive every adjacent arc (critical line swath) with its generators, end faces and orientation.

Durand et al. 1997, sections 3.2-3.3 and appendix 7.2. A candidate line is cast through the whole scene; it
is a node when its generators are touched in one free segment of the line (the inner ones tangent, the
outer ones tangent or terminal: a line may stop on a vertex or edge, as a line leaving a floor corner does).

The paper deduces a node's arcs from a catalogue, with a table of start/end criteria per node type (its
Table 2). Here the same information comes from one first-order computation valid for every node type:
relaxing one generator constraint leaves a one-parameter family of lines; its tangent at the node is an
affine displacement field Delta(tau) = alpha + tau beta perpendicular to the line (tau: position along it),
fixed by the retained constraints (Delta = 0 at a kept vertex, Delta parallel to a kept edge at its contact)
and a normalisation (the contact slides one unit along the arc's parameter edge). For each direction of that
motion the contacts along the line are classified to first order: a face is hit when the displaced line
crosses its plane inside it; a retained generator stays tangent or becomes terminal according to the faces
around it seen along the tilted direction. This yields the arc's validity (nothing hit between its
generators), its end faces (the first face crossed beyond each outer generator) and whether the node starts
or ends it along its parameter edge — exactly the catalogue adjacencies and the start/end criteria.

Arcs are keyed by their generators in line order and their two end faces (face groups, see
`core.skeleton.topology`); END_TERMINAL marks an outer generator the lines stop on, END_FREE lines that leave
the scene, END_PLANAR both ends of lines lying in a face's plane.
"""

from __future__ import annotations

import os
from collections import namedtuple
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..bvh import STACK_SIZE
from ..jit import by_reference, dereferenced, njit_leaf
from ..raycast import (
    _TURN,
    CONTACT_EDGE,
    CONTACT_INTERIOR,
    CONTACT_SLIDING,
    CONTACT_VERTEX,
    _arcs_cover_circle_with,
    _contact_arc,
    _gather_contacts,
    _perpendicular_frame,
    _polygon_contact,
    _sort_contacts,
)

NODE_VV = 0
NODE_VEE = 1
NODE_EVE = 2
NODE_E4 = 3
NODE_FEE = 4
NODE_EFE = 5
NODE_FXE = 6
NODE_NAMES = {
    NODE_VV: "VV", NODE_VEE: "VEE", NODE_EVE: "EVE", NODE_E4: "E4", NODE_FEE: "FEE", NODE_EFE: "EFE", NODE_FXE: "FXE"
}
"""FEE / EFE (seed 003, appendix 7.1): a line in a face's plane crossing the face, through two other edges; its
generators are those two edges and the two edges of the face it crosses, the face beyond both other edges
(FEE) or between them (EFE). Its arcs are the EEE swaths grazing either crossed edge of the face (relaxing the
other one); the swaths keeping both are the face's FE pencils, not stored (see _coplanar_swath).

FXE: seed 003's FvE node (appendix 7.1, Fig. 18) with the crossing point X of two edges standing for the
vertex: a line in the plane of two edges crossing at X (objects in contact), through X and a third edge. Its
arc is the EEE swath of the lines through X meeting the third edge (the paper's ve arc); the lines through
the third edge's crossing point in that plane form a pencil (fv), not stored."""

ARC_EV = 0
ARC_EEE = 1
ARC_NAMES = {ARC_EV: "EV", ARC_EEE: "EEE"}

GEN_NONE = 0
GEN_VERTEX = 1
GEN_EDGE = 2

END_TERMINAL = -1
END_FREE = -2
END_PLANAR = -3
"""Both ends of an arc whose lines all lie in one face's plane (a box resting on the floor, seen along the
floor): such lines graze every face they touch, so where they end is a matter of rounding; one key for them
all lets the nodes along the arc pair up (simplest configuration, seed 000 section 2.2)."""

REJECT_MISSING = 0
REJECT_COINCIDENT = 1
REJECT_BLOCKED = 2
REJECT_NAMES = ("missing generator", "coincident generators", "blocked")

N_COUNTERS = 3

WORKERS = max(1, min(2, os.cpu_count() or 1))
"""Threads validating one chunk of candidates (the machines this is tuned for have two cores)."""

_MIN_SLICE = 2_000
"""Fewest candidates worth a thread of their own."""

_SLICES_PER_WORKER = 4
"""Slices of a chunk per thread: slices of equal counts take unequal times (a vertex pair's line has more arcs
than an edge quadruple's), and a thread done early takes the next slice instead of waiting."""

_CONTACT_LENGTHS = 1e3
"""A line meeting two touching faces over fewer tolerance lengths than this only passes a corner of their
contact (the tolerant overlap of a line with a polygon it touches at a corner is a few tolerance lengths
over the sine of the angles there); a line through the contact itself runs along it over a scene length."""

_TILT = 1e-6
"""Angle (radians) by which a line is tilted to read the tangent/terminal state of its generators just off a
node; far above tol.cosine and far below any angle between two faces of a sane scene."""

_SIDE_EPS = 1e-9
"""Relative margin of the first-order side tests; ambiguous cases count as hits (never a false free line)."""


_Geometry = namedtuple(
    "_Geometry",
    "points offsets normals areas vertices edges edge_unit vf_off vf_face vf_corner ef_off ef_face ef_local "
    "corner_edge face_group object_ids element_solid face_region split_edge diag tol angle_tol",
)
"""The read-only scene the kernels share (a numba named tuple): polygon points (P, 3) float64 and offsets (F + 1,)
int64, normals (F, 3) and areas (F,) float64; vertices (V, 3) float64, edges (E, 2) int64 and edge_unit (E, 3)
float64 their unit directions (_edge_units); the faces around each vertex (vf_off (V + 1,), vf_face and vf_corner,
int64) and each edge (ef_off (E + 1,), ef_face and ef_local, int64); corner_edge (P,) int64 the edge from each
polygon corner to the next; face_group and object_ids (F,) int64; element_solid (V + E,) int64 the closed convex
object all faces of each vertex, then each edge, belong to (-1: none, see element_solids); face_region (F,) int64
each face's flat region (see flat_regions) and split_edge (E,) bool whether a face of the edge shares its region with
another (_flush_faces); the scene's diagonal, tol.length and tol.cosine (floats)."""

_Line = namedtuple(
    "_Line", "c_poly c_kind c_local g_lo g_hi g_tau n_groups sl_poly sl_a sl_b n_sliding start u f1 f2"
)
"""One cast candidate line start + tau u, tau in [0, length] (start, u and the unit frame f1, f2 perpendicular
to u: 3-tuples): its point contacts sorted along it (c_poly int64, c_kind int8, c_local int64), in n_groups
groups of one point (contacts g_lo[g]..g_hi[g] - 1 at tau g_tau[g]), and the n_sliding faces sl_poly it slides
over, from sl_a to sl_b."""

_Scratch = namedtuple(
    "_Scratch",
    "polys kinds locals_ arc_start arc_len bounds in_plane system rhs solution order codes touch touch_face planar "
    "behind angles",
)
"""Work arrays of one thread, reused for every line and arc (see _new_scratch)."""

_Incidences = namedtuple("_Incidences", "node kind codes end s direction")
"""The incidence rows being filled (the columns of IncidenceChunk, codes and end int64)."""


# ----------------------------------------------------------------------------------------------------------
# 3-vectors: rows are read by component and small results are tuples, because a row view costs two atomic
# reference counts and a small array a heap allocation, which together took about half of the kernels' time


@njit_leaf
def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit_leaf
def _cross(a, b):
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit_leaf
def _row(array, i):
    """Row i of an (n, 3) array as a 3-tuple."""
    return array[i, 0], array[i, 1], array[i, 2]


@njit_leaf
def _minus(a, b):
    return a[0] - b[0], a[1] - b[1], a[2] - b[2]


@njit_leaf
def _negated(a):
    return -a[0], -a[1], -a[2]


@njit_leaf
def _scaled(a, s):
    return s * a[0], s * a[1], s * a[2]


@njit_leaf
def _over(a, s):
    return a[0] / s, a[1] / s, a[2] / s


@njit_leaf
def _along(point, t, d):
    """point + t d."""
    return point[0] + t * d[0], point[1] + t * d[1], point[2] + t * d[2]


@njit_leaf
def _combined(x, a, y, b):
    """x a + y b."""
    return x * a[0] + y * b[0], x * a[1] + y * b[1], x * a[2] + y * b[2]


@njit(cache=True)
def _new_scratch(size):
    """_Scratch for lines of up to `size` contacts and faces around a generator: polys, kinds (int8), locals_,
    arc_start, arc_len (size,); bounds (2 size,); in_plane (size,) bool; system (4, 4), rhs, solution (4,);
    order, codes (3,) int64; touch, planar (2,) bool; touch_face, behind (2,) int64; angles (5, 2 size) (see
    _enters)."""
    return _Scratch(
        np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int8), np.empty(size, dtype=np.int64),
        np.empty(size), np.empty(size), np.empty(2 * size), np.empty(size, dtype=np.bool_),
        np.empty((4, 4)), np.empty(4), np.empty(4), np.empty(3, dtype=np.int64), np.empty(3, dtype=np.int64),
        np.empty(2, dtype=np.bool_), np.empty(2, dtype=np.int64), np.empty(2, dtype=np.bool_),
        np.empty(2, dtype=np.int64), np.empty((5, 2 * size)),
    )  # fmt: skip


@njit(cache=True)
def _line_buffers(capacity):
    """Buffers for the contacts of one line: polygon (int64), t, kind (int8), local (int64); groups lo, hi
    (int64) and tau; sliding faces (int64) and their intervals from, to: (capacity,) each."""
    return (
        np.empty(capacity, dtype=np.int64), np.empty(capacity), np.empty(capacity, dtype=np.int8),
        np.empty(capacity, dtype=np.int64), np.empty(capacity, dtype=np.int64), np.empty(capacity, dtype=np.int64),
        np.empty(capacity), np.empty(capacity, dtype=np.int64), np.empty(capacity), np.empty(capacity),
    )  # fmt: skip


@njit_leaf
def _clip_line(origin, direction, lo, hi):
    """Parameter range (t0, t1) of origin + t direction inside the box [lo, hi]; t0 > t1 when it misses."""
    t0 = -np.inf
    t1 = np.inf
    for k in range(3):
        if direction[k] == 0.0:
            if origin[k] < lo[k] or origin[k] > hi[k]:
                return 1.0, 0.0
        else:
            a = (lo[k] - origin[k]) / direction[k]
            b = (hi[k] - origin[k]) / direction[k]
            if a > b:
                a, b = b, a
            t0 = max(t0, a)
            t1 = min(t1, b)
    return t0, t1


@njit_leaf
def _group_blocked(points, offsets, normals, polys, kinds, locals_, lo, hi, direction, angle_tol, arc_start, arc_len,
                   bounds):  # fmt: skip
    """Whether contacts lo..hi-1 of (polys, kinds, locals_), at one point, close around a line of the given
    (unit) direction (it cannot pass there); arc_start, arc_len (at least hi - lo,) and bounds (at least
    2 (hi - lo),) float64 are work arrays.

    A face whose plane holds the line projects along it to a ray, not a sector: it covers no direction around
    the line, so it is left out (its sector's side would otherwise be decided by rounding, and a line sliding
    along a face of a convex corner would count as entering the solid)."""
    # sectors cost a frame and arc tangents, and most points have fewer than two faces with one: count first
    members = 0
    first = -1
    second = -1
    for i in range(lo, hi):
        if kinds[i] == CONTACT_INTERIOR:
            return True
        if kinds[i] != CONTACT_EDGE and kinds[i] != CONTACT_VERTEX:
            continue
        if abs(_dot(_row(normals, polys[i]), direction)) > angle_tol:
            members += 1
            if first < 0:
                first = i
            else:
                second = i
    if members < 2:
        return False
    if members == 2 and kinds[first] == CONTACT_EDGE and kinds[second] == CONTACT_EDGE:
        covered = _faces_along_one_edge_cover(points, offsets, normals, polys, locals_, first, second, direction)
        if covered >= 0:
            return covered == 1
    e1, e2 = _perpendicular_frame(direction)
    members = 0
    for i in range(lo, hi):
        if kinds[i] != CONTACT_EDGE and kinds[i] != CONTACT_VERTEX:
            continue
        if abs(_dot(_row(normals, polys[i]), direction)) > angle_tol:
            arc_start[members], arc_len[members] = _contact_arc(
                points, offsets, normals, polys[i], kinds[i], locals_[i], e1, e2
            )
            members += 1
    return _arcs_cover_circle_with(arc_start, arc_len, members, angle_tol, bounds)


@njit_leaf
def _faces_along_one_edge_cover(points, offsets, normals, polys, locals_, first, second, direction):
    """Whether the two faces touched along one edge (contacts `first` and `second` of polys, locals_: edge k of
    each, with the same two end points), neither holding the line of this direction, close around it: 1 if so, 0
    if not, -1 when the edges are not the same segment. Each face covers the half-plane around the line on the
    side its inward direction n x e takes, and that side turns with the sign of n . direction (e x (n x e) is n
    |e|^2): the half-planes are opposite, and cover every direction, when the faces run along the edge in
    opposite senses and face the line alike, or in one sense and face it oppositely. The sectors of
    _group_blocked decide the same by the same signs, at the cost of a frame and four angles."""
    p = polys[first]
    q = polys[second]
    p_from = offsets[p] + locals_[first]
    p_to = offsets[p] + (locals_[first] + 1) % (offsets[p + 1] - offsets[p])
    q_from = offsets[q] + locals_[second]
    q_to = offsets[q] + (locals_[second] + 1) % (offsets[q + 1] - offsets[q])
    same = True
    opposite = True
    for k in range(3):
        same = same and points[p_from, k] == points[q_from, k] and points[p_to, k] == points[q_to, k]
        opposite = opposite and points[p_from, k] == points[q_to, k] and points[p_to, k] == points[q_from, k]
    if same == opposite:
        return -1
    alike = (_dot(_row(normals, p), direction) > 0.0) == (_dot(_row(normals, q), direction) > 0.0)
    return 1 if alike == opposite else 0


@njit_leaf
def _turn(angle):
    """angle % 4 (a full turn: core.raycast._quarter_turns) for an angle in (-4, 8), the same number (up to the
    sign of a zero): numba's float modulo calls the C library's fmod (1 % of office-432's samples), and a
    difference of two numbers within a factor two of each other is exact (Sterbenz), as is fmod."""
    if angle < 0.0:
        return angle + _TURN
    if angle >= _TURN:
        return angle - _TURN
    return angle


@njit_leaf
def _enters(points, offsets, normals, faces, kinds, corners, count, direction, e1, e2, cosine, angles):
    """Whether a line leaving a point along unit `direction` (frame e1, e2 across it) enters a solid whose
    faces meet there: faces[:count] touched as kinds[:count] (CONTACT_VERTEX at corner, CONTACT_EDGE along the
    edge from corner) wind -1 around every direction, counted with the sign of normal . direction. Faces seen
    edge-on (sliding) count nothing, nor contacts of other kinds; with none left the line enters nothing. angles:
    scratch (5+, 2 count)."""
    starts = angles[0]
    lengths = angles[1]
    signs = angles[2]
    bounds = angles[3]
    n = 0
    for i in range(count):
        if kinds[i] != CONTACT_EDGE and kinds[i] != CONTACT_VERTEX:
            continue
        face = faces[i]
        rate = normals[face, 0] * direction[0] + normals[face, 1] * direction[1] + normals[face, 2] * direction[2]
        if abs(rate) <= cosine:
            continue
        starts[n], lengths[n] = _contact_arc(points, offsets, normals, faces[i], kinds[i], corners[i], e1, e2)
        signs[n] = 1.0 if rate > 0.0 else -1.0
        bounds[2 * n] = starts[n]
        bounds[2 * n + 1] = _turn(starts[n] + lengths[n])
        n += 1
    if n == 0:
        return False
    # sorted by insertion (a few arcs; numba's sort would need its runtime)
    ordered = angles[4]
    for k in range(2 * n):
        value = bounds[k]
        j = k
        while j > 0 and ordered[j - 1] > value:
            ordered[j] = ordered[j - 1]
            j -= 1
        ordered[j] = value
    for k in range(2 * n):
        lo = ordered[k]
        hi = ordered[k + 1] if k + 1 < 2 * n else ordered[0] + _TURN
        if hi - lo <= cosine:
            continue
        middle = _turn(0.5 * (lo + hi))
        winding = 0.0
        for j in range(n):
            if _turn(middle - starts[j]) < lengths[j]:
                winding += signs[j]
        if winding >= 0.0:
            return False
    return True


@njit_leaf
def _on_solid(poly, offsets, corner_edge, element_solid, n_vertices):
    """Whether the polygon bounds a closed convex solid (see element_solids; corner_edge: the scene edge along
    each polygon side): behind it lies that solid's inside, not the free space behind a single panel."""
    return element_solid[n_vertices + corner_edge[offsets[poly]]] >= 0


@njit_leaf
def _goes_into_solid(points, offsets, normals, object_ids, corner_edge, element_solid, n_vertices, polys, kinds,
                     locals_, count, direction, angle_tol, angles):
    """Whether a line leaving the point of contacts polys, kinds, locals_ [:count] (all the faces there; put in
    object order here) along unit `direction` goes into a solid: behind a face of a closed solid (corner_edge,
    element_solid: see _on_solid) it crosses inside, or into an object whose corners and edges meet there, each
    object winding on its own (see _enters: a line leaving one box into another touching it winds zero in the
    sum). angles: scratch (5+, 2 count)."""
    for i in range(count):
        if kinds[i] == CONTACT_INTERIOR and _dot(_row(normals, polys[i]), direction) < -angle_tol and \
                _on_solid(polys[i], offsets, corner_edge, element_solid, n_vertices):  # fmt: skip
            return True
    # in object order by insertion (a few contacts)
    for i in range(1, count):
        k = i
        while k > 0 and object_ids[polys[k - 1]] > object_ids[polys[k]]:
            polys[k - 1], polys[k] = polys[k], polys[k - 1]
            kinds[k - 1], kinds[k] = kinds[k], kinds[k - 1]
            locals_[k - 1], locals_[k] = locals_[k], locals_[k - 1]
            k -= 1
    e1, e2 = _perpendicular_frame(direction)
    lo = 0
    while lo < count:
        hi = lo + 1
        while hi < count and object_ids[polys[hi]] == object_ids[polys[lo]]:
            hi += 1
        if _enters(points, offsets, normals, polys[lo:hi], kinds[lo:hi], locals_[lo:hi], hi - lo, direction, e1, e2,
                   angle_tol, angles):  # fmt: skip
            return True
        lo = hi
    return False


@njit_leaf
def _displaced_hit(points, offsets, normals, poly, kind, local, delta, u, angle_tol, margin=_SIDE_EPS):
    """First-order test: does the line displaced by the 3-vector `delta` (perpendicular to u) cross the polygon
    at the contact? Returns (hit, shift) where shift is how far along u the crossing moves (to order contacts).

    margin > 0 counts a displaced line that keeps grazing the contact (crossing on the polygon's boundary) as a
    hit, what deciding whether an arc is free needs; margin < 0 counts only lines crossing the polygon's
    inside, what finding where the lines end needs (a grazed face does not end them)."""
    n = _row(normals, poly)
    nu = _dot(n, u)
    grazing = margin > 0.0
    if abs(nu) <= angle_tol:
        return grazing, 0.0
    nd = _dot(n, delta)
    shift = -nd / nu
    if kind == CONTACT_INTERIOR:
        return True, shift
    q = _along(delta, shift, u)
    q_len = np.sqrt(_dot(q, q))
    if q_len == 0.0:
        return grazing, shift
    first = offsets[poly]
    count = offsets[poly + 1] - first
    if kind == CONTACT_EDGE:
        m = _cross(n, _minus(_row(points, first + (local + 1) % count), _row(points, first + local)))
        return _dot(q, m) > -margin * q_len * np.sqrt(_dot(m, m)), shift
    if kind == CONTACT_VERTEX:
        prev = _row(points, first + (local - 1) % count)
        corner = _row(points, first + local)
        nxt = _row(points, first + (local + 1) % count)
        m1 = _cross(n, _minus(corner, prev))
        m2 = _cross(n, _minus(nxt, corner))
        inside1 = _dot(q, m1) > -margin * q_len * np.sqrt(_dot(m1, m1))
        inside2 = _dot(q, m2) > -margin * q_len * np.sqrt(_dot(m2, m2))
        return inside1 and inside2, shift
    return True, shift


@njit_leaf
def _sliding_interval(points, offsets, normals, poly, start, u, length, tol):
    """(tau_in, tau_out): where the line start + tau u (tau in [0, length]), lying in the polygon's plane,
    overlaps the polygon; tau_in > tau_out when it does not."""
    first = offsets[poly]
    count = offsets[poly + 1] - first
    normal = _row(normals, poly)
    lo = 0.0
    hi = length
    for k in range(count):
        a = _row(points, first + k)
        b = _row(points, first + (k + 1) % count)
        outward = _cross(_minus(b, a), normal)
        outward = _over(outward, np.sqrt(_dot(outward, outward)))
        offset = _dot(_minus(start, a), outward)
        rate = _dot(u, outward)
        if rate == 0.0:
            if offset > tol:
                return 1.0, 0.0
        elif rate > 0.0:
            hi = min(hi, (tol - offset) / rate)
        else:
            lo = max(lo, (tol - offset) / rate)
    return lo, hi


@njit_leaf
def _inside_to_first_order(points, offsets, normals, poly, point, delta, tol, corners):
    """Whether `point` (in the polygon's plane) moved by a small multiple of `delta` (in that plane) lies
    strictly inside the polygon: inside by more than tol from every side, or on a side and moving inwards from
    it. Within tol of two sides (a corner): with `corners`, inside when it moves inwards from both (a point
    known to lie at the corner); without, not inside (a point merely near a corner, where a first-order motion
    tells nothing)."""
    first = offsets[poly]
    count = offsets[poly + 1] - first
    normal = _row(normals, poly)
    delta_len = np.sqrt(_dot(delta, delta))
    on_sides = 0
    for k in range(count):
        a = _row(points, first + k)
        inward = _cross(normal, _minus(_row(points, first + (k + 1) % count), a))
        inward = _over(inward, np.sqrt(_dot(inward, inward)))
        depth = _dot(_minus(point, a), inward)
        if depth > tol:
            continue
        on_sides += 1
        if depth < -tol or (on_sides > 1 and not corners) or _dot(delta, inward) <= _SIDE_EPS * delta_len:
            return False
    return True


@njit_leaf
def _near_sides_on_line(points, offsets, normals, poly, point, u, tol):
    """Whether every side of the polygon within tol of `point` (in its plane) lies on the line point + tau u:
    both its corners within tol of the line."""
    first = offsets[poly]
    count = offsets[poly + 1] - first
    normal = _row(normals, poly)
    for k in range(count):
        a = _row(points, first + k)
        b = _row(points, first + (k + 1) % count)
        inward = _cross(normal, _minus(b, a))
        inward = _over(inward, np.sqrt(_dot(inward, inward)))
        if abs(_dot(_minus(point, a), inward)) > tol:
            continue
        for corner in (a, b):
            off = _minus(corner, point)
            off = _minus(off, _scaled(u, _dot(off, u)))
            if _dot(off, off) > tol * tol:
                return False
    return True


@njit_leaf
def _pressed_pair(normals, object_ids, sl_poly, in_plane, k, m, angle_tol):
    """Whether sliding faces sl_poly[k] and sl_poly[m], both holding the displaced lines (in_plane), belong to
    different objects and face each other: where both hold a point, the objects touch there."""
    if not in_plane[k] or not in_plane[m] or object_ids[sl_poly[k]] == object_ids[sl_poly[m]]:
        return False
    return _dot(_row(normals, sl_poly[k]), _row(normals, sl_poly[m])) <= -1.0 + angle_tol


@njit_leaf
def _sandwiched(points, offsets, normals, object_ids, sl_poly, sl_a, sl_b, n_sliding, in_plane, start, u, alpha, beta,
                lo, hi, diag, angle_tol, tol):  # fmt: skip
    """Whether the line start + tau u, moved by the displacement alpha + (tau / diag) beta (zero: the line
    itself), runs between lo and hi through the inside of two coplanar faces of different objects facing
    each other (a box against a wall, a box's bottom on the floor): objects in contact, whose touching faces
    hide each other; such lines are inside the solids, blocked (seed 000 section 2.2, touching objects).
    in_plane (n_sliding,) bool: the faces whose plane holds every displaced line."""
    for k in range(n_sliding):
        for m in range(k + 1, n_sliding):
            if not _pressed_pair(normals, object_ids, sl_poly, in_plane, k, m, angle_tol):
                continue
            a = max(max(sl_a[k], sl_a[m]), lo)
            b = min(min(sl_b[k], sl_b[m]), hi)
            if b - a <= _CONTACT_LENGTHS * tol:
                continue
            tau = 0.5 * (a + b)
            point = _along(start, tau, u)
            delta = _along(alpha, tau / diag, beta)
            # a side the point lies on within tol but the line only crosses (at a grazing angle, near a corner
            # it pivots about) is no contact along the line: the motion tells nothing there, and the nodes at
            # either end of the arc, whose lines are farther from that side, see the lines stay outside
            if _inside_to_first_order(points, offsets, normals, sl_poly[k], point, delta, tol, False) and \
                    _inside_to_first_order(points, offsets, normals, sl_poly[m], point, delta, tol, False) and \
                    _near_sides_on_line(points, offsets, normals, sl_poly[k], point, u, tol) and \
                    _near_sides_on_line(points, offsets, normals, sl_poly[m], point, u, tol):  # fmt: skip
                return True
    return False


@njit_leaf
def _slide_along(edge_unit, edges, edge, delta, f1, f2):
    """(d, slide): the unit direction d of `edge` and how far along d the point where a line meets it moves
    when the line is moved by the small 3-vector `delta` across it (frame f1, f2): the part of delta across
    the line that the edge gives. slide is NaN when the edge runs along the line (it gives none)."""
    d = _edge_direction(edge_unit, edges, edge, -1)
    w1 = _dot(d, f1)
    w2 = _dot(d, f2)
    if w1 * w1 + w2 * w2 <= 1e-24:
        return d, np.nan
    return d, (_dot(delta, f1) * w1 + _dot(delta, f2) * w2) / (w1 * w1 + w2 * w2)


@njit_leaf
def _pressed_between_contacts(points, offsets, normals, edge_unit, edges, object_ids, sl_poly, n_sliding,
                              in_plane, crossing, delta, edge_a, edge_b, f1, f2, angle_tol, tol):  # fmt: skip
    """Whether lines moved by the small 3-vector `delta` (across the line, frame f1, f2) off the point `crossing`
    of edges edge_a and edge_b, meeting both, run between their two contacts through the inside of two faces of
    different objects facing each other whose plane holds them (sl_poly[:n_sliding], where in_plane): objects
    in contact, the lines inside them. Each contact moves along its edge by the part of delta across the line
    that the edge gives (_relaxed_arc's slide); the point halfway between them is tested to first order."""
    halfway = (0.0, 0.0, 0.0)
    for edge in (edge_a, edge_b):
        d, slide = _slide_along(edge_unit, edges, edge, delta, f1, f2)
        if not np.isfinite(slide):
            return False
        halfway = _along(halfway, 0.5 * slide, d)
    for k in range(n_sliding):
        for m in range(k + 1, n_sliding):
            if not _pressed_pair(normals, object_ids, sl_poly, in_plane, k, m, angle_tol):
                continue
            if _inside_to_first_order(points, offsets, normals, sl_poly[k], crossing, halfway, tol, False) and \
                    _inside_to_first_order(points, offsets, normals, sl_poly[m], crossing, halfway, tol, False):
                return True
    return False


@njit_leaf
def _solve4(a, b, x):
    """Solve the 4x4 system a x = b by Gaussian elimination with partial pivoting, in place: a (4, 4) and b (4,)
    float64 are overwritten, x (4,) float64 receives the solution. Returns whether the system is regular."""
    # the largest magnitude, NaN when an entry is (as np.max(np.abs(a)))
    scale = 0.0
    for row in range(4):
        for col in range(4):
            magnitude = abs(a[row, col])
            if magnitude > scale or np.isnan(magnitude):
                scale = magnitude
    if scale == 0.0:
        return False
    for col in range(4):
        pivot = col
        for row in range(col + 1, 4):
            if abs(a[row, col]) > abs(a[pivot, col]):
                pivot = row
        if abs(a[pivot, col]) <= 1e-12 * scale:
            return False
        if pivot != col:
            for k in range(4):
                a[col, k], a[pivot, k] = a[pivot, k], a[col, k]
            b[col], b[pivot] = b[pivot], b[col]
        for row in range(col + 1, 4):
            factor = a[row, col] / a[col, col]
            for k in range(col, 4):
                a[row, k] -= factor * a[col, k]
            b[row] -= factor * b[col]
    for row in range(3, -1, -1):
        total = b[row]
        for k in range(row + 1, 4):
            total -= a[row, k] * x[k]
        x[row] = total / a[row, row]
    return True


@njit(cache=True)
def _edge_units(vertices, edges):
    """(E, 3) float64: the unit direction of each edge from its first vertex."""
    units = np.empty((edges.shape[0], 3))
    for e in range(edges.shape[0]):
        d = _minus(_row(vertices, edges[e, 1]), _row(vertices, edges[e, 0]))
        units[e, 0], units[e, 1], units[e, 2] = _over(d, np.sqrt(_dot(d, d)))
    return units


@njit_leaf
def _edge_direction(edge_unit, edges, e, away_from):
    """Unit direction (3-tuple) of edge e (edge_unit: _edge_units), from its first vertex, or away from vertex
    `away_from` if >= 0 (the same numbers, negated: a - b is exactly -(b - a))."""
    if away_from >= 0 and edges[e, 1] == away_from:
        return -edge_unit[e, 0], -edge_unit[e, 1], -edge_unit[e, 2]
    return edge_unit[e, 0], edge_unit[e, 1], edge_unit[e, 2]


@njit_leaf
def _is_incident_face(poly, kind, gid, vf_off, vf_face, ef_off, ef_face):
    if kind == GEN_VERTEX:
        for i in range(vf_off[gid], vf_off[gid + 1]):
            if vf_face[i] == poly:
                return True
        return False
    for i in range(ef_off[gid], ef_off[gid + 1]):
        if ef_face[i] == poly:
            return True
    return False


@njit_leaf
def _generator_blocked(
    points, offsets, normals, kind, gid, vf_off, vf_face, vf_corner, ef_off, ef_face, ef_local,
    direction, angle_tol, polys, kinds, locals_, arc_start, arc_len, bounds,
):  # fmt: skip
    """Whether the faces around generator (kind, gid) close around a line of this direction through it."""
    count = 0
    if kind == GEN_VERTEX:
        for i in range(vf_off[gid], vf_off[gid + 1]):
            polys[count] = vf_face[i]
            kinds[count] = CONTACT_VERTEX
            locals_[count] = vf_corner[i]
            count += 1
    else:
        for i in range(ef_off[gid], ef_off[gid + 1]):
            polys[count] = ef_face[i]
            kinds[count] = CONTACT_EDGE
            locals_[count] = ef_local[i]
            count += 1
    return _group_blocked(
        points, offsets, normals, polys, kinds, locals_, 0, count, direction, angle_tol, arc_start, arc_len, bounds
    )


@njit_leaf
def _meets_first(normals, areas, poly, key, best, best_key, travel):
    """Whether a line travelling along `travel` (3-vector) meets polygon `poly` at position `key` before polygon
    `best` at `best_key` (best < 0: none yet). Positions within _SIDE_EPS are one point: there the face whose
    front the line arrives at comes first (a table top before the bottom of a box resting on it, reached from
    its back, inside the box), then the smaller face (a picture on a wall), then the lower id."""
    if best < 0:
        return True
    if abs(key - best_key) > _SIDE_EPS * (1.0 + abs(key) + abs(best_key)):
        return key < best_key
    front = _dot(_row(normals, poly), travel) < 0.0
    best_front = _dot(_row(normals, best), travel) < 0.0
    if front != best_front:
        return front
    if areas[poly] != areas[best]:
        return areas[poly] < areas[best]
    return poly < best


@njit_leaf
def _first_crossing(points, offsets, normals, areas, c_poly, c_kind, c_local, lo, hi, delta, u, angle_tol, outward):
    """Among contacts lo..hi-1 (one point), the polygon whose inside the displaced line crosses first going
    `outward` (+1 along u, -1 against); -1 when it crosses none (grazed polygons do not count: lines sliding
    past an edge in the plane of its face's neighbour go on). Ties: see _meets_first."""
    best = -1
    best_shift = 0.0
    for i in range(lo, hi):
        hit, shift = _displaced_hit(
            points, offsets, normals, c_poly[i], c_kind[i], c_local[i], delta, u, angle_tol, -_SIDE_EPS
        )
        if not hit:
            continue
        key = shift * outward
        if _meets_first(normals, areas, c_poly[i], key, best, best_shift, _scaled(u, outward)):
            best = c_poly[i]
            best_shift = key
    return best


@njit_leaf
def _near_plane(point, normal, offset, tol):
    return abs(_dot(normal, point) + offset) <= tol


@njit_leaf
def _parallel_edges(vertices, edge_unit, edges, e, f, tol):
    """Whether edge f stays within tol of a line parallel to edge e over its whole length."""
    d = _edge_direction(edge_unit, edges, e, -1)
    span = _minus(_row(vertices, edges[f, 1]), _row(vertices, edges[f, 0]))
    along = _dot(span, d)
    off = _minus(span, _scaled(d, along))
    return _dot(off, off) <= tol * tol


@njit_leaf
def _side_along(points, offsets, poly, kind, local, motion, tol):
    """The side of polygon `poly` at a contact (kind, local) that a point moving along `motion` (3-vector) from
    it stays on (within tol of the line of that motion): the edge of an edge contact, the side leaving a vertex
    contact's corner that way; -1 when none does."""
    first = offsets[poly]
    count = offsets[poly + 1] - first
    d = _over(motion, np.sqrt(_dot(motion, motion)))
    if kind == CONTACT_EDGE:
        candidates = (local, -1)
    elif kind == CONTACT_VERTEX:
        candidates = (local, (local - 1) % count)
    else:
        return -1
    corner = _row(points, first + local)
    for k in candidates:
        if k < 0:
            continue
        a = _row(points, first + k)
        b = _row(points, first + (k + 1) % count)
        span = _minus(b, a)
        off = _minus(span, _scaled(d, _dot(span, d)))
        if _dot(off, off) > tol * tol:
            continue
        if kind == CONTACT_EDGE:
            return k
        # from the corner along the side, not back past the corner
        leaving = _minus(b, corner) if k == local else _minus(a, corner)
        if _dot(leaving, d) > 0.0:
            return k
    return -1


@njit_leaf
def _shared_face(ef_off, ef_face, e, f):
    """Whether edges e and f bound one polygon."""
    for i in range(ef_off[e], ef_off[e + 1]):
        for k in range(ef_off[f], ef_off[f + 1]):
            if ef_face[i] == ef_face[k]:
                return True
    return False


@njit_leaf
def _flush_faces(ef_off, ef_face, face_region, split_edge, e, f):
    """Whether a face of edge e and a face of edge f are parts of one flat region (flat_regions: faces of objects
    in one plane joined along their edges; boxes stacked flush, a box beside another of its height). A line
    meeting e and f lies in that plane, as for two edges of one face."""
    if not (split_edge[e] and split_edge[f]):
        return False
    for i in range(ef_off[e], ef_off[e + 1]):
        for k in range(ef_off[f], ef_off[f + 1]):
            if ef_face[i] != ef_face[k] and face_region[ef_face[i]] == face_region[ef_face[k]]:
                return True
    return False


@njit_leaf
def _coplanar_swath(vertices, edge_unit, edges, ef_off, ef_face, face_region, split_edge, r_kind, r_id, n, tol):
    """Whether an EEE arc's three edges share a plane or two bound one face (or faces of one flat region, see
    _flush_faces): the degenerate edge triples the paper rejects (1999, section 2.2); they are not visual events.
    Two parallel edges and a third piercing their plane are one: the pencil of that plane about the piercing
    point (see _pivot), unless _aligned_pencil."""
    if n == 3 and r_kind[0] == GEN_EDGE and r_kind[1] == GEN_EDGE and r_kind[2] == GEN_EDGE:
        # two edges of one face: a line meeting both inside them lies in the face's plane (or passes through
        # their common vertex), so the family is the face's pencil through the third edge's crossing point, an
        # FE swath of seed 003's appendix, not an EEE swath (met at face nodes, see _validate_chunk)
        for j in range(3):
            for k in range(j + 1, 3):
                if _shared_face(ef_off, ef_face, r_id[j], r_id[k]) or \
                        _flush_faces(ef_off, ef_face, face_region, split_edge, r_id[j], r_id[k]):  # fmt: skip
                    return True
                if _parallel_edges(vertices, edge_unit, edges, r_id[j], r_id[k], tol) and \
                        _aligned_pencil(vertices, edges, r_id[j], r_id[k], r_id[3 - j - k], tol):  # fmt: skip
                    return True
        a = _row(vertices, edges[r_id[0], 0])
        tip = _minus(_row(vertices, edges[r_id[0], 1]), a)
        normal = _cross(tip, _minus(_row(vertices, edges[r_id[1], 0]), a))
        length = np.sqrt(_dot(normal, normal))
        if length == 0.0:
            normal = _cross(tip, _minus(_row(vertices, edges[r_id[1], 1]), a))
            length = np.sqrt(_dot(normal, normal))
        if length > 0.0:
            normal = _over(normal, length)
            offset = -_dot(normal, a)
            for k in range(3):
                for end in range(2):
                    if not _near_plane(_row(vertices, edges[r_id[k], end]), normal, offset, tol):
                        return False
            return True
    return False


@njit_leaf
def _aligned_pencil(vertices, edges, a, b, c, tol):
    """Whether the pencil of lines meeting parallel edges a and b and edge c (in the plane of a and b, about the
    point X where c pierces it) is degenerate, the simplest-configuration rule of seed 000 section 2.2 leaving
    it out: X lies on a or b (c crosses it: the pencils of a crossing, see FXE nodes), or one of its lines
    passes through an end of a and an end of b at once (their ends and X aligned: boxes of one height, a
    corner edge and a box edge ending on the floor), or c does not pierce the plane."""
    base = _row(vertices, edges[a, 0])
    normal = _cross(_minus(_row(vertices, edges[a, 1]), base), _minus(_row(vertices, edges[b, 0]), base))
    length = np.sqrt(_dot(normal, normal))
    if length == 0.0:
        return True
    normal = _over(normal, length)
    c0 = _row(vertices, edges[c, 0])
    span = _minus(_row(vertices, edges[c, 1]), c0)
    rate = _dot(normal, span)
    if abs(rate) <= tol:
        return True
    pivot = _along(c0, _dot(normal, _minus(base, c0)) / rate, span)
    if _segment_gap(vertices, edges, a, pivot) <= tol or _segment_gap(vertices, edges, b, pivot) <= tol:
        return True
    for end_a in range(2):
        for end_b in range(2):
            p = _row(vertices, edges[a, end_a])
            across = _minus(_row(vertices, edges[b, end_b]), p)
            off = _cross(across, _minus(pivot, p))
            if _dot(off, off) <= tol * tol * _dot(across, across):
                return True
    return False


@njit_leaf
def _segment_gap(vertices, edges, e, point):
    """The distance from a point (3-vector) to edge e."""
    base = _row(vertices, edges[e, 0])
    along = _minus(_row(vertices, edges[e, 1]), base)
    off = _minus(point, base)
    t = min(max(_dot(off, along) / _dot(along, along), 0.0), 1.0)
    gap = _minus(off, _scaled(along, t))
    return np.sqrt(_dot(gap, gap))


@njit_leaf
def _pivot(vertices, edge_unit, edges, r_kind, r_id, r_group, n_retained, tol):
    """The retained edge the lines of an EEE arc turn about, else -1: with three edges met at three points of
    the line, two of them spanning one plane (ends within tol of it) and the third piercing it, every line near
    this one meeting the two lies in their plane (a line meeting both elsewhere passes through the point where
    their lines cross, away from this line; parallel ones never cross), so the lines meeting all three are the
    pencil of that plane about the point where the third edge pierces it, and that edge's contact does not
    move."""
    if n_retained != 3:
        return -1
    for k in range(3):
        if r_kind[k] != GEN_EDGE or r_group[k] == r_group[(k + 1) % 3]:
            return -1
    for k in range(3):
        a = r_id[(k + 1) % 3]
        b = r_id[(k + 2) % 3]
        base = _row(vertices, edges[a, 0])
        # parallel edges span the plane holding one and the other's first end
        parallel = _parallel_edges(vertices, edge_unit, edges, a, b, tol)
        across = _minus(_row(vertices, edges[b, 0]), base) if parallel else \
            _minus(_row(vertices, edges[b, 1]), _row(vertices, edges[b, 0]))  # fmt: skip
        normal = _cross(_minus(_row(vertices, edges[a, 1]), base), across)
        length = np.sqrt(_dot(normal, normal))
        if length == 0.0:
            continue
        normal = _over(normal, length)
        offset = -_dot(normal, base)
        if _near_plane(_row(vertices, edges[b, 0]), normal, offset, tol) and \
                _near_plane(_row(vertices, edges[b, 1]), normal, offset, tol) and \
                not (_near_plane(_row(vertices, edges[r_id[k], 0]), normal, offset, tol) and
                     _near_plane(_row(vertices, edges[r_id[k], 1]), normal, offset, tol)):  # fmt: skip
            return k
    return -1


@njit_leaf
def _through_own_solid(kind_a, id_a, kind_b, id_b, element_solid, vf_off, vf_face, ef_off, ef_face):
    """Whether generators a and b belong to one convex solid and bound no common face of it: lines meeting both
    (inside the edges: an arc's lines between its nodes) run through that solid between them."""
    n_vertices = vf_off.shape[0] - 1
    obj = element_solid[id_a if kind_a == GEN_VERTEX else n_vertices + id_a]
    if obj < 0 or obj != element_solid[id_b if kind_b == GEN_VERTEX else n_vertices + id_b]:
        return False
    if kind_a == GEN_VERTEX:
        lo, hi, faces = vf_off[id_a], vf_off[id_a + 1], vf_face
    else:
        lo, hi, faces = ef_off[id_a], ef_off[id_a + 1], ef_face
    for i in range(lo, hi):
        if _is_incident_face(faces[i], kind_b, id_b, vf_off, vf_face, ef_off, ef_face):
            return False
    return True


@njit_leaf
def _plane_holds_generators(points, offsets, normals, vertices, edges, poly, r_kind, r_id, r_group, n_retained, tol):
    """Whether two of the retained generators (r_kind, r_id, r_group: n_retained of them) met at different points
    of the line lie in the polygon's plane (a vertex, or an edge with both ends, within tol of it)."""
    normal = _row(normals, poly)
    offset = -_dot(normal, _row(points, offsets[poly]))
    group = -1
    for j in range(n_retained):
        if r_kind[j] == GEN_VERTEX:
            inside = _near_plane(_row(vertices, r_id[j]), normal, offset, tol)
        else:
            inside = _near_plane(_row(vertices, edges[r_id[j], 0]), normal, offset, tol) and \
                _near_plane(_row(vertices, edges[r_id[j], 1]), normal, offset, tol)  # fmt: skip
        if not inside:
            continue
        if group >= 0 and r_group[j] != group:
            return True
        group = r_group[j]
    return False


@njit_leaf
def _crossing_pair(vertices, edge_unit, edges, r_kind, r_id, r_group, n_retained, tol):
    """(a, b), a < b: two retained edges met at one point and not parallel (crossing there: objects in contact),
    else (-1, -1)."""
    for j in range(n_retained):
        for k in range(j + 1, n_retained):
            if r_group[k] == r_group[j] and r_kind[j] == GEN_EDGE and r_kind[k] == GEN_EDGE and \
                    not _parallel_edges(vertices, edge_unit, edges, r_id[j], r_id[k], tol):  # fmt: skip
                return j, k
    return -1, -1


@njit_leaf
def _end_on_edge(vertices, edges, a, b, tol):
    """Whether an end of edge a lies within tol of edge b."""
    return _segment_gap(vertices, edges, b, _row(vertices, edges[a, 0])) <= tol or \
        _segment_gap(vertices, edges, b, _row(vertices, edges[a, 1])) <= tol  # fmt: skip


@njit_leaf
def _partner(pair, j):
    """The other member of the crossing pair (a, b) when j is one of them, else -1."""
    if j == pair[0]:
        return pair[1]
    if j == pair[1]:
        return pair[0]
    return -1


@njit_leaf
def _relaxed_arc(geometry_ref, line_ref, retained_ref, n_retained, norm_index, norm_dir, sigma, both_ways,
                 scratch_ref, incidences_ref, n_inc, node):  # fmt: skip
    """One arc adjacent to node `node` of `line` (_Line, its frame f1, f2 perpendicular to u) in the scene
    `geometry` (_Geometry), recorded at row n_inc of `incidences` (_Incidences) when it exists; returns the next
    free row. retained = (r_kind, r_id, r_group, r_pin), (3,) arrays: the retained generators, n_retained of them
    in any order; the motion normalised by sliding retained edge `norm_index` by sigma * norm_dir (3-vector);
    r_pin: for a retained edge met at one of its vertices, that vertex (its contact must move into the edge),
    else -1. both_ways: the arc of the opposite motion (-sigma) too, recorded after it: sigma scales the right-hand
    side of the motion's linear system alone, so that motion is the solution negated, and everything before it
    (the pencil and pivot tests, the system and its solve) is done once for both. scratch: the work arrays
    (_Scratch; x below: its solution, the motion's coefficients).

    The named tuples are handed over by address (`*_ref`, core.jit.by_reference): numba passes a tuple member by
    member, and the 408 machine words of these five were copied on the stack at every call; by address, with
    the unit edge directions looked up (_edge_units), office-432 builds 3 % faster (2026-11-29). Unpacked into
    sixty arguments by a wrapper, office-312's validation took 1.6 % longer on one thread (2026-11-27).

    The row holds the arc kind, the generators in canonical line order, the end faces before and after them,
    the node's coordinate s on the arc's parameter edge (its lowest retained edge id, 0..1 from its first
    vertex) and the direction, +1 when the arc extends towards larger s."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    scratch = dereferenced(scratch_ref)
    (points, offsets, normals, areas, vertices, edges, edge_unit, vf_off, vf_face, vf_corner, ef_off, ef_face, ef_local,
     corner_edge, face_group, object_ids, element_solid, face_region, split_edge, diag, tol,
     angle_tol) = geometry
    c_poly, c_kind, c_local, g_lo, g_hi, g_tau, n_groups, sl_poly, sl_a, sl_b, n_sliding, start, u, f1, f2 = line
    r_kind, r_id, r_group, r_pin = retained
    (polys, kinds, locals_, arc_start, arc_len, bounds, in_plane, system, rhs, x, order, codes, touch, touch_face,
     planar, behind, angles) = scratch
    # the motion sliding the contact on an edge off its crossing with another kept edge, on a line lying in
    # their plane: the lines keep meeting both in that plane, turning about the point where the third kept
    # generator meets it (a pencil of the contact plane: seed 003's fv arcs of an FvE node, keyed as EEE)
    pencil = -1
    pair = _crossing_pair(vertices, edge_unit, edges, r_kind, r_id, r_group, n_retained, tol)
    norm_partner = _partner(pair, norm_index)
    if norm_partner >= 0:
        across = _cross(_edge_direction(edge_unit, edges, r_id[norm_index], -1),
                        _edge_direction(edge_unit, edges, r_id[norm_partner], -1))  # fmt: skip
        if n_retained != 3 or abs(_dot(across, u)) > angle_tol * np.sqrt(_dot(across, across)):
            return n_inc
        pencil = 3 - norm_index - norm_partner
    elif pair[0] >= 0 and (_end_on_edge(vertices, edges, r_id[pair[0]], r_id[pair[1]], tol)
                           or _end_on_edge(vertices, edges, r_id[pair[1]], r_id[pair[0]], tol)):  # fmt: skip
        # the lines kept through the crossing are those through a vertex when it ends one of the edges (a chair
        # leg's top corner on the seat's bottom edge: no crossing of interiors, which FXE nodes stand for): that
        # vertex's EV arcs, which the nodes through it name so
        return n_inc
    # a pivot (see _pivot) moves by rounding only when solved for: held still, what meets the lines there
    # meets all of them. Sliding it cannot normalise the motion (the system is singular: nearly so by
    # rounding, a huge motion that is none), nor parametrise the arc (its lines would share one coordinate)
    pivot = _pivot(vertices, edge_unit, edges, r_kind, r_id, r_group, n_retained, tol)
    if pivot >= 0:
        lowest = True
        for k in range(n_retained):
            lowest = lowest and r_id[k] >= r_id[pivot]
        if pivot == norm_index or lowest:
            return n_inc
    for row in range(4):
        rhs[row] = 0.0
        for col in range(4):
            system[row, col] = 0.0
    row = 0
    for j in range(n_retained):
        tn = g_tau[r_group[j]] / diag
        # two kept edges crossing at one point hold the lines through that point, as a vertex does: the lines
        # meeting both near it but lying in their plane are the plane's pencils (above). Nothing slides along
        # either edge, so neither can normalise the motion
        partner = -1 if pencil >= 0 else _partner(pair, j)
        if j == norm_partner:
            continue
        if partner >= 0 and partner == norm_index:
            return n_inc
        if partner >= 0 and partner < j:
            continue
        if r_kind[j] == GEN_VERTEX or partner >= 0 or j == pencil:
            system[row, 0] = 1.0
            system[row, 2] = tn
            system[row + 1, 1] = 1.0
            system[row + 1, 3] = tn
            row += 2
        elif j == norm_index:
            w1 = _dot(norm_dir, f1)
            w2 = _dot(norm_dir, f2)
            system[row, 0] = 1.0
            system[row, 2] = tn
            rhs[row] = sigma * w1
            system[row + 1, 1] = 1.0
            system[row + 1, 3] = tn
            rhs[row + 1] = sigma * w2
            row += 2
        else:
            d = _edge_direction(edge_unit, edges, r_id[j], -1)
            w1 = _dot(d, f1)
            w2 = _dot(d, f2)
            system[row, 0] = -w2
            system[row, 1] = w1
            system[row, 2] = -w2 * tn
            system[row, 3] = w1 * tn
            row += 1
    if row != 4 or _coplanar_swath(vertices, edge_unit, edges, ef_off, ef_face, face_region, split_edge, r_kind, r_id,
                                   n_retained, tol):  # fmt: skip
        return n_inc
    if not _solve4(system, rhs, x):
        return n_inc
    # two retained generators met at different points of the plane of a face the line slides over hold every
    # line of the arc in that plane; the solved motion leaves it by rounding where their contacts are close
    # together (the system is then nearly singular across the plane), enough to find a crossing of that face
    # between them
    for k in range(n_sliding):
        if _plane_holds_generators(points, offsets, normals, vertices, edges, sl_poly[k], r_kind, r_id, r_group,
                                   n_retained, tol):  # fmt: skip
            n = _row(normals, sl_poly[k])
            m1 = _dot(n, f1)
            m2 = _dot(n, f2)
            across = m1 * m1 + m2 * m2
            if across > 0.0:
                for base in (0, 2):
                    out = (x[base] * m1 + x[base + 1] * m2) / across
                    x[base] -= out * m1
                    x[base + 1] -= out * m2
            break
    n_inc = _arc_of_motion(geometry_ref, line_ref, retained_ref, n_retained, norm_index, norm_partner, pencil, pair,
                           pivot, scratch_ref, incidences_ref, n_inc, node)  # fmt: skip
    if both_ways:
        for k in range(4):
            x[k] = -x[k]
        n_inc = _arc_of_motion(geometry_ref, line_ref, retained_ref, n_retained, norm_index, norm_partner, pencil,
                               pair, pivot, scratch_ref, incidences_ref, n_inc, node)  # fmt: skip
    return n_inc


@njit_leaf
def _arc_of_motion(geometry_ref, line_ref, retained_ref, n_retained, norm_index, norm_partner, pencil, pair, pivot,
                   scratch_ref, incidences_ref, n_inc, node):  # fmt: skip
    """The arc of _relaxed_arc for the motion solved in scratch.solution (x: alpha = x[0] f1 + x[1] f2, beta =
    x[2] f1 + x[3] f2), recorded at row n_inc of `incidences` when it exists; returns the next free row.
    norm_index, norm_partner, pencil, pair, pivot: as _relaxed_arc found them (-1: none)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    scratch = dereferenced(scratch_ref)
    incidences = dereferenced(incidences_ref)
    (points, offsets, normals, areas, vertices, edges, edge_unit, vf_off, vf_face, vf_corner, ef_off, ef_face, ef_local,
     corner_edge, face_group, object_ids, element_solid, face_region, split_edge, diag, tol,
     angle_tol) = geometry
    c_poly, c_kind, c_local, g_lo, g_hi, g_tau, n_groups, sl_poly, sl_a, sl_b, n_sliding, start, u, f1, f2 = line
    r_kind, r_id, r_group, r_pin = retained
    (polys, kinds, locals_, arc_start, arc_len, bounds, in_plane, system, rhs, x, order, codes, touch, touch_face,
     planar, behind, angles) = scratch
    beta = _combined(x[2], f1, x[3], f2)
    beta_len = np.sqrt(_dot(beta, beta))
    tilted = u
    if beta_len > 1e-12:
        tilted = _along(u, _TILT / beta_len, beta)
        tilted = _over(tilted, np.sqrt(_dot(tilted, tilted)))

    first = n_groups
    last = -1
    for j in range(n_retained):
        first = min(first, r_group[j])
        last = max(last, r_group[j])

    # the faces whose plane holds every line of the arc; lines running between touching objects between the
    # generators (see _sandwiched) are no arc
    for k in range(n_sliding):
        n = _row(normals, sl_poly[k])
        in_plane[k] = abs(x[2] * _dot(n, f1) + x[3] * _dot(n, f2)) <= 1e-12 and \
            abs(x[0] * _dot(n, f1) + x[1] * _dot(n, f2)) <= 1e-12  # fmt: skip
    if n_sliding >= 2:
        alpha = _combined(x[0], f1, x[1], f2)
        if _sandwiched(points, offsets, normals, object_ids, sl_poly, sl_a, sl_b, n_sliding, in_plane, start, u,
                       alpha, beta, g_tau[first], g_tau[last], diag, angle_tol, tol):  # fmt: skip
            return n_inc
        # a pencil's contacts on the norm edge and its partner part from their crossing: between them its lines
        # may run inside two facing faces of touching objects, which the node's line only reaches at that point
        if pencil >= 0:
            crossing_tau = g_tau[r_group[norm_index]]
            tn = crossing_tau / diag
            if _pressed_between_contacts(
                points, offsets, normals, edge_unit, edges, object_ids, sl_poly, n_sliding, in_plane,
                _along(start, crossing_tau, u), _combined(x[0] + tn * x[2], f1, x[1] + tn * x[3], f2),
                r_id[norm_index], r_id[norm_partner], f1, f2, angle_tol, tol,
            ):  # fmt: skip
                return n_inc

    # a face whose plane held the line is crossed where the displacement leaves its plane, if inside it
    before_tau = -np.inf
    before_poly = -1
    after_tau = np.inf
    after_poly = -1
    for side in range(2):
        touch[side] = False
        touch_face[side] = -1
        planar[side] = False
        behind[side] = -1
    for k in range(n_sliding):
        n = _row(normals, sl_poly[k])
        rate = x[2] * _dot(n, f1) + x[3] * _dot(n, f2)
        offset = x[0] * _dot(n, f1) + x[1] * _dot(n, f2)
        if abs(rate) <= 1e-12:
            # the whole family stays in the face's plane (or parallel to it): it keeps grazing the face. A face
            # all generators bound is the one a horizon slides over, whose far edge is a clean end; another
            # object's face in that plane, touching an outer generator and reaching beyond it (a leg's top edge
            # under the table top), makes the lines graze contacts where they end on that side (see
            # END_PLANAR); the other side may be clean (a horizon over a table top from a box standing on it).
            # A face met further on, past the outer generator, is read after the ends are known (below).
            # A face bounded by the outer generator ends at it (its tolerant overlap may poke past): only faces
            # the generator does not bound count on its side
            if in_plane[k]:
                for j in range(n_retained):
                    if _is_incident_face(sl_poly[k], r_kind[j], r_id[j], vf_off, vf_face, ef_off, ef_face):
                        continue
                    if r_group[j] == first and sl_a[k] < g_tau[first] - tol and sl_b[k] >= g_tau[first] - tol:
                        planar[0] = True
                    if r_group[j] == last and sl_b[k] > g_tau[last] + tol and sl_a[k] <= g_tau[last] + tol:
                        planar[1] = True
            continue
        crossing = -offset / rate * diag
        if crossing < sl_a[k] - tol or crossing > sl_b[k] + tol:
            continue
        at = -1
        if abs(crossing - g_tau[first]) <= tol:
            at = 0
        elif abs(crossing - g_tau[last]) <= tol:
            at = 1
        outer_vertex = False
        for j in range(n_retained):
            if at >= 0 and r_group[j] == (first if at == 0 else last) and r_kind[j] == GEN_VERTEX:
                outer_vertex = True
        # from an outer vertex towards the other generators the lines go behind a face lying along them there
        # (its own face when the node's line runs over it, a table top over a leg's top corner): they run inside
        # that face's object (an interior swath, seed 003 section 3.1, which bounds no view)
        if outer_vertex and (rate < 0.0) == (at == 0) and \
                _on_solid(sl_poly[k], offsets, corner_edge, element_solid, vertices.shape[0]) and \
                _inside_to_first_order(points, offsets, normals, sl_poly[k],
                                       _along(start, g_tau[first if at == 0 else last], u),
                                       u if at == 0 else _negated(u), tol, True):  # fmt: skip
            return n_inc
        handled = False
        for j in range(n_retained):
            if abs(g_tau[r_group[j]] - crossing) <= tol and _is_incident_face(
                sl_poly[k], r_kind[j], r_id[j], vf_off, vf_face, ef_off, ef_face
            ):
                handled = True
        if handled:
            continue
        # a face of another object crossed at an outer generator (a box corner or edge resting on the floor):
        # the lines end there as at the arc's nodes where they do not lie in that face's plane: stopped by a
        # vertex, on the face beyond an edge
        if at >= 0:
            for j in range(n_retained):
                if r_group[j] == (first if at == 0 else last):
                    if r_kind[j] == GEN_VERTEX:
                        touch[at] = True
                    elif _meets_first(
                        normals, areas, sl_poly[k], 0.0, touch_face[at], 0.0, u if at == 1 else _negated(u)
                    ):
                        touch_face[at] = sl_poly[k]
            continue
        if g_tau[first] + tol < crossing < g_tau[last] - tol:
            return n_inc
        if crossing <= g_tau[first] + tol and _meets_first(
            normals, areas, sl_poly[k], -crossing / diag, before_poly, -before_tau / diag, _negated(u)
        ):
            before_tau = crossing
            before_poly = sl_poly[k]
        if crossing >= g_tau[last] - tol and _meets_first(
            normals, areas, sl_poly[k], crossing / diag, after_poly, after_tau / diag, u
        ):
            after_tau = crossing
            after_poly = sl_poly[k]

    blocked_first = False
    blocked_last = False
    # the inner groups first: a face hit there rejects the arc before the outer generators' costlier tests
    for step in range(last - first + 1):
        if step < last - first - 1:
            g = first + 1 + step
        elif step == last - first - 1:
            g = first
        else:
            g = last
        tn = g_tau[g] / diag
        delta = _combined(x[0] + tn * x[2], f1, x[1] + tn * x[3], f2)
        j = -1
        for k in range(n_retained):
            if r_group[k] == g:
                j = k
        if pivot >= 0 and j == pivot:
            delta = (0.0, 0.0, 0.0)
        blocked = False
        partner = _partner(pair, j)
        crossed = -1
        if pencil >= 0 and partner >= 0:
            # the pencil's contact slides along the norm edge, off the crossing; the lines cross the partner edge
            # too, before or after the norm edge: its faces are a generator's, grazed, not faces in front
            j = norm_index
            crossed = r_id[norm_partner]
            partner = -1
        if partner >= 0:
            # the lines keep the crossing point: as at a vertex, every face there (those of both edges, which
            # a line in their plane slides over, and the other objects') may close around the tilted line
            count = 0
            for i in range(g_lo[g], g_hi[g]):
                own = _is_incident_face(c_poly[i], GEN_EDGE, r_id[j], vf_off, vf_face, ef_off, ef_face)
                if not own and not _is_incident_face(c_poly[i], GEN_EDGE, r_id[partner], vf_off, vf_face, ef_off,
                                                     ef_face):  # fmt: skip
                    polys[count] = c_poly[i]
                    kinds[count] = c_kind[i]
                    locals_[count] = c_local[i]
                    count += 1
            for e in (r_id[j], r_id[partner]):
                for i in range(ef_off[e], ef_off[e + 1]):
                    polys[count] = ef_face[i]
                    kinds[count] = CONTACT_EDGE
                    locals_[count] = ef_local[i]
                    count += 1
            blocked = _group_blocked(
                points, offsets, normals, polys, kinds, locals_, 0, count, tilted, angle_tol, arc_start, arc_len, bounds
            )
        elif j >= 0 and r_kind[j] == GEN_VERTEX:
            count = 0
            for i in range(g_lo[g], g_hi[g]):
                if not _is_incident_face(c_poly[i], GEN_VERTEX, r_id[j], vf_off, vf_face, ef_off, ef_face):
                    polys[count] = c_poly[i]
                    kinds[count] = c_kind[i]
                    locals_[count] = c_local[i]
                    count += 1
            for i in range(vf_off[r_id[j]], vf_off[r_id[j] + 1]):
                polys[count] = vf_face[i]
                kinds[count] = CONTACT_VERTEX
                locals_[count] = vf_corner[i]
                count += 1
            blocked = _group_blocked(
                points, offsets, normals, polys, kinds, locals_, 0, count, tilted, angle_tol, arc_start, arc_len, bounds
            )
            # an outer vertex stops the lines where they go into a solid (its own, or the one it rests on):
            # behind it, not on the generators' side, where they would run inside that solid (an interior swath,
            # seed 003 section 3.1, which bounds no view)
            if blocked and (g == first or g == last) and _goes_into_solid(
                points, offsets, normals, object_ids, corner_edge, element_solid, vertices.shape[0], polys, kinds,
                locals_, count, tilted if g == first else _negated(tilted), angle_tol, angles,
            ):  # fmt: skip
                return n_inc
        elif j >= 0:
            # the contact slides along the kept edge, so its position on the line moves too: a face met at
            # the same point is in front of the edge (the arc does not exist) or behind it (the line stops).
            # What can reject the arc comes before the faces closing around the edge, which cost arc tangents
            d, slide = _slide_along(edge_unit, edges, r_id[j], delta, f1, f2)
            if not np.isfinite(slide):
                return n_inc
            # an edge met at its end vertex only holds the lines whose contact moves into it
            if r_pin[j] >= 0 and slide * (1.0 if edges[r_id[j], 0] == r_pin[j] else -1.0) <= _SIDE_EPS:
                return n_inc
            # so does the other edge of a pencil's pair, met at its end vertex too (objects touching corner to
            # corner): its contact slides along it off the corner as well
            if crossed >= 0 and r_pin[norm_partner] >= 0:
                _, slide_crossed = _slide_along(edge_unit, edges, crossed, delta, f1, f2)
                if not np.isfinite(slide_crossed):
                    return n_inc
                if slide_crossed * (1.0 if edges[crossed, 0] == r_pin[norm_partner] else -1.0) <= _SIDE_EPS:
                    return n_inc
            generator_shift = slide * _dot(d, u)
            nearest = np.inf
            side = 1 if g == last else 0
            for i in range(g_lo[g], g_hi[g]):
                if _is_incident_face(c_poly[i], GEN_EDGE, r_id[j], vf_off, vf_face, ef_off, ef_face):
                    continue
                if crossed >= 0 and _is_incident_face(c_poly[i], GEN_EDGE, crossed, vf_off, vf_face, ef_off, ef_face):
                    continue
                hit, shift = _displaced_hit(
                    points, offsets, normals, c_poly[i], c_kind[i], c_local[i], delta, u, angle_tol
                )
                if not hit:
                    continue
                if g != first and g != last:
                    return n_inc
                ahead = shift - generator_shift if g == first else generator_shift - shift
                if ahead > _SIDE_EPS:
                    return n_inc
                # the lines cross this face just beyond the edge, or at it (the edge lies on the face: objects
                # in contact): it ends them, as it does at the arc's other node (one key for both ends). Only
                # its inside: lines grazing its side (sliding over a face of the edge to its corner) go on
                inside, _ = _displaced_hit(
                    points, offsets, normals, c_poly[i], c_kind[i], c_local[i], delta, u, angle_tol, -_SIDE_EPS
                )
                if not inside:
                    continue
                travel = u if g == last else _negated(u)
                # an edge lying on the face (objects in contact) reached from behind the face: the lines between
                # the generators run inside the other object (a box's bottom edge overhanging the top of the box
                # it stands on, seen from under that top), or behind a panel that hides the edge from them. Only
                # where the contact moves: lines kept through one point (where the edge crosses the face's side)
                # cross the face's plane on its boundary, whatever rounding says
                if ahead >= -_SIDE_EPS and _dot(_row(normals, c_poly[i]), travel) > angle_tol and \
                        _dot(delta, delta) > _SIDE_EPS * _SIDE_EPS:  # fmt: skip
                    return n_inc
                beyond = max(-ahead, 0.0)
                if _meets_first(normals, areas, c_poly[i], beyond, behind[side], nearest, travel):
                    nearest = beyond
                    behind[side] = c_poly[i]
            blocked = _generator_blocked(
                points, offsets, normals, GEN_EDGE, r_id[j], vf_off, vf_face, vf_corner, ef_off, ef_face,
                ef_local, tilted, angle_tol, polys, kinds, locals_, arc_start, arc_len, bounds,
            )  # fmt: skip
            if not blocked and crossed >= 0:
                blocked = _generator_blocked(
                    points, offsets, normals, GEN_EDGE, crossed, vf_off, vf_face, vf_corner, ef_off, ef_face,
                    ef_local, tilted, angle_tol, polys, kinds, locals_, arc_start, arc_len, bounds,
                )  # fmt: skip
            # another object's edge collinear with this one (boxes side by side or stacked flush), met here or
            # from its corner here on the side the contact slides to, keeps meeting the lines: its faces close
            # around them with the edge's own (lines over the seam of two coplanar tops go into the other box).
            # At an outer generator the lines may also come from inside that object, whether or not the edge's
            # own faces stop them
            if (not blocked or g == first or g == last) and abs(slide) > _SIDE_EPS:
                count = 0
                for i in range(ef_off[r_id[j]], ef_off[r_id[j] + 1]):
                    polys[count] = ef_face[i]
                    kinds[count] = CONTACT_EDGE
                    locals_[count] = ef_local[i]
                    count += 1
                own = count
                for i in range(g_lo[g], g_hi[g]):
                    if _is_incident_face(c_poly[i], GEN_EDGE, r_id[j], vf_off, vf_face, ef_off, ef_face):
                        continue
                    side_local = _side_along(points, offsets, c_poly[i], c_kind[i], c_local[i], _scaled(d, slide), tol)
                    if side_local >= 0:
                        polys[count] = c_poly[i]
                        kinds[count] = CONTACT_EDGE
                        locals_[count] = side_local
                        count += 1
                if count > own:
                    blocked = blocked or _group_blocked(
                        points, offsets, normals, polys, kinds, locals_, 0, count, tilted, angle_tol, arc_start,
                        arc_len, bounds,
                    )  # fmt: skip
                    # towards the other generators they may go into the other object (a box's top edge flush with
                    # the bottom edge of the box stacked on it, the lines coming down through the upper box): they
                    # run inside it between the generators, entering and leaving at edges, no face crossed
                    if blocked and _goes_into_solid(
                        points, offsets, normals, object_ids, corner_edge, element_solid, vertices.shape[0], polys,
                        kinds, locals_, count, tilted if g == first else _negated(tilted), angle_tol, angles,
                    ):  # fmt: skip
                        return n_inc
        else:
            for i in range(g_lo[g], g_hi[g]):
                hit, _ = _displaced_hit(points, offsets, normals, c_poly[i], c_kind[i], c_local[i], delta, u, angle_tol)
                if hit:
                    blocked = True
                    break
        if g == first:
            blocked_first = blocked
        elif g == last:
            blocked_last = blocked
        elif blocked:
            return n_inc

    # where the lines end beyond either outer generator (infinite: they leave the scene)
    reach_before = g_tau[first]
    reach_after = g_tau[last]
    end_before = END_FREE
    if blocked_first or touch[0]:
        end_before = END_TERMINAL
    elif behind[0] >= 0:
        end_before = face_group[behind[0]]
    elif touch_face[0] >= 0:
        end_before = face_group[touch_face[0]]
    else:
        reach_before = -np.inf
        for g in range(first - 1, -1, -1):
            if g_tau[g] < before_tau:
                break
            tn = g_tau[g] / diag
            delta = _combined(x[0] + tn * x[2], f1, x[1] + tn * x[3], f2)
            poly = _first_crossing(
                points, offsets, normals, areas, c_poly, c_kind, c_local, g_lo[g], g_hi[g], delta, u, angle_tol, -1.0
            )
            if poly >= 0:
                end_before = face_group[poly]
                reach_before = g_tau[g]
                break
        if end_before == END_FREE and before_poly >= 0:
            end_before = face_group[before_poly]
            reach_before = before_tau
    end_after = END_FREE
    if blocked_last or touch[1]:
        end_after = END_TERMINAL
    elif behind[1] >= 0:
        end_after = face_group[behind[1]]
    elif touch_face[1] >= 0:
        end_after = face_group[touch_face[1]]
    else:
        reach_after = np.inf
        for g in range(last + 1, n_groups):
            if g_tau[g] > after_tau:
                break
            tn = g_tau[g] / diag
            delta = _combined(x[0] + tn * x[2], f1, x[1] + tn * x[3], f2)
            poly = _first_crossing(
                points, offsets, normals, areas, c_poly, c_kind, c_local, g_lo[g], g_hi[g], delta, u, angle_tol, 1.0
            )
            if poly >= 0:
                end_after = face_group[poly]
                reach_after = g_tau[g]
                break
        if end_after == END_FREE and after_poly >= 0:
            end_after = face_group[after_poly]
            reach_after = after_tau

    # lines lying in the plane of a face they run along beyond an outer generator (the top of a box flush with
    # the one the generator bounds, the bottom of a box standing over them, two such faces pressed together)
    # have that face's solid on one side there, which the faces around the generators do not tell, and are
    # stopped inside a contact, which no face crossing tells: what either side sees is read by probing, as for
    # lines lying in a face's plane at the generators
    for k in range(n_sliding):
        if not in_plane[k]:
            continue
        incident = False
        for j in range(n_retained):
            if _is_incident_face(sl_poly[k], r_kind[j], r_id[j], vf_off, vf_face, ef_off, ef_face):
                incident = True
                break
        if incident:
            continue
        if min(sl_b[k], g_tau[first]) - max(sl_a[k], reach_before) > _CONTACT_LENGTHS * tol:
            planar[0] = True
        if min(sl_b[k], reach_after) - max(sl_a[k], g_tau[last]) > _CONTACT_LENGTHS * tol:
            planar[1] = True

    if planar[0]:
        end_before = END_PLANAR
    if planar[1]:
        end_after = END_PLANAR

    param = -1
    has_vertex = False
    for j in range(n_retained):
        if r_kind[j] == GEN_EDGE and (param < 0 or r_id[j] < r_id[param]):
            param = j
        if r_kind[j] == GEN_VERTEX:
            has_vertex = True
    e = r_id[param]
    a = _row(vertices, edges[e, 0])
    along = _minus(_row(vertices, edges[e, 1]), a)
    contact = _along(start, g_tau[r_group[param]], u)
    s = _dot(_minus(contact, a), along) / _dot(along, along)
    tn = g_tau[r_group[param]] / diag
    d = _over(along, np.sqrt(_dot(along, along)))
    rate = (x[0] + tn * x[2]) * _dot(d, f1) + (x[1] + tn * x[3]) * _dot(d, f2)
    if abs(rate) <= 1e-12:
        return n_inc
    direction = 1 if rate > 0.0 else -1
    # generators of one convex solid on no common face: the arc's lines cross its inside between them, at every
    # node along the arc alike (a test of the generators alone, last: most arcs tried end before)
    for j in range(n_retained):
        for k in range(j + 1, n_retained):
            if r_group[j] != r_group[k] and _through_own_solid(
                r_kind[j], r_id[j], r_kind[k], r_id[k], element_solid, vf_off, vf_face, ef_off, ef_face
            ):
                return n_inc

    # generators in line order. Two edges crossing at one point (one group): a pencil's lines leave the crossing
    # and meet them in the order of their contacts' first-order shifts along the line; lines kept through the
    # crossing meet both there, ordered by code. Then the canonical orientation: the end whose lowest code is
    # lower first (a crossing pair kept by code), so that the nodes on either side name the arc alike
    behind_of_pair = -1
    if pencil >= 0:
        tn = g_tau[r_group[norm_index]] / diag
        behind_of_pair = norm_index
        lowest = np.inf
        for m in (norm_index, norm_partner):
            d = _edge_direction(edge_unit, edges, r_id[m], -1)
            w1 = _dot(d, f1)
            w2 = _dot(d, f2)
            slide = ((x[0] + tn * x[2]) * w1 + (x[1] + tn * x[3]) * w2) / (w1 * w1 + w2 * w2)
            if slide * _dot(d, u) < lowest:
                lowest = slide * _dot(d, u)
                behind_of_pair = m
    for k in range(3):
        codes[k] = -1
    for k in range(n_retained):
        code = r_id[k] if r_kind[k] == GEN_VERTEX else vertices.shape[0] + r_id[k]
        place = k
        while place > 0:
            previous = order[place - 1]
            if r_group[k] != r_group[previous]:
                if g_tau[r_group[k]] > g_tau[r_group[previous]]:
                    break
            elif previous == behind_of_pair or (pencil < 0 and code > codes[place - 1]):
                break
            order[place] = previous
            codes[place] = codes[place - 1]
            place -= 1
        order[place] = k
        codes[place] = code
    last_low = n_retained - 1
    if pencil < 0 and r_group[order[last_low]] == r_group[order[last_low - 1]]:
        last_low -= 1
    if codes[0] > codes[last_low]:
        for k in range(n_retained // 2):
            codes[k], codes[n_retained - 1 - k] = codes[n_retained - 1 - k], codes[k]
            order[k], order[n_retained - 1 - k] = order[n_retained - 1 - k], order[k]
        for k in range(1, n_retained):
            if pencil < 0 and r_group[order[k]] == r_group[order[k - 1]] and codes[k] < codes[k - 1]:
                codes[k], codes[k - 1] = codes[k - 1], codes[k]
        end_before, end_after = end_after, end_before
    incidences.node[n_inc] = node
    incidences.kind[n_inc] = ARC_EV if has_vertex else ARC_EEE
    for k in range(3):
        incidences.codes[n_inc, k] = codes[k]
    incidences.end[n_inc, 0] = end_before
    incidences.end[n_inc, 1] = end_after
    incidences.s[n_inc] = s
    incidences.direction[n_inc] = direction
    return n_inc + 1


@njit_leaf
def _met_before(line_ref, corner_element, offsets, g, i, contact_kind, element):
    """Whether one of the contacts of group g of the line before contact i is of contact_kind (CONTACT_EDGE or
    CONTACT_VERTEX) with `element` (an edge or vertex met by its faces gives a contact per face); corner_element:
    the scene's corner_edge or corner_vertex, to match the kind."""
    line = dereferenced(line_ref)
    for earlier in range(line.g_lo[g], i):
        if line.c_kind[earlier] == contact_kind and \
                corner_element[offsets[line.c_poly[earlier]] + line.c_local[earlier]] == element:  # fmt: skip
            return True
    return False


@njit_leaf
def _other_corner_at(line_ref, corner_vertex, offsets, v, g):
    """Whether group g of the line, holding vertex v, meets another vertex there (objects corner to corner)."""
    line = dereferenced(line_ref)
    for i in range(line.g_lo[g], line.g_hi[g]):
        if line.c_kind[i] == CONTACT_VERTEX and corner_vertex[offsets[line.c_poly[i]] + line.c_local[i]] != v:
            return True
    return False


@njit_leaf
def _arcs_off_edge(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask, v, e_v,
                   tau_v, group_v, tau_w, gk, gid, ng):  # fmt: skip
    """The EV arcs of vertex generator v (at tau_v, group group_v of the node's line) and each masked edge of
    another object crossing the line where it runs along v's edge e_v (up to its other end, at tau_w): the lines
    through v meeting that edge lie in the plane of both edges and turn at this line from one side of e_v to
    the other (off the face of e_v, or in under the object stacked across it), so these arcs start or end
    here. gk, gid: the node's ng generators (edges among them have their own arcs). Returns the next free row,
    or -1 when the rows run out (see _validate_from)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    incidences = dereferenced(incidences_ref)
    g_ = geometry
    edges = g_.edges
    offsets = g_.offsets
    corner_edge = g_.corner_edge
    lo_tau = min(tau_v, tau_w) + g_.tol
    hi_tau = max(tau_v, tau_w) - g_.tol
    for g in range(line.n_groups):
        if not lo_tau < line.g_tau[g] < hi_tau:
            continue
        for i in range(line.g_lo[g], line.g_hi[g]):
            if line.c_kind[i] != CONTACT_EDGE:
                continue
            e = corner_edge[offsets[line.c_poly[i]] + line.c_local[i]]
            if not edge_mask[e] or edges[e, 0] == v or edges[e, 1] == v or \
                    _parallel_edges(g_.vertices, g_.edge_unit, edges, e_v, e, g_.tol):  # fmt: skip
                continue
            # once per edge: its faces give a contact each, and a generator edge has its own arcs
            repeated = _met_before(line_ref, corner_edge, offsets, g, i, CONTACT_EDGE, e)
            for k in range(ng):
                if gk[k] == GEN_EDGE and gid[k] == e:
                    repeated = True
            if repeated:
                continue
            if n_inc + 2 > incidences.node.shape[0]:
                return -1
            r_kind, r_id, r_group, _ = retained
            r_kind[0], r_id[0], r_group[0] = GEN_VERTEX, v, group_v
            r_kind[1], r_id[1], r_group[1] = GEN_EDGE, e, g
            norm_dir = _edge_direction(g_.edge_unit, edges, e, -1)
            n_inc = _relaxed_arc(geometry_ref, line_ref, retained_ref, 2, 1, norm_dir, 1.0, True, scratch_ref,
                                 incidences_ref, n_inc, node)  # fmt: skip
    return n_inc


@njit_leaf
def _pencils_at_junction(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask,
                         ve_off, ve_edge, v, group_v, extra, gk, gid, gg, ng):  # fmt: skip
    """The arcs of the pencils in the plane of vertex generator v's edge e_v and another object's edge `extra`
    through v (a box's corner on the edge of a box beside or under it: a T-junction), about a generator edge
    piercing that plane: their lines cross both edges, the contact on e_v moving into it from v, as at a
    crossing of two edges (FXE nodes) away from its ends. gk, gid, gg: the node's ng generators and their
    groups. Returns the next free row (_validate_chunk leaves room for these rows)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    g_ = geometry
    u = line.u
    across_extra = _edge_direction(g_.edge_unit, g_.edges, extra, -1)
    for slot in range(ve_off[v], ve_off[v + 1]):
        e_v = ve_edge[slot]
        if not edge_mask[e_v]:
            continue
        into = _edge_direction(g_.edge_unit, g_.edges, e_v, v)
        normal = _cross(into, across_extra)
        length = np.sqrt(_dot(normal, normal))
        # e_v along `extra` (boxes side by side) spans no plane; lines off the plane are no pencil of it
        if length <= g_.angle_tol or abs(_dot(normal, u)) > g_.angle_tol * length:
            continue
        # the lines run from their contact on e_v to their contact on `extra` within the angle of the two edges
        # at v (to first order, along `wedge`): where the objects of both touch there, face against face (boxes
        # side by side, seen in their contact plane), such lines are inside the solids
        turn = _dot(_cross(u, across_extra), normal)
        if turn == 0.0:
            continue
        wedge = _along(into, _dot(_cross(u, into), normal) / turn, across_extra)
        if _sliding_faces_meet_in(geometry_ref, line_ref, _row(g_.vertices, v), wedge, _over(normal, length)):
            continue
        for k in range(ng):
            if gk[k] != GEN_EDGE:
                continue
            if abs(_dot(_edge_direction(g_.edge_unit, g_.edges, gid[k], -1), normal)) <= g_.angle_tol * length:
                continue
            r_kind, r_id, r_group, r_pin = retained
            r_kind[0], r_id[0], r_group[0] = GEN_EDGE, gid[k], gg[k]
            r_kind[1], r_id[1], r_group[1], r_pin[1] = GEN_EDGE, e_v, group_v, v
            r_kind[2], r_id[2], r_group[2] = GEN_EDGE, extra, group_v
            n_inc = _relaxed_arc(geometry_ref, line_ref, retained_ref, 3, 1, into, 1.0, False, scratch_ref,
                                 incidences_ref, n_inc, node)  # fmt: skip
            r_pin[1] = -1
    return n_inc


@njit_leaf
def _swaths_leaving_both_vertices(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                                  edge_mask, ve_off, ve_edge, gid, gg, extra, g):  # fmt: skip
    """The EEE arcs of a line through two vertex generators gid[0], gid[1] (groups gg) and meeting edge `extra`
    (group g): through `extra`, an edge of either vertex, the contacts on both moving into them from their
    vertices (the first vertex's edge normalises the motion, the second's is pinned). Returns the next free row
    (the caller leaves room for one per pair of edges)."""
    geometry = dereferenced(geometry_ref)
    retained = dereferenced(retained_ref)
    r_kind, r_id, r_group, r_pin = retained
    for slot in range(ve_off[gid[0]], ve_off[gid[0] + 1]):
        e_slide = ve_edge[slot]
        if not edge_mask[e_slide] or e_slide == extra:
            continue
        for other in range(ve_off[gid[1]], ve_off[gid[1] + 1]):
            e_pin = ve_edge[other]
            if not edge_mask[e_pin] or e_pin == extra or e_pin == e_slide:
                continue
            r_kind[0], r_id[0], r_group[0] = GEN_EDGE, e_slide, gg[0]
            r_kind[1], r_id[1], r_group[1], r_pin[1] = GEN_EDGE, e_pin, gg[1], gid[1]
            r_kind[2], r_id[2], r_group[2] = GEN_EDGE, extra, g
            norm_dir = _edge_direction(geometry.edge_unit, geometry.edges, e_slide, gid[0])
            n_inc = _relaxed_arc(geometry_ref, line_ref, retained_ref, 3, 0, norm_dir, 1.0, False, scratch_ref,
                                 incidences_ref, n_inc, node)  # fmt: skip
            r_pin[1] = -1
    return n_inc


@njit_leaf
def _corner_edges(geometry_ref, line_ref, edge_mask, ve_off, ve_edge, v, g, out, pins):
    """The masked edges the contact of a line through vertex v (met in group g of the line) may move into, written
    to `out`: v's own, the contact moving into them from v (pins: v), and other objects' edges holding v (a
    box's corner on the seam of two boxes side by side), the contact sliding either way (pins: -1). Returns how
    many."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    count = 0
    for slot in range(ve_off[v], ve_off[v + 1]):
        if edge_mask[ve_edge[slot]]:
            out[count] = ve_edge[slot]
            pins[count] = v
            count += 1
    edges, offsets, corner_edge = geometry.edges, geometry.offsets, geometry.corner_edge
    for i in range(line.g_lo[g], line.g_hi[g]):
        if line.c_kind[i] != CONTACT_EDGE:
            continue
        e = corner_edge[offsets[line.c_poly[i]] + line.c_local[i]]
        if edge_mask[e] and edges[e, 0] != v and edges[e, 1] != v and \
                not _met_before(line_ref, corner_edge, offsets, g, i, CONTACT_EDGE, e):  # fmt: skip
            out[count] = e
            pins[count] = -1
            count += 1
    return count


@njit(cache=True)
def _swaths_leaving_three_corners(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                                  edge_mask, ve_off, ve_edge, gid, gg, x, g):  # fmt: skip
    """The EEE arcs of a line through two vertex generators gid[0], gid[1] (groups gg) grazing a third vertex x
    between them (group g): through an edge at each of the three corners (see _corner_edges), the contacts
    leaving all three at once. Returns the next free row, or -1 when the rows run out (see _validate_from)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    incidences = dereferenced(incidences_ref)
    corners = (gid[0], gid[1], x)
    groups = (gg[0], gg[1], g)
    size = 0
    for k in range(3):
        size = max(size, ve_off[corners[k] + 1] - ve_off[corners[k]] + line.g_hi[groups[k]] - line.g_lo[groups[k]])
    found = np.empty((3, size), dtype=np.int64)
    pins = np.empty((3, size), dtype=np.int64)
    counts = np.empty(3, dtype=np.int64)
    for k in range(3):
        counts[k] = _corner_edges(geometry_ref, line_ref, edge_mask, ve_off, ve_edge, corners[k], groups[k], found[k],
                                  pins[k])  # fmt: skip
    if n_inc + 2 * counts[0] * counts[1] * counts[2] > incidences.node.shape[0]:
        return -1
    r_kind, r_id, r_group, r_pin = retained
    for a in range(counts[0]):
        for b in range(counts[1]):
            for c in range(counts[2]):
                e_a, e_b, e_c = found[0, a], found[1, b], found[2, c]
                if e_a == e_b or e_a == e_c or e_b == e_c:
                    continue
                r_kind[0], r_id[0], r_group[0], r_pin[0] = GEN_EDGE, e_a, groups[0], pins[0, a]
                r_kind[1], r_id[1], r_group[1], r_pin[1] = GEN_EDGE, e_b, groups[1], pins[1, b]
                r_kind[2], r_id[2], r_group[2], r_pin[2] = GEN_EDGE, e_c, groups[2], pins[2, c]
                norm_dir = _edge_direction(geometry.edge_unit, geometry.edges, e_a, -1)
                n_inc = _relaxed_arc(
                    geometry_ref, line_ref, retained_ref, 3, 0, norm_dir, 1.0, True, scratch_ref, incidences_ref,
                    n_inc, node
                )
    for k in range(3):
        r_pin[k] = -1
    return n_inc


@njit_leaf
def _vertex_replaced_by_edge(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                             edge_mask, ve_off, ve_edge, j, extra, gk, gid, gg, ng):  # fmt: skip
    """The arcs of the node's generators (gk, gid, gg: ng of them) with vertex generator j replaced by another
    object's edge `extra` holding it, the contact sliding either way along that edge, and the pencils of that
    junction (_pencils_at_junction). Returns the next free row (the caller leaves room for these rows)."""
    geometry = dereferenced(geometry_ref)
    retained = dereferenced(retained_ref)
    r_kind, r_id, r_group, _ = retained
    for k in range(ng):
        r_kind[k] = GEN_EDGE if k == j else gk[k]
        r_id[k] = extra if k == j else gid[k]
        r_group[k] = gg[k]
    norm_dir = _edge_direction(geometry.edge_unit, geometry.edges, extra, -1)
    n_inc = _relaxed_arc(geometry_ref, line_ref, retained_ref, ng, j, norm_dir, 1.0, True, scratch_ref,
                         incidences_ref, n_inc, node)  # fmt: skip
    return _pencils_at_junction(
        geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask, ve_off, ve_edge,
        gid[j], gg[j], extra,
        gk, gid, gg, ng,
    )  # fmt: skip


@njit_leaf
def _angle_in_solid(geometry_ref, line_ref, scratch_ref, group, into_a, into_b):
    """Whether the points just inside the angle of unit directions into_a, into_b at the contact point of the
    line's group `group` lie inside a solid touching that point (see _goes_into_solid; the group's contacts are
    copied into scratch's contact rows)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    scratch = dereferenced(scratch_ref)
    g_ = geometry
    polys, kinds, locals_ = scratch.polys, scratch.kinds, scratch.locals_
    count = 0
    for i in range(line.g_lo[group], line.g_hi[group]):
        polys[count] = line.c_poly[i]
        kinds[count] = line.c_kind[i]
        locals_[count] = line.c_local[i]
        count += 1
    inward = _along(into_a, 1.0, into_b)
    inward = _over(inward, np.sqrt(_dot(inward, inward)))
    return _goes_into_solid(g_.points, g_.offsets, g_.normals, g_.object_ids, g_.corner_edge, g_.element_solid,
                            g_.vertices.shape[0], polys, kinds, locals_, count, inward, g_.angle_tol,
                            scratch.angles)  # fmt: skip


@njit_leaf
def _pencils_at_shared_corner(geometry_ref, corner_vertex, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc,
                              node, edge_mask, ve_off, ve_edge, v, group_v, gk, gid, gg, ng):  # fmt: skip
    """The arcs of the pencils in the plane of vertex generator v's edge e_v and an edge e_w of another vertex w at
    v's point (objects touching corner to corner: a chair leg's top corner under the seat's corner) about a
    generator edge piercing that plane, when the node's line lies in it: their lines cross e_v and e_w near the
    corner, both contacts moving into their edges from it, and pass through the corner on this line, where
    both contacts reach their edge's end at once (no node through one of the vertices and the other edge names
    them). gk, gid, gg: the node's ng generators and their groups. Returns the next free row, or -1 when the
    rows run out (see _validate_from)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    incidences = dereferenced(incidences_ref)
    g_ = geometry
    vertices, edges, edge_unit, offsets = g_.vertices, g_.edges, g_.edge_unit, g_.offsets
    u = line.u
    corner = _row(vertices, v)
    for i in range(line.g_lo[group_v], line.g_hi[group_v]):
        if line.c_kind[i] != CONTACT_VERTEX:
            continue
        w = corner_vertex[offsets[line.c_poly[i]] + line.c_local[i]]
        if w == v:
            continue
        # once per vertex: each of its faces gives a contact
        if _met_before(line_ref, corner_vertex, offsets, group_v, i, CONTACT_VERTEX, w):
            continue
        for slot_v in range(ve_off[v], ve_off[v + 1]):
            e_v = ve_edge[slot_v]
            if not edge_mask[e_v]:
                continue
            into_v = _edge_direction(edge_unit, edges, e_v, v)
            for slot_w in range(ve_off[w], ve_off[w + 1]):
                e_w = ve_edge[slot_w]
                if not edge_mask[e_w]:
                    continue
                into_w = _edge_direction(edge_unit, edges, e_w, w)
                normal = _cross(into_v, into_w)
                length = np.sqrt(_dot(normal, normal))
                # edges along each other span no plane; lines off the plane are no pencil of it
                if length <= g_.angle_tol or abs(_dot(normal, u)) > g_.angle_tol * length:
                    continue
                # the lines run between their contacts within the angle of the two edges at the corner: where two
                # objects touch there face against face (those of the edges, or a third one's face under both: a
                # box stacked on another, its corner on the other's edge), such lines are inside the solids
                if _sliding_faces_meet_in(geometry_ref, line_ref, corner, _along(into_v, 1.0, into_w), _over(normal,
                                                                                                             length)):
                    continue
                # or in a solid whose edge or corner is at the corner (two boxes stacked corner to corner beside
                # a third box that reaches past both): the lines enter it at one edge and leave it at the other
                if _angle_in_solid(geometry_ref, line_ref, scratch_ref, group_v, into_v, into_w):
                    continue
                for k in range(ng):
                    if gk[k] != GEN_EDGE or \
                            abs(_dot(_edge_direction(edge_unit, edges, gid[k], -1), normal)) <= g_.angle_tol * length:
                        continue
                    if n_inc + 1 > incidences.node.shape[0]:
                        return -1
                    r_kind, r_id, r_group, r_pin = retained
                    r_kind[0], r_id[0], r_group[0] = GEN_EDGE, gid[k], gg[k]
                    r_kind[1], r_id[1], r_group[1], r_pin[1] = GEN_EDGE, e_v, group_v, v
                    r_kind[2], r_id[2], r_group[2], r_pin[2] = GEN_EDGE, e_w, group_v, w
                    n_inc = _relaxed_arc(geometry_ref, line_ref, retained_ref, 3, 1, into_v, 1.0, False, scratch_ref,
                                         incidences_ref, n_inc, node)  # fmt: skip
                    r_pin[1] = -1
                    r_pin[2] = -1
    return n_inc


@njit_leaf
def _on_line_around(vertices, edges, line_ref, e, tau_v, tol):
    """Whether edge e lies on the line (both ends within tol) with the point at tau_v strictly inside it."""
    line = dereferenced(line_ref)
    tau_a = _dot(_minus(_row(vertices, edges[e, 0]), line.start), line.u)
    tau_b = _dot(_minus(_row(vertices, edges[e, 1]), line.start), line.u)
    if not min(tau_a, tau_b) + tol < tau_v < max(tau_a, tau_b) - tol:
        return False
    for end in range(2):
        off = _minus(_row(vertices, edges[e, end]), line.start)
        off = _minus(off, _scaled(line.u, _dot(off, line.u)))
        if _dot(off, off) > tol * tol:
            return False
    return True


@njit_leaf
def _slides_along_edge_through(geometry_ref, line_ref, edge_mask, v, tau_v):
    """Whether a face the line slides over has a masked edge, not at vertex v, lying on the line around v's
    point (tau_v): the only lines _pencils_to_vertex_on_edge has work on."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    edges, offsets, corner_edge = geometry.edges, geometry.offsets, geometry.corner_edge
    for k in range(line.n_sliding):
        poly = line.sl_poly[k]
        for c in range(offsets[poly], offsets[poly + 1]):
            e = corner_edge[c]
            if edge_mask[e] and edges[e, 0] != v and edges[e, 1] != v and \
                    _on_line_around(geometry.vertices, edges, line_ref, e, tau_v, geometry.tol):  # fmt: skip
                return True
    return False


@njit_leaf
def _pencils_to_vertex_on_edge(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                               edge_mask, ve_off, ve_edge, v, tau_v, group_v):  # fmt: skip
    """The pencil arcs ending where the line runs along another object's edge e through vertex generator v (at
    tau_v, group group_v) lying inside e (a box's top corner on the top edge of a box of the same height beside
    it). An edge f crossing e on the line (the bottom edge of a box stacked on the other) holds the pencil of
    the plane of e and an edge e_v of v about the crossing: its lines meet e_v, and their contact reaches v on
    this line, along e. A corner off e ends such a pencil at the VEE node of the corner, e and f; this line
    meets e along its length, no VEE candidate, so its nodes (two vertices on it) end the pencil: relaxing v,
    the contact moves into e_v while the lines keep the crossing. Returns the next free row, or -1 when the
    rows run out (see _validate_from)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    incidences = dereferenced(incidences_ref)
    g_ = geometry
    vertices, edges, edge_unit = g_.vertices, g_.edges, g_.edge_unit
    offsets, corner_edge = g_.offsets, g_.corner_edge
    tol = g_.tol
    for k in range(line.n_sliding):
        poly = line.sl_poly[k]
        for side in range(offsets[poly + 1] - offsets[poly]):
            e = corner_edge[offsets[poly] + side]
            if not edge_mask[e] or edges[e, 0] == v or edges[e, 1] == v:
                continue
            if not _on_line_around(vertices, edges, line_ref, e, tau_v, tol):
                continue
            tau_a = _dot(_minus(_row(vertices, edges[e, 0]), line.start), line.u)
            tau_b = _dot(_minus(_row(vertices, edges[e, 1]), line.start), line.u)
            # once per edge: both its faces hold the line
            repeated = False
            for earlier in range(k):
                other = line.sl_poly[earlier]
                for c in range(offsets[other], offsets[other + 1]):
                    repeated = repeated or corner_edge[c] == e
            if repeated:
                continue
            along = _edge_direction(edge_unit, edges, e, -1)
            for g in range(line.n_groups):
                if g == group_v or not min(tau_a, tau_b) + tol < line.g_tau[g] < max(tau_a, tau_b) - tol:
                    continue
                for i in range(line.g_lo[g], line.g_hi[g]):
                    if line.c_kind[i] != CONTACT_EDGE:
                        continue
                    f = corner_edge[offsets[line.c_poly[i]] + line.c_local[i]]
                    if not edge_mask[f] or edges[f, 0] == v or edges[f, 1] == v or \
                            _parallel_edges(vertices, edge_unit, edges, e, f, tol) or \
                            _met_before(line_ref, corner_edge, offsets, g, i, CONTACT_EDGE, f):  # fmt: skip
                        continue
                    across = _edge_direction(edge_unit, edges, f, -1)
                    for slot in range(ve_off[v], ve_off[v + 1]):
                        e_v = ve_edge[slot]
                        if not edge_mask[e_v]:
                            continue
                        into = _edge_direction(edge_unit, edges, e_v, v)
                        normal = _cross(into, along)
                        length = np.sqrt(_dot(normal, normal))
                        if length <= g_.angle_tol or abs(_dot(across, normal)) <= g_.angle_tol * length:
                            continue
                        if n_inc + 1 > incidences.node.shape[0]:
                            return -1
                        r_kind, r_id, r_group, r_pin = retained
                        r_kind[0], r_id[0], r_group[0] = GEN_EDGE, f, g
                        r_kind[1], r_id[1], r_group[1], r_pin[1] = GEN_EDGE, e_v, group_v, v
                        r_kind[2], r_id[2], r_group[2] = GEN_EDGE, e, g
                        n_inc = _relaxed_arc(
                            geometry_ref, line_ref, retained_ref, 3, 1, into, 1.0, False, scratch_ref, incidences_ref,
                            n_inc, node
                        )
                        r_pin[1] = -1
    return n_inc


@njit_leaf
def _pencils_over_plane_edges(geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, gid, gg,
                              lone):
    """The pencil arcs of an FXE node (generators gid in line order, groups gg, `lone` the third edge's index)
    named by another edge of the crossing's plane that its line crosses between the third edge and the crossing
    (the top edge of a box the line runs over to the crossing): relaxing the crossing, the contact on either
    crossing edge slides off it while the lines keep meeting that edge. A node through a vertex of the
    crossing edge, off the crossing, meets the same pencil with that edge among its generators, and names the
    arc so; the lines that go on to cross the other crossing edge are rejected at both (they graze it). Returns
    the next free row, or -1 when the rows run out (see _validate_from)."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    retained = dereferenced(retained_ref)
    incidences = dereferenced(incidences_ref)
    g_ = geometry
    edges, edge_unit = g_.edges, g_.edge_unit
    first_pair = 1 if lone == 0 else 0
    second_pair = 3 - lone - first_pair
    normal = _cross(_edge_direction(edge_unit, edges, gid[first_pair], -1),
                    _edge_direction(edge_unit, edges, gid[second_pair], -1))  # fmt: skip
    normal_len = np.sqrt(_dot(normal, normal))
    lo_group = min(gg[lone], gg[first_pair])
    hi_group = max(gg[lone], gg[first_pair])
    for g in range(lo_group + 1, hi_group):
        for i in range(line.g_lo[g], line.g_hi[g]):
            if line.c_kind[i] != CONTACT_EDGE:
                continue
            e = g_.corner_edge[g_.offsets[line.c_poly[i]] + line.c_local[i]]
            if abs(_dot(_edge_direction(edge_unit, edges, e, -1), normal)) > g_.angle_tol * normal_len:
                continue
            # once per edge: each of its faces gives a contact
            if _met_before(line_ref, g_.corner_edge, g_.offsets, g, i, CONTACT_EDGE, e):
                continue
            if n_inc + 4 > incidences.node.shape[0]:
                return -1
            r_kind, r_id, r_group, _ = retained
            for sliding in (first_pair, second_pair):
                r_kind[0], r_id[0], r_group[0] = GEN_EDGE, gid[lone], gg[lone]
                r_kind[1], r_id[1], r_group[1] = GEN_EDGE, e, g
                r_kind[2], r_id[2], r_group[2] = GEN_EDGE, gid[sliding], gg[sliding]
                norm_dir = _edge_direction(edge_unit, edges, gid[sliding], -1)
                n_inc = _relaxed_arc(
                    geometry_ref, line_ref, retained_ref, 3, 2, norm_dir, 1.0, True, scratch_ref, incidences_ref,
                    n_inc, node
                )
    return n_inc


@njit_leaf
def _sliding_faces_meet_in(geometry_ref, line_ref, point, direction, normal):
    """Whether two faces the line slides over, in the plane of unit `normal` and facing each other, both hold the
    points just off `point` along `direction` (in that plane): objects pressed together there."""
    geometry = dereferenced(geometry_ref)
    line = dereferenced(line_ref)
    g_ = geometry
    points, offsets, normals = g_.points, g_.offsets, g_.normals
    for k in range(line.n_sliding):
        a = line.sl_poly[k]
        if abs(_dot(_row(normals, a), normal)) < 1.0 - g_.angle_tol or \
                not _inside_to_first_order(points, offsets, normals, a, point, direction, g_.tol, True):  # fmt: skip
            continue
        for m in range(k + 1, line.n_sliding):
            b = line.sl_poly[m]
            if _dot(_row(normals, a), _row(normals, b)) <= -1.0 + g_.angle_tol and \
                    _inside_to_first_order(points, offsets, normals, b, point, direction, g_.tol, True):  # fmt: skip
                return True
    return False


@njit(cache=True)
def _grown(incidences, n_inc, least):
    """_Incidences with room for twice as many rows and at least `least`, the first n_inc copied: rows an arc
    call site cannot bound in advance (edges crossing a vertex's edge along a node's line)."""
    size = max(2 * incidences.node.shape[0] + 16, least)
    bigger = _Incidences(
        np.empty(size, dtype=np.int64), np.empty(size, dtype=np.int8), np.empty((size, 3), dtype=np.int64),
        np.empty((size, 2), dtype=np.int64), np.empty(size), np.empty(size, dtype=np.int8),
    )  # fmt: skip
    bigger.node[:n_inc] = incidences.node[:n_inc]
    bigger.kind[:n_inc] = incidences.kind[:n_inc]
    bigger.codes[:n_inc] = incidences.codes[:n_inc]
    bigger.end[:n_inc] = incidences.end[:n_inc]
    bigger.s[:n_inc] = incidences.s[:n_inc]
    bigger.direction[:n_inc] = incidences.direction[:n_inc]
    return bigger


@njit_leaf
def _without_arcs_in_plane(incidences_ref, lo, hi, points, offsets, normals, vertices, edges, poly, tol):
    """Drop the incidence rows lo..hi whose generators all lie in the polygon's plane (an edge with both ends within
    tol of it); returns the new end of the rows."""
    incidences = dereferenced(incidences_ref)
    normal = _row(normals, poly)
    offset = -_dot(normal, _row(points, offsets[poly]))
    n_vertices = vertices.shape[0]
    kept = lo
    for row in range(lo, hi):
        inside = True
        for k in range(3):
            code = incidences.codes[row, k]
            if code < 0:
                continue
            if code < n_vertices:
                inside = inside and _near_plane(_row(vertices, code), normal, offset, tol)
            else:
                for end in range(2):
                    inside = inside and _near_plane(_row(vertices, edges[code - n_vertices, end]), normal, offset, tol)
        if inside:
            continue
        incidences.node[kept] = incidences.node[row]
        incidences.kind[kept] = incidences.kind[row]
        for k in range(3):
            incidences.codes[kept, k] = incidences.codes[row, k]
        incidences.end[kept, 0] = incidences.end[row, 0]
        incidences.end[kept, 1] = incidences.end[row, 1]
        incidences.s[kept] = incidences.s[row]
        incidences.direction[kept] = incidences.direction[row]
        kept += 1
    return kept


@njit_leaf
def _flat_vertex_tau(vertices, normals, plane_offsets, vf_off, vf_face, v, start, u, tol, angle_tol):
    """Where the line start + tau u (u unit) meets vertex v when every face of v holds the line (a corner of a
    polygon lying flat on the floor, met along the floor: no face of it gives a vertex contact), else NaN."""
    if vf_off[v + 1] == vf_off[v]:
        return np.nan
    for i in range(vf_off[v], vf_off[v + 1]):
        n = _row(normals, vf_face[i])
        if abs(_dot(n, u)) > angle_tol or abs(_dot(n, start) + plane_offsets[vf_face[i]]) > tol:
            return np.nan
    offset = _minus(_row(vertices, v), start)
    tau = _dot(offset, u)
    across = _minus(offset, _scaled(u, tau))
    return tau if _dot(across, across) <= tol * tol else np.nan


@njit_leaf
def _generator_met(points, offsets, normals, plane_offsets, corner_vertex, corner_edge, vf_off, vf_face, ef_off,
                   ef_face, kind, gid, start, end, tol):  # fmt: skip
    """Whether the segment start-end (3,) touches generator (kind, gid): a vertex contact at that vertex or an
    edge contact along that edge on one of its own faces. Contacts are found polygon by polygon, so this is
    what casting the segment through the whole scene would find there, for a few polygons' work."""
    if kind == GEN_VERTEX:
        faces, lo, hi, wanted, corner_ids = vf_face, vf_off[gid], vf_off[gid + 1], CONTACT_VERTEX, corner_vertex
    else:
        faces, lo, hi, wanted, corner_ids = ef_face, ef_off[gid], ef_off[gid + 1], CONTACT_EDGE, corner_edge
    for i in range(lo, hi):
        poly = faces[i]
        contact, _, local = _polygon_contact(points, offsets, normals, plane_offsets, poly, start, end, tol)
        if contact == wanted and corner_ids[offsets[poly] + local] == gid:
            return True
    return False


_CHAIN_LENGTHS = 16.0
"""Tolerance lengths kept clear of a generator's contact by the early test of _pierced_between: contacts closer
than tol along the line join one group, so only a chain of that many contacts could link a face crossed
farther in to the generator's group."""


@njit_leaf
def _pierced_between(
    points, offsets, normals, plane_offsets,
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
    vertices, edges, gk, gid, ng, start, u, tol, c_poly, c_t, c_kind, c_local, stack, probe_start, probe_end,
):  # fmt: skip
    """Whether the line start + tau u (u unit) crosses a polygon's interior strictly between where it meets its
    first and its last generator (gk, gid: ng of them), beyond any doubt: such a line is rejected as blocked
    by the full cast, which this short cast spares (most candidates are). The generators' contacts are bounded
    from the geometry: a vertex within tol of its projection, an edge within tol over the sine of its angle
    to the line of the point nearest to it; both bounds are grown by _CHAIN_LENGTHS tolerance lengths. False
    when unsure (an edge nearly along the line, generators too close together). probe_start, probe_end: (3,)
    float64 scratch for the inner segment (this runs for every candidate)."""
    inner_lo = np.inf
    inner_hi = -np.inf
    for j in range(ng):
        if gk[j] == GEN_VERTEX:
            p = vertices[gid[j]]
            tau = (p[0] - start[0]) * u[0] + (p[1] - start[1]) * u[1] + (p[2] - start[2]) * u[2]
            spread = tol
        else:
            a = vertices[edges[gid[j], 0]]
            b = vertices[edges[gid[j], 1]]
            g0 = b[0] - a[0]
            g1 = b[1] - a[1]
            g2 = b[2] - a[2]
            n0 = u[1] * g2 - u[2] * g1
            n1 = u[2] * g0 - u[0] * g2
            n2 = u[0] * g1 - u[1] * g0
            nn = n0 * n0 + n1 * n1 + n2 * n2
            gg = g0 * g0 + g1 * g1 + g2 * g2
            if nn <= 1e-6 * gg:
                return False
            w0 = a[0] - start[0]
            w1 = a[1] - start[1]
            w2 = a[2] - start[2]
            tau = ((w1 * g2 - w2 * g1) * n0 + (w2 * g0 - w0 * g2) * n1 + (w0 * g1 - w1 * g0) * n2) / nn
            spread = tol * np.sqrt(gg / nn)
        inner_lo = min(inner_lo, tau + (spread + _CHAIN_LENGTHS * tol))
        inner_hi = max(inner_hi, tau - (spread + _CHAIN_LENGTHS * tol))
    if not inner_lo < inner_hi:
        return False
    for k in range(3):
        probe_start[k] = start[k] + inner_lo * u[k]
        probe_end[k] = start[k] + inner_hi * u[k]
    found = _gather_contacts(
        points, offsets, normals, plane_offsets,
        node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
        probe_start, probe_end, -1, -1, tol, True, False, c_poly, c_t, c_kind, c_local, stack,
    )  # fmt: skip
    return found < 0


@njit_leaf
def _seam_edges(points, offsets, normals, vertices, edge_unit, edges, corner_edge, c_poly, c_kind, c_local, lo, hi,
                tol, out):
    """How many scene edges contacts lo..hi-1 lie on, written to `out`, when all are edge contacts of one edge
    or of collinear edges of objects side by side (a seam: each edge bounds the arcs through it alike), but
    for faces met inside whose plane holds those edges (a box against a wall: its edge on the wall); else 0."""
    count = 0
    for i in range(lo, hi):
        if c_kind[i] == CONTACT_INTERIOR:
            continue
        if c_kind[i] != CONTACT_EDGE:
            return 0
        e = corner_edge[offsets[c_poly[i]] + c_local[i]]
        seen = False
        for k in range(count):
            if out[k] == e:
                seen = True
        if seen:
            continue
        if count > 0 and not _parallel_edges(vertices, edge_unit, edges, out[0], e, tol):
            return 0
        out[count] = e
        count += 1
    for i in range(lo, hi):
        if c_kind[i] != CONTACT_INTERIOR:
            continue
        normal = _row(normals, c_poly[i])
        corner = _row(points, offsets[c_poly[i]])
        for k in range(count):
            for end in range(2):
                if abs(_dot(normal, _minus(_row(vertices, edges[out[k], end]), corner))) > tol:
                    return 0
    return count


@njit_leaf
def _junction_line(edge_unit, edges, ve_off, ve_edge, edge_mask, gk, gid, gg, ng, u, angle_tol):
    """Whether the line along u (unit) through generators gk, gid (groups gg, ng of them) is a T-junction's line:
    a vertex met inside an edge generator (a box's corner on the edge of a box beside or under it) and another
    edge generator elsewhere, the line lying in the plane of that edge and a masked edge of the vertex. The
    pencils of that plane about the other edge end there (_pencils_at_junction); any other line through the
    vertex meeting the other edge meets the edge under the vertex as well, and is no node."""
    if ng != 3:
        return False
    v = -1
    for j in range(3):
        if gk[j] == GEN_VERTEX:
            if v >= 0:
                return False
            v = j
    if v < 0:
        return False
    extra = -1
    for k in range(3):
        if k != v and gg[k] == gg[v]:
            if extra >= 0:
                return False
            extra = k
    if extra < 0 or edges[gid[extra], 0] == gid[v] or edges[gid[extra], 1] == gid[v]:
        return False
    along = _edge_direction(edge_unit, edges, gid[extra], -1)
    for slot in range(ve_off[gid[v]], ve_off[gid[v] + 1]):
        e_v = ve_edge[slot]
        if not edge_mask[e_v]:
            continue
        normal = _cross(along, _edge_direction(edge_unit, edges, e_v, -1))
        size = np.sqrt(_dot(normal, normal))
        if size > angle_tol and abs(_dot(normal, u)) <= angle_tol * size:
            return True
    return False


@njit_leaf
def _same_arc(incidences_ref, a, b):
    """Whether incidence rows a and b have one key: arc kind, generators and end faces."""
    incidences = dereferenced(incidences_ref)
    if incidences.kind[a] != incidences.kind[b]:
        return False
    for k in range(3):
        if incidences.codes[a, k] != incidences.codes[b, k]:
            return False
    return incidences.end[a, 0] == incidences.end[b, 0] and incidences.end[a, 1] == incidences.end[b, 1]


@njit_leaf
def _candidate_rows(cand_vertices, cand_edges, ve_off, c):
    """Most incidence rows candidate c records but those of _arcs_off_edge and _pencils_at_junction."""
    rows = 0
    for k in range(2):
        v = cand_vertices[c, k]
        if v >= 0:
            rows += ve_off[v + 1] - ve_off[v]
    for k in range(4):
        if cand_edges[c, k] >= 0:
            rows += 2
    if cand_vertices[c, 0] >= 0:
        # arcs of a dropped vertex with an edge beyond: 2 sides x up to 2 vertices x 2 directions; of a
        # vertex replaced by an edge through it: up to 2 vertices x 2 directions
        rows += 12
    if cand_vertices[c, 1] >= 0:
        # EEE arcs of two vertices and an edge beyond: 2 sides x an edge of each vertex
        v = cand_vertices[c, 0]
        w = cand_vertices[c, 1]
        rows += 2 * (ve_off[v + 1] - ve_off[v]) * (ve_off[w + 1] - ve_off[w])
    return rows


@njit(cache=True, nogil=True)
def _validate_chunk(
    geometry, plane_offsets, corner_vertex, bvh_arrays, ve_off, ve_edge, edge_mask,
    cand_kind, cand_vertices, cand_edges, cand_origin, cand_direction, lo, hi, first_rows=-1,
):  # fmt: skip
    """The nodes and incidences of the candidates, their lines clipped to the box lo..hi (see _validate_slice),
    in candidate order. The incidence rows start at a bound of what most candidates write (first_rows, when >= 0:
    that many instead) and grow when a candidate needs more: it is then validated again (_validate_from)."""
    n_cand = cand_kind.shape[0]
    bound = 0
    for c in range(n_cand):
        bound += _candidate_rows(cand_vertices, cand_edges, ve_off, c)
    if first_rows >= 0:
        bound = first_rows
    node_cand = np.empty(n_cand, dtype=np.int64)
    node_kind = np.empty(n_cand, dtype=np.int8)
    node_gkind = np.zeros((n_cand, 4), dtype=np.int8)
    node_gid = np.full((n_cand, 4), -1, dtype=np.int64)
    node_start = np.empty((n_cand, 3))
    node_dir = np.empty((n_cand, 3))
    node_reach = np.empty((n_cand, 2))
    node_end = np.empty((n_cand, 2), dtype=np.int64)
    incidences = _Incidences(
        np.empty(bound, dtype=np.int64), np.empty(bound, dtype=np.int8), np.empty((bound, 3), dtype=np.int64),
        np.empty((bound, 2), dtype=np.int64), np.empty(bound), np.empty(bound, dtype=np.int8),
    )  # fmt: skip
    counters = np.zeros(N_COUNTERS, dtype=np.int64)
    vf_off = geometry.vf_off
    ef_off = geometry.ef_off
    max_faces = 0
    for v in range(vf_off.shape[0] - 1):
        max_faces = max(max_faces, vf_off[v + 1] - vf_off[v])
    # the faces around a crossing of two edges (see _relaxed_arc) stand in for a vertex's
    for e in range(ef_off.shape[0] - 1):
        max_faces = max(max_faces, 2 * (ef_off[e + 1] - ef_off[e]))
    # a line meets each polygon once, and a flat vertex of each generator adds a group: buffers that never fill.
    # Grown in the loop they were new arrays every candidate carried, a reference count on each of them per candidate
    capacity = geometry.offsets.shape[0] - 1 + 4
    buffers = _line_buffers(capacity)
    retained = (np.zeros(3, dtype=np.int8), np.zeros(3, dtype=np.int64), np.zeros(3, dtype=np.int64),
                np.full(3, -1, dtype=np.int64))  # fmt: skip
    scratch = _new_scratch(capacity + max_faces)
    nodes = (node_cand, node_kind, node_gkind, node_gid, node_start, node_dir, node_reach, node_end)
    c = 0
    n_nodes = 0
    n_inc = 0
    while c < n_cand:
        c, n_nodes, n_inc, wanted = _validate_from(
            c, n_nodes, n_inc, geometry, plane_offsets, corner_vertex, bvh_arrays, ve_off, ve_edge, edge_mask,
            cand_vertices, cand_edges, cand_origin, cand_direction, lo, hi, nodes, incidences, buffers, retained,
            scratch, counters,
        )  # fmt: skip
        if c < n_cand:
            incidences = _grown(incidences, n_inc, wanted)
    return (
        node_cand[:n_nodes], node_kind[:n_nodes], node_gkind[:n_nodes], node_gid[:n_nodes], node_start[:n_nodes],
        node_dir[:n_nodes], node_reach[:n_nodes], node_end[:n_nodes],
        incidences.node[:n_inc], incidences.kind[:n_inc], incidences.codes[:n_inc], incidences.end[:n_inc],
        incidences.s[:n_inc], incidences.direction[:n_inc], counters,
    )  # fmt: skip


@njit(cache=True)
def _validate_from(
    c_from, n_nodes, n_inc, geometry, plane_offsets, corner_vertex, bvh_arrays, ve_off, ve_edge, edge_mask,
    cand_vertices, cand_edges, cand_origin, cand_direction, lo, hi, nodes, incidences, buffers, retained, scratch,
    counters,
):  # fmt: skip
    """Validate candidates c_from... (see _validate_chunk) into the node rows from n_nodes and the incidence rows
    from n_inc, until every candidate is done or a candidate needs more incidence rows than there are. Returns
    (the next candidate, node rows, incidence rows, rows wanted): a candidate that ran out is the next one, its
    rows count for nothing, and the rows wanted are at least as many as it asked for; the number of candidates
    when all are done.

    The incidences are never replaced here: an array variable replaced in the loop (a grown buffer) is one the
    loop carries from candidate to candidate, at a reference count per array per candidate. buffers (the line's
    contact and group arrays, _line_buffers), retained ((3,) arrays r_kind int8, r_id, r_group, r_pin int64) and
    scratch (_Scratch) are work arrays the caller keeps for all calls."""
    (points, offsets, normals, areas, vertices, edges, edge_unit, vf_off, vf_face, vf_corner, ef_off, ef_face, ef_local,
     corner_edge, face_group, object_ids, element_solid, face_region, split_edge, diag, tol,
     angle_tol) = geometry  # fmt: skip
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max = bvh_arrays
    node_cand, node_kind, node_gkind, node_gid, node_start, node_dir, node_reach, node_end = nodes
    n_cand = cand_vertices.shape[0]
    rows = incidences.node.shape[0]
    c_poly, c_t, c_kind, c_local, g_lo, g_hi, g_tau, sl_poly, sl_a, sl_b = buffers
    extras = np.empty(c_poly.shape[0], dtype=np.int64)
    stack = np.empty(STACK_SIZE, dtype=np.int64)
    arc_start = scratch.arc_start
    arc_len = scratch.arc_len
    bounds = scratch.bounds
    segment_start = np.empty(3)
    probe_start = np.empty(3)
    probe_end = np.empty(3)
    segment_end = np.empty(3)
    segment_direction = np.empty(3)
    gk = np.zeros(4, dtype=np.int8)
    gid = np.zeros(4, dtype=np.int64)
    gg = np.zeros(4, dtype=np.int64)
    flat = np.zeros(4, dtype=np.bool_)
    r_kind, r_id, r_group, r_pin = retained
    # the named tuples the arc kernels share, handed to them by address (core.jit.by_reference): arguments, so
    # their arrays outlive the addresses
    geometry_ref = by_reference(geometry)
    retained_ref = by_reference(retained)
    scratch_ref = by_reference(scratch)
    incidences_ref = by_reference(incidences)

    for c in range(c_from, n_cand):
        nodes_before = n_nodes
        rows_before = n_inc
        # the pencils of a vertex on another object's edge (an edge of it x 2 pivots) are rare: the rows left
        # for them are checked here instead of bounded above
        need = _candidate_rows(cand_vertices, cand_edges, ve_off, c)
        for k in range(2):
            v = cand_vertices[c, k]
            if v >= 0:
                need += 2 * (ve_off[v + 1] - ve_off[v])
        if n_inc + need > rows:
            return c, n_nodes, n_inc, n_inc + need
        ng = 0
        for k in range(2):
            if cand_vertices[c, k] >= 0:
                gk[ng] = GEN_VERTEX
                gid[ng] = cand_vertices[c, k]
                ng += 1
        for k in range(4):
            if cand_edges[c, k] >= 0:
                gk[ng] = GEN_EDGE
                gid[ng] = cand_edges[c, k]
                ng += 1
        given = _row(cand_direction, c)
        u = _over(given, np.sqrt(_dot(given, given)))
        origin = _row(cand_origin, c)
        t0, t1 = _clip_line(origin, u, lo, hi)
        if not t0 < t1:
            counters[REJECT_MISSING] += 1
            continue
        start = _along(origin, t0, u)
        end = _along(origin, t1, u)
        for k in range(3):
            segment_start[k] = start[k]
            segment_end[k] = end[k]
            segment_direction[k] = u[k]
        if _pierced_between(
            points, offsets, normals, plane_offsets,
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
            vertices, edges, gk, gid, ng, segment_start, segment_direction, tol, c_poly, c_t, c_kind, c_local, stack,
            probe_start, probe_end,
        ):  # fmt: skip
            counters[REJECT_BLOCKED] += 1
            continue
        # a line that misses a generator is rejected before the cast through the scene
        missing = False
        for j in range(ng):
            if not _generator_met(
                points, offsets, normals, plane_offsets, corner_vertex, corner_edge, vf_off, vf_face, ef_off, ef_face,
                gk[j], gid[j], segment_start, segment_end, tol,
            ) and not (gk[j] == GEN_VERTEX and np.isfinite(_flat_vertex_tau(
                vertices, normals, plane_offsets, vf_off, vf_face, gid[j], segment_start, u, tol, angle_tol
            ))):  # fmt: skip
                missing = True
                break
        if missing:
            counters[REJECT_MISSING] += 1
            continue
        length = t1 - t0
        found = _gather_contacts(
            points, offsets, normals, plane_offsets,
            node_min, node_max, node_child, node_first, node_count, order, box_min, box_max,
            segment_start, segment_end, -1, -1, tol, False, False, c_poly, c_t, c_kind, c_local, stack,
        )  # fmt: skip
        _sort_contacts(c_poly, c_t, c_kind, c_local, found, tol / length)
        # lines lying in a face plane slide over it: an interval, not a point; kept apart from the point groups
        n_sliding = 0
        kept = 0
        for i in range(found):
            if c_kind[i] == CONTACT_SLIDING:
                tau_in, tau_out = _sliding_interval(points, offsets, normals, c_poly[i], start, u, length, tol)
                if tau_in <= tau_out:
                    sl_poly[n_sliding] = c_poly[i]
                    sl_a[n_sliding] = tau_in
                    sl_b[n_sliding] = tau_out
                    n_sliding += 1
                continue
            c_poly[kept] = c_poly[i]
            c_t[kept] = c_t[i]
            c_kind[kept] = c_kind[i]
            c_local[kept] = c_local[i]
            kept += 1
        found = kept
        n_groups = 0
        for i in range(found):
            tau = c_t[i] * length
            if n_groups == 0 or tau - c_t[i - 1] * length > tol:
                g_lo[n_groups] = i
                g_tau[n_groups] = tau
                n_groups += 1
            g_hi[n_groups - 1] = i + 1

        # each generator's group: the last one holding a contact with it (one pass over the contacts)
        for j in range(ng):
            gg[j] = -1
        for g in range(n_groups):
            for i in range(g_lo[g], g_hi[g]):
                kind = c_kind[i]
                if kind != CONTACT_VERTEX and kind != CONTACT_EDGE:
                    continue
                base = offsets[c_poly[i]] + c_local[i]
                element = corner_vertex[base] if kind == CONTACT_VERTEX else corner_edge[base]
                wanted = GEN_VERTEX if kind == CONTACT_VERTEX else GEN_EDGE
                for j in range(ng):
                    if gk[j] == wanted and gid[j] == element:
                        gg[j] = g
        # a flat polygon's corner met along its plane (a rug's, by lines along the floor) gives no contact, yet the
        # arcs of its lines leaving the floor end there: a group of its own at its point, without contacts (the
        # vertex's faces stand for them where its arcs are relaxed)
        for j in range(ng):
            flat[j] = False
        for j in range(ng):
            if gg[j] >= 0 or gk[j] != GEN_VERTEX or n_groups == g_tau.shape[0]:
                continue
            tau = _flat_vertex_tau(vertices, normals, plane_offsets, vf_off, vf_face, gid[j], start, u, tol, angle_tol)
            if not np.isfinite(tau):
                continue
            at = 0
            while at < n_groups and g_tau[at] < tau - tol:
                at += 1
            flat[j] = True
            if at < n_groups and g_tau[at] <= tau + tol:
                gg[j] = at
                continue
            for g in range(n_groups, at, -1):
                g_lo[g] = g_lo[g - 1]
                g_hi[g] = g_hi[g - 1]
                g_tau[g] = g_tau[g - 1]
            g_lo[at] = g_hi[at - 1] if at > 0 else 0
            g_hi[at] = g_lo[at]
            g_tau[at] = tau
            n_groups += 1
            for k in range(ng):
                if gg[k] >= at:
                    gg[k] += 1
            gg[j] = at
        missing = False
        for j in range(ng):
            if gg[j] < 0:
                missing = True
        if missing:
            counters[REJECT_MISSING] += 1
            continue
        # two edges met at one point cross there (objects in contact: a box's bottom edge across the top edge
        # of the box it stands on): that point bounds the arcs along either edge like a vertex, so the line
        # is a node; a vertex on an edge generator, or two vertices at one point, stay rejected but on the line
        # of a T-junction's pencils (_junction_line), which ends those pencils only
        coincident = False
        for j in range(ng):
            for k in range(j + 1, ng):
                if gg[j] == gg[k] and not (gk[j] == GEN_EDGE and gk[k] == GEN_EDGE):
                    coincident = True
        junction = coincident and _junction_line(edge_unit, edges, ve_off, ve_edge, edge_mask, gk, gid, gg, ng, u,
                                                 angle_tol)  # fmt: skip
        if coincident and not junction:
            counters[REJECT_COINCIDENT] += 1
            continue
        # generators in line order
        for j in range(1, ng):
            k = j
            while k > 0 and gg[k - 1] > gg[k]:
                gg[k - 1], gg[k] = gg[k], gg[k - 1]
                flat[k - 1], flat[k] = flat[k], flat[k - 1]
                gk[k - 1], gk[k] = gk[k], gk[k - 1]
                gid[k - 1], gid[k] = gid[k], gid[k - 1]
                k -= 1
        first = gg[0]
        last = gg[ng - 1]
        # a contact between the outer generators that blocks rejects the line; one that does not (an extra
        # vertex or edge grazed: three aligned vertices, parallel edges of one face) leaves a degenerate node
        # of the generators asked for, its arcs decided to first order; nodes on one line are merged later
        # (core.skeleton.graph.coincident_nodes): the simplest configuration of seed 000 section 2.2
        blocked = False
        for g in range(first + 1, last):
            if _group_blocked(
                points, offsets, normals, c_poly, c_kind, c_local, g_lo[g], g_hi[g], u, angle_tol,
                arc_start, arc_len, bounds,
            ):  # fmt: skip
                blocked = True
                break
        # a box's opposite corners: the line between them runs inside the box (its space diagonal, no node; the
        # swaths through the corners along it are interior ones, rejected where they start)
        if ng == 2 and _through_own_solid(gk[0], gid[0], gk[1], gid[1], element_solid, vf_off, vf_face, ef_off,
                                          ef_face):  # fmt: skip
            blocked = True
        if blocked:
            counters[REJECT_BLOCKED] += 1
            continue

        node = n_nodes
        node_rows = n_inc
        n_nodes += 1
        node_cand[node] = c
        if ng == 2:
            node_kind[node] = NODE_VV
        elif ng == 3 and gk[0] == GEN_EDGE and gk[1] == GEN_EDGE and gk[2] == GEN_EDGE:
            node_kind[node] = NODE_FXE
        elif ng == 3:
            node_kind[node] = NODE_EVE if gk[1] == GEN_VERTEX else NODE_VEE
        else:
            node_kind[node] = NODE_E4
            for j in range(ng):
                for k in range(j + 1, ng):
                    if _shared_face(ef_off, ef_face, gid[j], gid[k]):
                        node_kind[node] = NODE_EFE if j == 1 and k == 2 else NODE_FEE
        for j in range(ng):
            node_gkind[node, j] = gk[j]
            node_gid[node, j] = gid[j]
        for k in range(3):
            node_start[node, k] = start[k]
            node_dir[node, k] = u[k]
        for side in range(2):
            outer = first if side == 0 else last
            node_end[node, side] = END_FREE
            node_reach[node, side] = -np.inf if side == 0 else np.inf
            if _group_blocked(
                points, offsets, normals, c_poly, c_kind, c_local, g_lo[outer], g_hi[outer], u, angle_tol,
                arc_start, arc_len, bounds,
            ):  # fmt: skip
                node_end[node, side] = END_TERMINAL
                node_reach[node, side] = g_tau[outer]
                continue
            g = outer - 1 if side == 0 else outer + 1
            while 0 <= g < n_groups:
                if _group_blocked(
                    points, offsets, normals, c_poly, c_kind, c_local, g_lo[g], g_hi[g], u, angle_tol,
                    arc_start, arc_len, bounds,
                ):  # fmt: skip
                    node_end[node, side] = face_group[c_poly[g_lo[g]]]
                    node_reach[node, side] = g_tau[g]
                    break
                g = g - 1 if side == 0 else g + 1

        f1, f2 = _perpendicular_frame(u)
        line = _Line(c_poly, c_kind, c_local, g_lo, g_hi, g_tau, n_groups, sl_poly, sl_a, sl_b, n_sliding, start, u,
                     f1, f2)  # fmt: skip
        line_ref = by_reference(line)

        # a vertex generator lying on another element's edge (a box's corner on the room's floor edge, on the
        # top edge of the box it stands on, on the collinear edge of a box beside it): the arcs along that edge
        # through the vertex's point start or end here as well, so the vertex is replaced by the edge, sliding
        # either way. Each such edge: the vertex may lie on a seam of collinear edges of boxes side by side
        for j in range(ng):
            if ng > 3 or gk[j] != GEN_VERTEX:
                continue
            g = gg[j]
            for i in range(g_lo[g], g_hi[g]):
                if c_kind[i] != CONTACT_EDGE:
                    continue
                extra = corner_edge[offsets[c_poly[i]] + c_local[i]]
                if not edge_mask[extra] or edges[extra, 0] == gid[j] or edges[extra, 1] == gid[j] or \
                        _met_before(line_ref, corner_edge, offsets, g, i, CONTACT_EDGE, extra):  # fmt: skip
                    continue
                # the relaxed arcs and the junction's pencils (an edge of the vertex by a pivot edge)
                need = 2 + 3 * (ve_off[gid[j] + 1] - ve_off[gid[j]])
                if n_inc + need > rows:
                    return c, nodes_before, rows_before, n_inc + need
                n_inc = _vertex_replaced_by_edge(
                    geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask, ve_off,
                    ve_edge, j, extra,
                    gk, gid, gg, ng,
                )  # fmt: skip
        # the other swaths through a junction's line (the lines through its vertex meeting the other edge) pass
        # it: no node ends them there, but the pencils of a corner of another object at the vertex's point
        # (_pencils_at_shared_corner) do: the nodes through either vertex are this line
        if junction:
            for j in range(ng):
                if gk[j] == GEN_VERTEX and _other_corner_at(line_ref, corner_vertex, offsets, gid[j], gg[j]):
                    n_inc = _pencils_at_shared_corner(
                        geometry_ref, corner_vertex, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                        edge_mask, ve_off, ve_edge, gid[j], gg[j], gk, gid, gg, ng,
                    )  # fmt: skip
                    if n_inc < 0:
                        return c, nodes_before, rows_before, 2 * rows
            continue

        # a line through a vertex generator running along one of its edges (a box's top edge) that another
        # object's edge crosses on that edge (the bottom edge of a box stacked across it): see _arcs_off_edge;
        # in the plane of an edge of it and an edge of another object's corner at its point: see
        # _pencils_at_shared_corner; or along another object's edge holding the vertex: see
        # _pencils_to_vertex_on_edge
        for j in range(ng):
            if gk[j] != GEN_VERTEX:
                continue
            v = gid[j]
            for slot in range(ve_off[v], ve_off[v + 1]):
                e_v = ve_edge[slot]
                w = edges[e_v, 1] if edges[e_v, 0] == v else edges[e_v, 0]
                offset = _minus(_row(vertices, w), start)
                tau_w = _dot(offset, u)
                across = _minus(offset, _scaled(u, tau_w))
                if _dot(across, across) <= tol * tol:
                    n_inc = _arcs_off_edge(
                        geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask, v,
                        e_v, g_tau[gg[j]], gg[j], tau_w, gk, gid, ng,
                    )  # fmt: skip
                    if n_inc < 0:
                        return c, nodes_before, rows_before, 2 * rows
            # a quick test first: another vertex is met at v's point at few corners
            if _other_corner_at(line_ref, corner_vertex, offsets, v, gg[j]):
                n_inc = _pencils_at_shared_corner(
                    geometry_ref, corner_vertex, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node,
                    edge_mask, ve_off, ve_edge, v, gg[j], gk, gid, gg, ng,
                )  # fmt: skip
                if n_inc < 0:
                    return c, nodes_before, rows_before, 2 * rows
            # lines sliding over a face (along the floor) are many, edges of it around v's point few: a quick test
            # first
            if n_sliding > 0 and _slides_along_edge_through(geometry_ref, line_ref, edge_mask, v, g_tau[gg[j]]):
                n_inc = _pencils_to_vertex_on_edge(
                    geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask, ve_off,
                    ve_edge, v, g_tau[gg[j]], gg[j],
                )  # fmt: skip
                if n_inc < 0:
                    return c, nodes_before, rows_before, 2 * rows

        # a line through a vertex generator that also meets an edge beyond its outer generators (a floor edge
        # reached along the floor, a box edge grazed on the way) is where the lines through the other
        # generators and that edge stop meeting the vertex: drop the vertex, keep the edge (the arcs of such
        # over-determined lines, simplest configuration of seed 000 section 2.2). Every such edge up to where
        # the line stops: past one grazed (a table's near leg), the lines meeting the next (its far leg) end here
        for side in range(2):
            if ng > 3:
                break
            g = first - 1 if side == 0 else last + 1
            while 0 <= g < n_groups:
                n_extra = _seam_edges(points, offsets, normals, vertices, edge_unit, edges, corner_edge, c_poly,
                                      c_kind, c_local, g_lo[g], g_hi[g], tol, extras)  # fmt: skip
                # the edge lies on a face the line ends on (a box's edge against the wall)
                on_face = False
                if n_extra > 0:
                    for i in range(g_lo[g], g_hi[g]):
                        on_face = on_face or c_kind[i] == CONTACT_INTERIOR
                for x in range(n_extra):
                    extra = extras[x]
                    if not edge_mask[extra]:
                        continue
                    # the rows bounded per candidate cover one edge; a seam of several needs more
                    need = 4
                    if ng == 2:
                        need += (ve_off[gid[0] + 1] - ve_off[gid[0]]) * (ve_off[gid[1] + 1] - ve_off[gid[1]])
                    if n_inc + need > rows:
                        return c, nodes_before, rows_before, n_inc + need
                    for j in range(ng):
                        if gk[j] != GEN_VERTEX:
                            continue
                        n_retained = 0
                        norm = -1
                        for k in range(ng + 1):
                            if k == j:
                                continue
                            r_kind[n_retained] = gk[k] if k < ng else GEN_EDGE
                            r_id[n_retained] = gid[k] if k < ng else extra
                            r_group[n_retained] = gg[k] if k < ng else g
                            if r_kind[n_retained] == GEN_EDGE and (norm < 0 or r_id[n_retained] < r_id[norm]):
                                norm = n_retained
                            n_retained += 1
                        norm_dir = _edge_direction(edge_unit, edges, r_id[norm], -1)
                        first_row = n_inc
                        n_inc = _relaxed_arc(
                            geometry_ref, line_ref, retained_ref, n_retained, norm, norm_dir, 1.0, True, scratch_ref,
                            incidences_ref, n_inc, node,
                        )  # fmt: skip
                        # the lines ending on a face at an edge lying on it, going on past this line both ways alike:
                        # the arc passes it (a node inside the arc, see Skeleton._arc_cuts); it ends the arc only where
                        # one way is no arc (lines going on between touching objects). So does a dropped flat polygon's
                        # corner (a rug's, lines along the floor): the lines slide over that polygon either way
                        if (on_face or flat[j]) and n_inc == first_row + 2 and \
                                _same_arc(incidences_ref, first_row, first_row + 1):  # fmt: skip
                            n_inc = first_row
                    # two vertices and the edge: the EEE swaths through that edge and an edge of each vertex end here as
                    # well (the contact on either edge reaches its vertex at once)
                    if ng == 2:
                        n_inc = _swaths_leaving_both_vertices(
                            geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask,
                            ve_off, ve_edge, gid,
                            gg, extra, g,
                        )  # fmt: skip
                if _group_blocked(
                    points, offsets, normals, c_poly, c_kind, c_local, g_lo[g], g_hi[g], u, angle_tol,
                    arc_start, arc_len, bounds,
                ):  # fmt: skip
                    break
                g = g - 1 if side == 0 else g + 1
        # so do they where the edge is grazed between the two vertices (three generators on one line: a box's
        # corner, the top edge of a box and the corner of a box floating beyond, aligned)
        if ng == 2:
            for g in range(first + 1, last):
                n_extra = _seam_edges(points, offsets, normals, vertices, edge_unit, edges, corner_edge, c_poly,
                                      c_kind, c_local, g_lo[g], g_hi[g], tol, extras)  # fmt: skip
                for x in range(n_extra):
                    if not edge_mask[extras[x]]:
                        continue
                    need = (ve_off[gid[0] + 1] - ve_off[gid[0]]) * (ve_off[gid[1] + 1] - ve_off[gid[1]])
                    if n_inc + need > rows:
                        return c, nodes_before, rows_before, n_inc + need
                    n_inc = _swaths_leaving_both_vertices(
                        geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask,
                        ve_off, ve_edge, gid,
                        gg, extras[x], g,
                    )  # fmt: skip
                # or a third corner grazed there (a box's corner on a seam, a box's top corner and the room's
                # corner, aligned): the EEE swaths through an edge at each corner
                for i in range(g_lo[g], g_hi[g]):
                    if c_kind[i] != CONTACT_VERTEX:
                        continue
                    corner = corner_vertex[offsets[c_poly[i]] + c_local[i]]
                    if not _met_before(line_ref, corner_vertex, offsets, g, i, CONTACT_VERTEX, corner):
                        n_inc = _swaths_leaving_three_corners(
                            geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, edge_mask,
                            ve_off, ve_edge, gid, gg, corner, g,
                        )  # fmt: skip
                        if n_inc < 0:
                            return c, nodes_before, rows_before, 2 * rows

        # an FXE node ends the EEE swath of the lines through its crossing point meeting its third edge: all
        # three generators are kept and the contact on the third edge slides either way
        if node_kind[node] == NODE_FXE:
            lone = 0 if gg[0] != gg[1] else 2
            for k in range(3):
                r_kind[k] = GEN_EDGE
                r_id[k] = gid[k]
                r_group[k] = gg[k]
            norm_dir = _edge_direction(edge_unit, edges, gid[lone], -1)
            n_inc = _relaxed_arc(
                geometry_ref, line_ref, retained_ref, 3, lone, norm_dir, 1.0, True, scratch_ref, incidences_ref,
                n_inc, node
            )
            # and the pencil of the plane about the third edge's point, its contacts sliding off the crossing
            pair_low = 1 if lone == 0 else 0
            if gid[3 - lone - pair_low] < gid[pair_low]:
                pair_low = 3 - lone - pair_low
            norm_dir = _edge_direction(edge_unit, edges, gid[pair_low], -1)
            n_inc = _relaxed_arc(
                geometry_ref, line_ref, retained_ref, 3, pair_low, norm_dir, 1.0, True, scratch_ref, incidences_ref,
                n_inc, node
            )
            n_inc = _pencils_over_plane_edges(
                geometry_ref, line_ref, retained_ref, scratch_ref, incidences_ref, n_inc, node, gid, gg, lone
            )
            if n_inc < 0:
                return c, nodes_before, rows_before, 2 * rows

        # relax one generator at a time: an edge in both directions, a vertex along each of its edges
        for j in range(ng):
            if gk[j] == GEN_EDGE:
                n_retained = 0
                norm = -1
                for k in range(ng):
                    if k == j:
                        continue
                    r_kind[n_retained] = gk[k]
                    r_id[n_retained] = gid[k]
                    r_group[n_retained] = gg[k]
                    if gk[k] == GEN_EDGE and (norm < 0 or gid[k] < r_id[norm]):
                        norm = n_retained
                    n_retained += 1
                if norm < 0:
                    continue
                norm_dir = _edge_direction(edge_unit, edges, r_id[norm], -1)
                n_inc = _relaxed_arc(
                    geometry_ref, line_ref, retained_ref, n_retained, norm, norm_dir, 1.0, True, scratch_ref,
                    incidences_ref, n_inc, node
                )
            else:
                v = gid[j]
                for slot in range(ve_off[v], ve_off[v + 1]):
                    e = ve_edge[slot]
                    if not edge_mask[e]:
                        continue
                    taken = False
                    for k in range(ng):
                        if gk[k] == GEN_EDGE and gid[k] == e:
                            taken = True
                    if taken:
                        continue
                    n_retained = 0
                    norm = -1
                    for k in range(ng):
                        r_kind[n_retained] = GEN_EDGE if k == j else gk[k]
                        r_id[n_retained] = e if k == j else gid[k]
                        r_group[n_retained] = gg[k]
                        if k == j:
                            norm = n_retained
                        n_retained += 1
                    norm_dir = _edge_direction(edge_unit, edges, e, v)
                    n_inc = _relaxed_arc(
                        geometry_ref, line_ref, retained_ref, n_retained, norm, norm_dir, 1.0, False, scratch_ref,
                        incidences_ref, n_inc, node
                    )
        # at a flat polygon's corner, the arcs whose lines all lie in its plane slide over the polygon: it is no
        # event of theirs, and the lines through its other corners do not end them
        for j in range(ng):
            if flat[j]:
                n_inc = _without_arcs_in_plane(
                    incidences_ref, node_rows, n_inc, points, offsets, normals, vertices, edges,
                    vf_face[vf_off[gid[j]]], tol,
                )  # fmt: skip
                break
    return n_cand, n_nodes, n_inc, 0


def validate_candidates(scene, topology, bvh, candidates, edge_mask, workers: int = WORKERS, element_solid=None,
                        face_region=None):  # fmt: skip
    """Cast every candidate line; return (NodeChunk, IncidenceChunk, counters (N_COUNTERS,) int64).

    scene: core.scene.Scene; topology: core.skeleton.topology.Topology; bvh: core.bvh.BVH of the scene;
    candidates: NodeCandidates; edge_mask (E,) bool: the edges a vertex generator may slide along.
    workers: threads casting consecutive slices of the candidates at once (the kernel releases the GIL); the
    result is the same for any number, in candidate order. element_solid: element_solids(scene, topology), and
    face_region: flat_regions(scene), for a caller validating many chunks of one scene (computed here when None).
    """
    n = len(candidates.kind)
    if element_solid is None:
        element_solid = element_solids(scene, topology)
    if face_region is None:
        face_region = flat_regions(scene)
    # faces of one flat region are looked for only from edges with a face in a region of several
    shared_region = np.bincount(face_region, minlength=scene.n_polygons)[face_region] > 1
    split_edge = _any_of(shared_region, scene.edge_face_offsets, scene.edge_faces)
    parts = max(1, min(_SLICES_PER_WORKER * int(workers), n // _MIN_SLICE))
    bounds = np.linspace(0, n, parts + 1).astype(np.int64)
    slices = [(int(lo), int(hi)) for lo, hi in zip(bounds[:-1], bounds[1:], strict=True)]
    if parts == 1:
        results = [
            _validate_slice(scene, topology, bvh, candidates, edge_mask, element_solid, face_region, split_edge, 0, n)
        ]
    else:
        with ThreadPoolExecutor(min(parts, int(workers))) as pool:
            results = list(
                pool.map(
                    lambda b: _validate_slice(
                        scene, topology, bvh, candidates, edge_mask, element_solid, face_region, split_edge, *b
                    ),
                    slices,
                )
            )
    if len(results) == 1:
        return results[0]
    node_parts, incidence_parts, counters = zip(*results, strict=True)
    first_node = np.cumsum([0] + [len(nodes) for nodes in node_parts[:-1]])
    incidence_parts = [
        IncidenceChunk(p.node + offset, p.kind, p.codes, p.end, p.s, p.direction)
        for p, offset in zip(incidence_parts, first_node, strict=True)
    ]
    nodes = _stacked(NodeChunk, node_parts)
    incidences = _stacked(IncidenceChunk, incidence_parts)
    return nodes, incidences, np.sum(counters, axis=0)


def _stacked(chunk_type, parts):
    """One chunk_type (NodeChunk or IncidenceChunk) holding the rows of `parts` in order."""
    columns = [vars(part).values() for part in parts]
    return chunk_type(*(np.concatenate(arrays) for arrays in zip(*columns, strict=True)))


def element_solids(scene, topology) -> np.ndarray:
    """(V + E,) int64 for each vertex, then each edge, the object all its faces belong to when that object is a
    closed convex solid (every edge between two of its faces, no vertex of it in front of one of its face planes
    beyond tol.length, outward normals: Scene.solid), else -1. Inside such an object, a segment between two
    points of its surface lies on a common face of both or in the interior."""
    object_ids = np.asarray(scene.object_ids, dtype=np.int64)
    result = np.full(len(object_ids), -1, dtype=np.int64)
    counts = np.diff(scene.edge_face_offsets)
    owner = object_ids[scene.edge_faces]
    first = scene.edge_face_offsets[:-1]
    open_edge = (counts != 2) | (owner[first] != owner[np.minimum(first + 1, len(owner) - 1)])
    open_object = np.zeros(int(object_ids.max()) + 1, dtype=bool)
    open_object[owner[np.repeat(open_edge, counts)]] = True
    order = np.argsort(object_ids, kind="stable")
    bounds = np.searchsorted(object_ids[order], np.arange(len(open_object) + 1))
    for obj in np.flatnonzero(~open_object):
        polygons = order[bounds[obj] : bounds[obj + 1]]
        if len(polygons) < 4 or not scene.solid[polygons].all():
            continue
        corners = np.concatenate([scene.polygon_vertices(int(p)) for p in polygons])
        heights = scene.vertices[corners] @ scene.normals[polygons].T + scene.plane_offsets[polygons]
        if heights.max() <= scene.tol.length:
            result[polygons] = obj
    return np.concatenate([
        _common_value(result, topology.vertex_face_offsets, topology.vertex_faces),
        _common_value(result, scene.edge_face_offsets, scene.edge_faces),
    ])  # fmt: skip


def _common_value(values: np.ndarray, offsets: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(K,) int64 for each element of the CSR element -> faces (offsets (K + 1,), faces), the value (values (F,)
    int64) all its faces share, else -1 (and -1 for an element without faces)."""
    counts = np.diff(offsets)
    owned = values[faces]
    element = np.repeat(np.arange(len(counts)), counts)
    low = np.full(len(counts), np.iinfo(np.int64).max)
    high = np.full(len(counts), -1)
    np.minimum.at(low, element, owned)
    np.maximum.at(high, element, owned)
    return np.where((counts > 0) & (low == high), high, -1).astype(np.int64)


def flat_regions(scene) -> np.ndarray:
    """(F,) int64 for each face its flat region: faces of different objects lying in one plane (either way round,
    every corner within tol.length of the other's plane) and sharing a piece of boundary longer than tol.length
    (an edge of each on one line, overlapping) are joined, and so on (boxes stacked flush: their front faces; a
    box beside another of its height: their tops; the top of a box and the bottom of one stacked on it). The
    label is a connected component's; a face joined to none has a region of its own."""
    n = scene.n_polygons
    normals = scene.normals
    along = np.argmax(np.abs(normals), axis=1)
    sign = np.where(normals[np.arange(n), along] >= 0.0, 1.0, -1.0)
    planes = np.hstack([normals * (sign * scene.tol.scale)[:, None], (scene.plane_offsets * sign)[:, None]])
    pairs = cKDTree(planes).query_pairs(4.0 * scene.tol.length, output_type="ndarray")
    object_ids = np.asarray(scene.object_ids, dtype=np.int64)
    pairs = pairs[object_ids[pairs[:, 0]] != object_ids[pairs[:, 1]]]
    joined = _boundaries_meet(
        scene.polygon_points, scene.polygon_offsets, normals, pairs.astype(np.int64), scene.tol.length
    )
    pairs = pairs[joined]
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), (n, n))
    return connected_components(graph, directed=False)[1].astype(np.int64)


@njit(cache=True)
def _boundaries_meet(points, offsets, normals, pairs, tol):
    """(K,) bool for each face pair (pairs (K, 2) int64): every corner of the second within tol of the first's
    plane, and a side of each on one line (both ends of the second's within tol of the first's line) overlapping
    over more than tol."""
    result = np.zeros(pairs.shape[0], dtype=np.bool_)
    for k in range(pairs.shape[0]):
        a = pairs[k, 0]
        b = pairs[k, 1]
        normal = _row(normals, a)
        offset = -_dot(normal, _row(points, offsets[a]))
        inside = True
        for corner in range(offsets[b], offsets[b + 1]):
            inside = inside and _near_plane(_row(points, corner), normal, offset, tol)
        if not inside:
            continue
        for i in range(offsets[a], offsets[a + 1]):
            p = _row(points, i)
            side = _minus(_row(points, offsets[a] + (i - offsets[a] + 1) % (offsets[a + 1] - offsets[a])), p)
            length = np.sqrt(_dot(side, side))
            if length <= tol:
                continue
            u = _over(side, length)
            for j in range(offsets[b], offsets[b + 1]):
                q0 = _minus(_row(points, j), p)
                q1 = _minus(_row(points, offsets[b] + (j - offsets[b] + 1) % (offsets[b + 1] - offsets[b])), p)
                t0 = _dot(q0, u)
                t1 = _dot(q1, u)
                off0 = _minus(q0, _scaled(u, t0))
                off1 = _minus(q1, _scaled(u, t1))
                if _dot(off0, off0) > tol * tol or _dot(off1, off1) > tol * tol:
                    continue
                if min(max(t0, t1), length) - max(min(t0, t1), 0.0) > tol:
                    result[k] = True
                    break
            if result[k]:
                break
    return result


def _any_of(flag: np.ndarray, offsets: np.ndarray, items: np.ndarray) -> np.ndarray:
    """(K,) bool for each row of the CSR row -> items (offsets (K + 1,), items (M,) int64), whether flag (N,) bool
    holds for one of its items (a polygon's edges, an edge's faces)."""
    counts = np.diff(offsets)
    hits = np.zeros(len(counts), dtype=np.int64)
    np.add.at(hits, np.repeat(np.arange(len(counts)), counts), flag[items].astype(np.int64))
    return hits > 0


def _validate_slice(scene, topology, bvh, candidates, edge_mask, element_solid, face_region, split_edge, lo: int,
                    hi: int):  # fmt: skip
    """validate_candidates on candidates[lo:hi] (node ids of the incidences local to the slice); element_solid:
    element_solids(scene, topology); face_region: flat_regions(scene); split_edge (E,) bool: the edges with a face
    in a region of several."""
    geometry = _Geometry(
        scene.polygon_points, scene.polygon_offsets, scene.normals, scene.areas, scene.vertices, scene.edges,
        _edge_units(scene.vertices, scene.edges), topology.vertex_face_offsets, topology.vertex_faces,
        topology.vertex_face_corner, scene.edge_face_offsets,
        scene.edge_faces, topology.edge_face_local, scene.polygon_edge_ids, topology.face_group,
        np.ascontiguousarray(scene.object_ids, dtype=np.int64), element_solid, face_region, split_edge,
        float(scene.diagonal), float(scene.tol.length),
        float(scene.tol.cosine),
    )  # fmt: skip
    grown = scene.diagonal
    result = _validate_chunk(
        geometry, scene.plane_offsets, scene.polygon_vertex_ids, tuple(bvh.arrays),
        topology.vertex_edge_offsets, topology.vertex_edges, np.ascontiguousarray(edge_mask, dtype=np.bool_),
        candidates.kind[lo:hi], candidates.vertices[lo:hi], candidates.edges[lo:hi],
        np.ascontiguousarray(candidates.origin[lo:hi], dtype=np.float64),
        np.ascontiguousarray(candidates.direction[lo:hi], dtype=np.float64),
        scene.bbox_min - grown, scene.bbox_max + grown,
    )  # fmt: skip
    (n_cand, n_kind, n_gkind, n_gid, n_start, n_dir, n_reach, n_end,
     i_node, i_kind, i_codes, i_end, i_s, i_dir, counters) = result  # fmt: skip
    # the kernel returns the used part of buffers sized for the worst case: copies let those go (ids, codes
    # and face groups in int32)
    nodes = NodeChunk(
        n_kind.copy(), n_gkind.copy(), n_gid.astype(np.int32), n_start.copy(), n_dir.copy(), n_end.astype(np.int32),
        n_reach.copy(),
    )  # fmt: skip
    incidences = IncidenceChunk(
        i_node.copy(), i_kind.copy(), i_codes.astype(np.int32), i_end.astype(np.int32), i_s.copy(), i_dir.copy()
    )
    return nodes, incidences, counters


@dataclass(frozen=True, eq=False)
class NodeChunk:
    """N validated nodes. kind (N,) int8 NODE_*; gen_kind (N, 4) int8 GEN_* and gen_id (N, 4) int32, the
    generators in line order (GEN_NONE / -1 padded); start (N, 3), direction (N, 3) unit: the line is
    start + tau direction; end (N, 2) int32 (a Skeleton holds it in the narrowest integer its face groups fit)
    the face groups met beyond the first and the last generator (END_TERMINAL when the line stops on it,
    END_FREE when it leaves); reach (N, 2) float64 the tau of those points, seed 003's P_down and P_up (the
    outer generator's own when terminal, -inf / +inf when free)."""

    kind: np.ndarray
    gen_kind: np.ndarray
    gen_id: np.ndarray
    start: np.ndarray
    direction: np.ndarray
    end: np.ndarray
    reach: np.ndarray

    def __len__(self) -> int:
        return len(self.kind)


@dataclass(frozen=True, eq=False)
class IncidenceChunk:
    """M (node, arc) incidences. node (M,) int64 index into the NodeChunk; kind (M,) int8 ARC_*; codes (M, 3)
    int32 the arc's generators in canonical line order (vertex v -> v, edge e -> V + e; -1 padded); end (M, 2)
    int32 the face groups beyond the first and last generator (END_*); s (M,) float64 the node's coordinate on
    the arc's parameter edge; direction (M,) int8 +1 when the arc leaves the node towards larger s."""

    node: np.ndarray
    kind: np.ndarray
    codes: np.ndarray
    end: np.ndarray
    s: np.ndarray
    direction: np.ndarray

    def __len__(self) -> int:
        return len(self.node)
