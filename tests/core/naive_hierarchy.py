"""Naive references for the hierarchy tests: plain loops, no code shared with core.hierarchy."""

import math

import numpy as np


def sub(a, b):
    return [a[i] - b[i] for i in range(len(a))]


def dot(a, b):
    return sum(a[i] * b[i] for i in range(len(a)))


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def norm(a):
    return math.sqrt(dot(a, a))


def triangle_area(a, b, c):
    """Area of a 3-D triangle."""
    return 0.5 * norm(cross(sub(b, a), sub(c, a)))


def polygon_area(points):
    """Area of a planar convex 3-D polygon: sum of a fan of triangles."""
    return sum(triangle_area(points[0], points[i], points[i + 1]) for i in range(1, len(points) - 1))


def polygon_normal(points):
    n = [0.0, 0.0, 0.0]
    for i in range(1, len(points) - 1):
        c = cross(sub(points[i], points[0]), sub(points[i + 1], points[0]))
        n = [n[k] + c[k] for k in range(3)]
    length = norm(n)
    return [x / length for x in n]


def polygon_centroid(points):
    """Area centroid of a planar convex 3-D polygon (fan of triangles, centroids weighted by area)."""
    total = 0.0
    acc = [0.0, 0.0, 0.0]
    for i in range(1, len(points) - 1):
        area = triangle_area(points[0], points[i], points[i + 1])
        total += area
        for k in range(3):
            acc[k] += area * (points[0][k] + points[i][k] + points[i + 1][k]) / 3.0
    return [x / total for x in acc]


def distance_to_segment(p, a, b):
    ab = sub(b, a)
    t = dot(sub(p, a), ab) / dot(ab, ab)
    t = min(1.0, max(0.0, t))
    closest = [a[k] + t * ab[k] for k in range(len(a))]
    return norm(sub(p, closest))


def barycentric_3d(p, a, b, c):
    """Barycentric coordinates of p in the plane of triangle a b c (least squares on the plane)."""
    n = cross(sub(b, a), sub(c, a))
    area2 = dot(n, n)
    wa = dot(cross(sub(b, p), sub(c, p)), n) / area2
    wb = dot(cross(sub(c, p), sub(a, p)), n) / area2
    return [wa, wb, 1.0 - wa - wb]


def piecewise_linear(knots, values, x):
    """Linear interpolation at x of the function taking values[i] at knots[i] (any order)."""
    pairs = sorted(zip(knots, values, strict=True))
    for (x0, y0), (x1, y1) in zip(pairs, pairs[1:], strict=False):
        if x0 <= x <= x1:
            return y0 + (y1 - y0) * (x - x0) / (x1 - x0)
    raise ValueError(f"{x} outside the knots")


def conformity_problems(vertices, triangles, triangle_polygon, polygons, tol):
    """Every way in which leaf triangles fail to conform, as readable strings (empty list: conforming).

    Inside a polygon, each directed edge u->v must be matched by exactly one v->u, or lie on a side of the
    polygon. On a side shared with another polygon (same endpoints), both polygons must break the side at
    the same points (within tol). vertices: list of 3-D points; triangles: list of vertex-index triples.
    """
    problems = []
    directed = {}
    for t, tri in enumerate(triangles):
        for j in range(3):
            key = (tri[j], tri[(j + 1) % 3])
            if key in directed:
                problems.append(f"edge {key} used twice in the same direction")
            directed[key] = t
    polygon_vertices = {}
    for t, tri in enumerate(triangles):
        polygon_vertices.setdefault(triangle_polygon[t], set()).update(tri)
    for (u, v), t in directed.items():
        if (v, u) in directed:
            if triangle_polygon[directed[(v, u)]] != triangle_polygon[t]:
                problems.append(f"edge {(u, v)} joins two polygons")
            continue
        p = triangle_polygon[t]
        pts = polygons[p]
        on_side = False
        for s in range(len(pts)):
            a, b = pts[s], pts[(s + 1) % len(pts)]
            if distance_to_segment(vertices[u], a, b) <= tol and distance_to_segment(vertices[v], a, b) <= tol:
                on_side = True
        if not on_side:
            problems.append(f"polygon {p}: edge {(u, v)} has no neighbour and is not on a side")
    for p, pts in enumerate(polygons):
        for s in range(len(pts)):
            a, b = pts[s], pts[(s + 1) % len(pts)]
            for q, other in enumerate(polygons):
                if q == p:
                    continue
                for r in range(len(other)):
                    c, d = other[r], other[(r + 1) % len(other)]
                    if norm(sub(a, c)) <= tol and norm(sub(b, d)) <= tol:
                        same = True
                    elif norm(sub(a, d)) <= tol and norm(sub(b, c)) <= tol:
                        same = False
                    else:
                        continue
                    mine = _params(vertices, polygon_vertices.get(p, ()), a, b, tol)
                    theirs = _params(vertices, polygon_vertices.get(q, ()), a, b, tol)
                    if not _same_params(mine, theirs, tol / norm(sub(b, a))):
                        problems.append(f"side {s} of polygon {p} and side {r} of polygon {q} break differently"
                                        f" ({len(mine)} vs {len(theirs)} points, orientation same={same})")
    return problems


