"""Linear interpolation over leaf triangles (seed 000 section 3.2): where a point lies in a triangulation, with
which barycentric weights, and the sample points at which a leaf's interpolation is checked (section 6.2).

These weights are the push of the lazy-wavelet representation: a vertex that inherits a transfer gets the
barycentric combination of the effective form factors of the corners of the leaf it was inserted in.
"""

from __future__ import annotations

import numpy as np

# (points x triangles) barycentric coordinates computed at once
_BATCH_ENTRIES = 2_000_000
# how far outside a triangle (in barycentric units) a point still counts as on it: rounding of points inserted
# on a shared edge
_ON_TRIANGLE = 1e-9

# the samples of a leaf triangle: its centroid and its three edge midpoints, as barycentric weights
SAMPLE_WEIGHTS = np.array(
    [[1 / 3, 1 / 3, 1 / 3], [0.5, 0.5, 0.0], [0.0, 0.5, 0.5], [0.5, 0.0, 0.5]],
)


def barycentric_coordinates(a, b, c, points) -> np.ndarray:
    """(Q, T, 3) barycentric coordinates of points (Q, 3) in triangles a, b, c (T, 3) each, in each plane; a
    triangle without area holds no point (-inf)."""
    e1 = b - a
    e2 = c - a
    d = points[:, None, :] - a[None]
    d11 = np.einsum("ij,ij->i", e1, e1)
    d12 = np.einsum("ij,ij->i", e1, e2)
    d22 = np.einsum("ij,ij->i", e2, e2)
    p1 = np.einsum("qtj,tj->qt", d, e1)
    p2 = np.einsum("qtj,tj->qt", d, e2)
    den = d11 * d22 - d12 * d12
    degenerate = den == 0.0
    den = np.where(degenerate, 1.0, den)
    v = (d22 * p1 - d12 * p2) / den
    w = (d11 * p2 - d12 * p1) / den
    coordinates = np.stack([1.0 - v - w, v, w], axis=2)
    coordinates[:, degenerate] = -np.inf
    return coordinates


def locate(vertices, triangles, triangle_polygon, points, polygons) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The leaf triangles holding points of the same polygon.

    vertices (N, 3), triangles (T, 3) int64, triangle_polygon (T,): a triangulation of the polygons; points
    (Q, 3) on polygons (Q,). Returns (best (Q,) int64, other (Q,) int64, weights (Q, 3) float64): the triangle
    the point is deepest in with its barycentric weights (clipped to >= 0, summing to 1), and a second triangle
    also holding the point (it lies on their shared edge) or -1. A point a rounding error outside every
    triangle of its polygon takes the nearest.
    """
    best = np.full(len(points), -1, dtype=np.int64)
    other = np.full(len(points), -1, dtype=np.int64)
    weights = np.zeros((len(points), 3))
    for polygon in np.unique(polygons):
        idx = np.flatnonzero(polygons == polygon)
        candidates = np.flatnonzero(triangle_polygon == polygon)
        if not len(candidates):
            raise ValueError(f"polygon {polygon} has no triangle to locate points in")
        a, b, c = (vertices[triangles[candidates, k]] for k in range(3))
        batch = max(1, _BATCH_ENTRIES // len(candidates))
        for start in range(0, len(idx), batch):
            part = idx[start : start + batch]
            coords = barycentric_coordinates(a, b, c, points[part])
            depth = coords.min(axis=2)
            order = np.argsort(-depth, axis=1)[:, :2]
            rows = np.arange(len(part))
            best[part] = candidates[order[:, 0]]
            w = np.clip(coords[rows, order[:, 0]], 0.0, None)
            weights[part] = w / w.sum(axis=1, keepdims=True)
            if len(candidates) > 1:
                second = depth[rows, order[:, 1]] >= -_ON_TRIANGLE
                other[part[second]] = candidates[order[second, 1]]
    return best, other, weights
