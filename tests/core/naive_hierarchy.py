"""Naive references for the hierarchy tests: plain loops, no code shared with core.hierarchy."""

import math


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