def _params(vertices, candidates, a, b, tol):
    """Sorted parameters along a -> b of the candidate vertices lying on segment a b."""
    ab = sub(b, a)
    ts = [dot(sub(vertices[w], a), ab) / dot(ab, ab) for w in candidates
          if distance_to_segment(vertices[w], a, b) <= tol]
    return sorted(ts)


def _same_params(x, y, tol):
    return len(x) == len(y) and all(abs(p - q) <= 4 * tol for p, q in zip(x, y, strict=True))


# ---------------------------------------------------------------------------------------------- CDT check
# Plain numpy, written for the tests: a triangulation is constrained Delaunay when no triangle's circumcircle
# holds, strictly, a vertex of the same triangulation visible from the triangle's interior (Chew 1989).


def plane_coordinates(polygon, points):
    """Coordinates (M, 2) of 3-D points (M, 3) in the plane of a convex polygon (K, 3): origin at its first
    corner, first axis along its first side, second axis turning counter-clockwise about its normal."""
    corners = np.asarray(polygon, dtype=np.float64)
    u = corners[1] - corners[0]
    u /= np.linalg.norm(u)
    n = np.asarray(polygon_normal(corners.tolist()))
    v = np.cross(n, u)
    d = np.asarray(points, dtype=np.float64) - corners[0]
    return np.stack([d @ u, d @ v], axis=1)


def _orient(p, q, r):
    """Twice the signed area of triangles p q r, arrays (..., 2) -> (...): positive when counter-clockwise."""
    return (q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1]) - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0])


def edges_on_segments(xy, edges, segments, distance):
    """Which edges (E, 2) of points xy (N, 2) lie on one of the segments (S, 2, 2): both ends within
    `distance` of the same closed segment. Returns (E,) bool."""
    if len(edges) == 0 or len(segments) == 0:
        return np.zeros(len(edges), dtype=bool)
    a = segments[:, 0]
    ab = segments[:, 1] - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    near = np.ones((len(edges), len(segments)), dtype=bool)
    for end in (0, 1):
        p = xy[edges[:, end]]
        t = np.clip(np.einsum("esk,sk->es", p[:, None, :] - a[None], ab) / length2, 0.0, 1.0)
        foot = a[None] + t[..., None] * ab[None]
        near &= np.linalg.norm(p[:, None, :] - foot, axis=2) <= distance
    return near.any(axis=1)


def near_segments(points, segments, distance):
    """Which points (M, 2) lie within `distance` of one of the closed segments (S, 2, 2): (M,) bool."""
    near = np.zeros(len(points), dtype=bool)
    if len(segments) == 0:
        return near
    a = segments[:, 0]
    ab = segments[:, 1] - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    for start in range(0, len(points), 1024):
        p = points[start : start + 1024, None, :]
        t = np.clip(np.einsum("msk,sk->ms", p - a[None], ab) / length2, 0.0, 1.0)
        near[start : start + 1024] = (np.linalg.norm(p - (a[None] + t[..., None] * ab[None]), axis=2) <= distance).any(
            axis=1
        )
    return near


