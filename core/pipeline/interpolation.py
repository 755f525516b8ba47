"""Linear interpolation over leaf triangles (seed 000 section 3.2): where a point lies in a triangulation, with
which barycentric weights, and the sample points at which a leaf's interpolation is checked (section 6.2).

These weights are the push of the lazy-wavelet representation: a vertex that inherits a transfer gets the
barycentric combination of the effective form factors of the corners of the leaf it was inserted in.
"""

from __future__ import annotations

import numpy as np
from numba import njit

# how far outside a triangle (in barycentric units) a point still counts as on it: rounding of points inserted
# on a shared edge
_ON_TRIANGLE = 1e-9
# a triangle is listed in the grid cells its bounding box, grown by this fraction of its size, overlaps: a
# point within _ON_TRIANGLE of it in barycentric units is closer than that
_BOX_GROWTH = 1e-7

# the samples of a leaf triangle: its centroid and its three edge midpoints, as barycentric weights
SAMPLE_WEIGHTS = np.array(
    [[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]],
)


def locate(vertices, triangles, triangle_polygon, points, polygons) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The leaf triangles holding points of the same polygon.

    vertices (N, 3), triangles (T, 3) int64, triangle_polygon (T,): a triangulation of the polygons; points
    (Q, 3) on polygons (Q,). Returns (best (Q,) int64, other (Q,) int64, weights (Q, 3) float64): the triangle
    the point is deepest in (the largest smallest barycentric coordinate, in the triangle's plane; the lowest
    id among equals) with its barycentric weights (clipped to >= 0, summing to 1), and a second triangle also
    holding the point (it lies on their shared edge) or -1. A point a rounding error outside every triangle of
    its polygon takes the deepest all the same. A triangle without area holds no point.

    Each polygon's triangles are put in a uniform grid of their bounding boxes in the polygon's plane; a point
    tests those of its cell, and all of its polygon's when none of them holds it.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    triangles = np.ascontiguousarray(triangles, dtype=np.int64)
    triangle_polygon = np.asarray(triangle_polygon).ravel()
    points = np.ascontiguousarray(points, dtype=np.float64)
    polygons = np.asarray(polygons).ravel()
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise ValueError(f"vertices must be (N, 3), got {vertices.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3 or len(triangle_polygon) != len(triangles):
        raise ValueError(f"triangles (T, 3) and triangle_polygon (T,) expected, got {triangles.shape} and "
                         f"{triangle_polygon.shape}")  # fmt: skip
    if points.ndim != 2 or points.shape[1] != 3 or len(polygons) != len(points):
        raise ValueError(f"points (Q, 3) and polygons (Q,) expected, got {points.shape} and {polygons.shape}")
    if len(triangles) and (triangles.min() < 0 or triangles.max() >= len(vertices)):
        raise ValueError(f"triangles refer to vertices outside 0..{len(vertices) - 1}")
    keys, point_key = np.unique(polygons, return_inverse=True)
    triangle_order = np.argsort(triangle_polygon, kind="stable")
    ordered_keys = triangle_polygon[triangle_order]
    first = np.searchsorted(ordered_keys, keys, side="left")
    last = np.searchsorted(ordered_keys, keys, side="right")
    empty = np.flatnonzero(first == last)
    if len(empty):
        raise ValueError(f"polygon {keys[empty[0]]} has no triangle to locate points in")
    point_order = np.argsort(point_key.ravel(), kind="stable")
    point_offsets = np.searchsorted(point_key.ravel()[point_order], np.arange(len(keys) + 1))
    best, other, weights, flat = _locate(
        vertices, triangles, triangle_order, first, last, points, point_order, point_offsets
    )
    if flat >= 0:
        raise ValueError(f"polygon {keys[flat]} has no triangle with an area to locate points in")
    return best, other, weights


@njit(cache=True)
def _locate(vertices, triangles, triangle_order, first, last, points, point_order, point_offsets):
    """locate for the polygons g (K of them): triangles triangle_order[first[g]:last[g]] (increasing ids),
    points point_order[point_offsets[g]:point_offsets[g + 1]]. Also returns the first g whose triangles all
    lack an area, or -1."""
    n = points.shape[0]
    best = np.full(n, -1, dtype=np.int64)
    other = np.full(n, -1, dtype=np.int64)
    weights = np.zeros((n, 3))
    for g in range(first.shape[0]):
        ids = triangle_order[first[g] : last[g]]
        count = ids.shape[0]
        corner = np.empty((count, 3))
        e1 = np.empty((count, 3))
        e2 = np.empty((count, 3))
        gram = np.empty((count, 4))  # e1.e1, e1.e2, e2.e2, determinant
        normal = np.zeros(3)
        for k in range(count):
            t = ids[k]
            for c in range(3):
                corner[k, c] = vertices[triangles[t, 0], c]
                e1[k, c] = vertices[triangles[t, 1], c] - corner[k, c]
                e2[k, c] = vertices[triangles[t, 2], c] - corner[k, c]
            d11 = e1[k, 0] * e1[k, 0] + e1[k, 1] * e1[k, 1] + e1[k, 2] * e1[k, 2]
            d12 = e1[k, 0] * e2[k, 0] + e1[k, 1] * e2[k, 1] + e1[k, 2] * e2[k, 2]
            d22 = e2[k, 0] * e2[k, 0] + e2[k, 1] * e2[k, 1] + e2[k, 2] * e2[k, 2]
            gram[k, 0] = d11
            gram[k, 1] = d12
            gram[k, 2] = d22
            gram[k, 3] = d11 * d22 - d12 * d12
            # oriented consistently or not, the largest component of some triangle's normal names the plane
            n0 = e1[k, 1] * e2[k, 2] - e1[k, 2] * e2[k, 1]
            n1 = e1[k, 2] * e2[k, 0] - e1[k, 0] * e2[k, 2]
            n2 = e1[k, 0] * e2[k, 1] - e1[k, 1] * e2[k, 0]
            normal[0] = max(normal[0], abs(n0))
            normal[1] = max(normal[1], abs(n1))
            normal[2] = max(normal[2], abs(n2))
        if not (gram[:, 3] > 0.0).any():
            if point_offsets[g + 1] > point_offsets[g]:
                return best, other, weights, g
            continue
        drop = np.argmax(normal)
        u_axis = (drop + 1) % 3
        w_axis = (drop + 2) % 3
        low = np.empty((count, 2))
        high = np.empty((count, 2))
        for k in range(count):
            t = ids[k]
            for j, axis in enumerate((u_axis, w_axis)):
                a = vertices[triangles[t, 0], axis]
                b = vertices[triangles[t, 1], axis]
                c = vertices[triangles[t, 2], axis]
                lo = min(a, b, c)
                hi = max(a, b, c)
                grow = _BOX_GROWTH * (hi - lo) + _BOX_GROWTH * np.sqrt(gram[k, 0] + gram[k, 2])
                low[k, j] = lo - grow
                high[k, j] = hi + grow
        origin_u = low[:, 0].min()
        origin_w = low[:, 1].min()
        span_u = max(high[:, 0].max() - origin_u, 1e-300)
        span_w = max(high[:, 1].max() - origin_w, 1e-300)
        side = max(1, int(np.sqrt(count)))
        cell_offsets, cell_triangles = _grid(low, high, origin_u, origin_w, span_u, span_w, side)
        for slot in range(point_offsets[g], point_offsets[g + 1]):
            q = point_order[slot]
            p = points[q]
            pu = (p[u_axis] - origin_u) / span_u
            pw = (p[w_axis] - origin_w) / span_w
            found = (-np.inf, -1, -np.inf, -1)
            if 0.0 <= pu <= 1.0 and 0.0 <= pw <= 1.0:
                cell = _cell(p[u_axis], origin_u, span_u, side) * side + _cell(p[w_axis], origin_w, span_w, side)
                for r in range(cell_offsets[cell], cell_offsets[cell + 1]):
                    found = _deeper(found, cell_triangles[r], p, corner, e1, e2, gram)
            if found[1] < 0 or found[0] < -_ON_TRIANGLE:
                found = (-np.inf, -1, -np.inf, -1)
                for k in range(count):
                    found = _deeper(found, k, p, corner, e1, e2, gram)
            k = found[1]
            best[q] = ids[k]
            if found[3] >= 0 and found[2] >= -_ON_TRIANGLE:
                other[q] = ids[found[3]]
            v, w = _plane_coordinates(p, corner, e1, e2, gram, k)
            total = 0.0
            for c, value in enumerate((1.0 - v - w, v, w)):
                weights[q, c] = max(value, 0.0)
                total += weights[q, c]
            for c in range(3):
                weights[q, c] /= total
    return best, other, weights, -1


@njit(cache=True)
def _grid(low, high, origin_u, origin_w, span_u, span_w, side):
    """The triangles (their boxes low, high (T, 2) in the plane's coordinates) overlapping each cell of a side x
    side grid over the rectangle origin + [0, span]: CSR offsets (side**2 + 1,) int64, triangles (R,) int64,
    each cell's in increasing order."""
    count = low.shape[0]
    cell_offsets = np.zeros(side * side + 1, dtype=np.int64)
    for k in range(count):
        for i in range(_cell(low[k, 0], origin_u, span_u, side), _cell(high[k, 0], origin_u, span_u, side) + 1):
            for j in range(_cell(low[k, 1], origin_w, span_w, side), _cell(high[k, 1], origin_w, span_w, side) + 1):
                cell_offsets[i * side + j + 1] += 1
    for i in range(side * side):
        cell_offsets[i + 1] += cell_offsets[i]
    fill = cell_offsets[:-1].copy()
    cell_triangles = np.empty(cell_offsets[-1], dtype=np.int64)
    for k in range(count):
        for i in range(_cell(low[k, 0], origin_u, span_u, side), _cell(high[k, 0], origin_u, span_u, side) + 1):
            for j in range(_cell(low[k, 1], origin_w, span_w, side), _cell(high[k, 1], origin_w, span_w, side) + 1):
                cell_triangles[fill[i * side + j]] = k
                fill[i * side + j] += 1
    return cell_offsets, cell_triangles


@njit(cache=True)
def _cell(x, origin, span, side):
    return min(max(int((x - origin) / span * side), 0), side - 1)


@njit(cache=True)
def _plane_coordinates(p, corner, e1, e2, gram, k):
    """The barycentric coordinates (v, w) of p along e1 and e2 of triangle k, in its plane."""
    d0 = p[0] - corner[k, 0]
    d1 = p[1] - corner[k, 1]
    d2 = p[2] - corner[k, 2]
    p1 = d0 * e1[k, 0] + d1 * e1[k, 1] + d2 * e1[k, 2]
    p2 = d0 * e2[k, 0] + d1 * e2[k, 1] + d2 * e2[k, 2]
    v = (gram[k, 2] * p1 - gram[k, 1] * p2) / gram[k, 3]
    w = (gram[k, 0] * p2 - gram[k, 1] * p1) / gram[k, 3]
    return v, w


@njit(cache=True)
def _deeper(found, k, p, corner, e1, e2, gram):
    """found (depth, triangle, second depth, second triangle) updated with triangle k: a triangle without area
    holds nothing; among equal depths the lower k comes first."""
    if gram[k, 3] <= 0.0:
        return found
    v, w = _plane_coordinates(p, corner, e1, e2, gram, k)
    depth = min(1.0 - v - w, v, w)
    best_depth, best, second_depth, second = found
    if best < 0 or depth > best_depth or (depth == best_depth and k < best):
        return depth, k, best_depth, best
    if second < 0 or depth > second_depth or (depth == second_depth and k < second):
        return best_depth, best, depth, k
    return found