def _blocked(v, p, q, constraints, gap):
    """Whether every point of the open edge p q (2,) is hidden from point v (2,) by the constraint segments
    (C, 2, 2): the shadows the constraints cast from v onto p q, as parameters along p -> q, must cover [0, 1]
    leaving no gap longer than `gap` (a parameter)."""
    corners = np.array([v, p, q])
    if _orient(v, p, q) < 0.0:
        corners = corners[::-1]
    r = constraints[:, 0]
    d = constraints[:, 1] - r
    lo = np.zeros(len(constraints))
    hi = np.ones(len(constraints))
    # Clip each constraint to the closed triangle v p q: only the part inside it can cut a sight line.
    for i in range(3):
        start, end = corners[i], corners[(i + 1) % 3]
        edge = end - start
        num = edge[0] * (r[:, 1] - start[1]) - edge[1] * (r[:, 0] - start[0])
        den = edge[0] * d[:, 1] - edge[1] * d[:, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = -num / den
        lo = np.where(den > 0.0, np.maximum(lo, t), lo)
        hi = np.where(den < 0.0, np.minimum(hi, t), hi)
        hi = np.where((den == 0.0) & (num < 0.0), -1.0, hi)
    inside = hi > lo
    shadows = []
    e = q - p
    for k in np.nonzero(inside)[0]:
        ends = []
        for s in (lo[k], hi[k]):
            w = r[k] + s * d[k] - v
            den = e[0] * w[1] - e[1] * w[0]
            if den == 0.0:
                break
            ends.append(((v[0] - p[0]) * w[1] - (v[1] - p[1]) * w[0]) / den)
        if len(ends) == 2:
            shadows.append((min(ends), max(ends)))
    covered = 0.0
    for start, end in sorted(shadows):
        if start > covered + gap:
            return False
        covered = max(covered, end)
    return covered >= 1.0 - gap


def constrained_delaunay_violations(xy, triangles, constrained, slack):
    """Triangle / vertex pairs breaking the constrained Delaunay property, with readable reasons.

    xy (N, 2) float64: the vertices; triangles (T, 3) int64 indices into xy, counter-clockwise; constrained:
    set of frozenset({u, w}) edges that are constraints (the triangulation's boundary must be among them).
    slack: a length the vertices may have moved by since the triangulation was built (the scene's tolerance):
    a vertex is strictly inside a circumcircle only when the in-circle determinant exceeds what moving all four
    points by `slack` can change, 48 slack L^3 for points L apart (each of the 3 x 3 determinant's entries
    moves by at most slack or 2 L slack, against cofactors of at most 2 L^3 and 2 L^2).
    Returns a list of (triangle index, vertex index, reason).
    """
    tri = xy[triangles]
    rel = tri[:, None, :, :] - xy[None, :, None, :]
    lifted = np.einsum("tvik,tvik->tvi", rel, rel)
    det = (
        rel[..., 0, 0] * (rel[..., 1, 1] * lifted[..., 2] - lifted[..., 1] * rel[..., 2, 1])
        - rel[..., 0, 1] * (rel[..., 1, 0] * lifted[..., 2] - lifted[..., 1] * rel[..., 2, 0])
        + lifted[..., 0] * (rel[..., 1, 0] * rel[..., 2, 1] - rel[..., 1, 1] * rel[..., 2, 0])
    )
    size = np.sqrt(lifted.max(axis=2))
    extent = np.linalg.norm(tri.max(axis=1) - tri.min(axis=1), axis=1)
    span = np.maximum(size, extent[:, None])
    inside = det > 48.0 * slack * span**3
    inside[np.arange(len(triangles))[:, None], triangles] = False
    violations = []
    pair_list = sorted(tuple(sorted(e)) for e in constrained)
    ends = np.array(pair_list, dtype=np.int64).reshape(-1, 2)
    segments = xy[ends]
    for t, v in zip(*np.nonzero(inside), strict=True):
        a, b, c = triangles[t]
        point = xy[v]
        sides = [(a, b), (b, c), (c, a)]
        outside = [_orient(xy[p], xy[q], point) / np.linalg.norm(xy[q] - xy[p]) for p, q in sides]
        j = int(np.argmin(outside))
        if outside[j] >= 0.0:
            violations.append((int(t), int(v), "vertex inside the triangle"))
            continue
        p, q = sides[j]
        if frozenset((p, q)) in constrained:
            continue
        # Constraints ending at v cast no shadow from v (a sight line only touches them at v).
        others = (ends != v).all(axis=1)
        gap = slack / np.linalg.norm(xy[q] - xy[p])
        if not _blocked(point, xy[p], xy[q], segments[others], gap):
            violations.append((int(t), int(v), f"visible through edge {(int(p), int(q))}"))
    return violations


def smallest_angles(xy, triangles):
    """Smallest angle (degrees) of each triangle (T, 3) of points xy (N, 2), and the index 0..2 of its vertex:
    ((T,) float64, (T,) int64)."""
    corners = xy[triangles]
    angles = []
    for i in range(3):
        u = corners[:, (i + 1) % 3] - corners[:, i]
        w = corners[:, (i + 2) % 3] - corners[:, i]
        cosine = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        angles.append(np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0))))
    angles = np.stack(angles, axis=1)
    at = np.argmin(angles, axis=1)
    return angles[np.arange(len(triangles)), at], at


def in_every_triangulation(xy, edge, constrained, slack):
    """Whether edge (u, w) of points xy (N, 2) belongs to every triangulation of those points: it is a
    constraint, or no segment between two of the points crosses it (each end further than `slack` from the
    other segment's line; a crossing segment blocked by a constraint still counts, so the answer errs on
    the side of False)."""
    if frozenset(edge) in constrained:
        return True
    a, b = xy[edge[0]], xy[edge[1]]
    side = _orient(a, b, xy) / np.linalg.norm(b - a)
    left, right = xy[side > slack], xy[side < -slack]
    if len(left) == 0 or len(right) == 0:
        return True
    u, w = left[:, None, :], right[None, :, :]
    length = np.linalg.norm(w - u, axis=2)
    at_a, at_b = _orient(u, w, a) / length, _orient(u, w, b) / length
    return not np.any(((at_a > slack) & (at_b < -slack)) | ((at_a < -slack) & (at_b > slack)))


def forced_angle(xy, triangle, constrained, slack):
    """An angle (degrees) that every triangulation of the points xy (N, 2) and constraints of a constrained
    Delaunay triangulation containing `triangle` (3,) a b c must reach or go below in some triangle; 180
    when nothing is proven. For each side a b found in every triangulation, a triangle a b c' lies on c's
    side of it, and:
    - its angle at c' is at most a c b: a larger one puts c' strictly inside the circumcircle of a b c and
      visible from it (c' sees a b), against the Delaunay property;
    - when c's foot falls inside a b, c lies outside a b c', so a b c' is no higher than c there and its
      angle at a or at b is at most the larger of c a b, c b a.
    """
    corners = xy[np.asarray(triangle)]
    best = 180.0
    for i in range(3):
        a, b, c = corners[i], corners[(i + 1) % 3], corners[(i + 2) % 3]
        if not in_every_triangulation(xy, (triangle[i], triangle[(i + 1) % 3]), constrained, slack):
            continue
        at_a, at_b, at_c = (_angle(a, b, c), _angle(b, c, a), _angle(c, a, b))
        best = min(best, at_c)
        if at_a < 90.0 and at_b < 90.0:
            best = min(best, max(at_a, at_b))
    return best


def _angle(at, x, y):
    """Angle x at y, in degrees, of 2-D points (2,)."""
    u, w = x - at, y - at
    return math.degrees(math.atan2(abs(u[0] * w[1] - u[1] * w[0]), u[0] * w[0] + u[1] * w[1]))


def lattice_points_inside(corners, step, keep_points, keep_segments, radius, slack):
    """The interior grid of core.hierarchy.grid by its definition, one candidate at a time: the triangular
    lattice of spacing dx = L / round(L / step) along the longest side L (rows dx sqrt(3) / 2 apart, odd rows
    shifted by dx / 2, row 0 on that side), kept when more than dx / 2 from every side and more than radius
    from every keep point and segment (thresholds lowered by slack). Returns a list of (x, y)."""
    k = len(corners)
    lengths = [math.dist(corners[i], corners[(i + 1) % k]) for i in range(k)]
    longest = next(i for i in range(k) if lengths[i] >= max(lengths) - slack)
    dx = lengths[longest] / max(1, math.floor((lengths[longest] + slack) / step + 0.5))
    origin = corners[longest]
    axis = [(corners[(longest + 1) % k][c] - origin[c]) / lengths[longest] for c in range(2)]
    normal = [-axis[1], axis[0]]
    reach = max(math.dist(origin, p) for p in corners)
    kept = []
    for row in range(1, int(reach / (dx * math.sqrt(3) / 2)) + 2):
        for column in range(-int(reach / dx) - 2, int(reach / dx) + 3):
            x = column * dx + (row % 2) * dx / 2
            y = row * dx * math.sqrt(3) / 2
            p = [origin[c] + x * axis[c] + y * normal[c] for c in range(2)]
            side_distances = []
            for i in range(k):
                a, b = corners[i], corners[(i + 1) % k]
                side_distances.append(((b[0] - a[0]) * (p[1] - a[1]) - (b[1] - a[1]) * (p[0] - a[0])) / lengths[i])
            if min(side_distances) <= dx / 2 - slack:
                continue
            near = [math.dist(p, q) for q in keep_points]
            near += [distance_to_segment(p, list(s[0]), list(s[1])) for s in keep_segments]
            if near and min(near) <= radius - slack:
                continue
            kept.append(p)
    return kept
