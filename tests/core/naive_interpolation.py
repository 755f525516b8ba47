"""Naive reference for core.pipeline.interpolation.locate: every point against every triangle of its polygon,
barycentric coordinates as ratios of signed areas; no code shared with core."""

import numpy as np


def coordinates(a, b, c, p):
    """(u, v, w) (..., 3) of points p in triangles a, b, c (..., 3 each; in their planes); nan without area."""
    normal = np.cross(b - a, c - a)

    def area(x, y, z):
        return np.sum(np.cross(y - x, z - x) * normal, axis=-1)

    whole = area(a, b, c)
    whole = np.where(whole > 0.0, whole, np.nan)
    return np.stack([area(p, b, c) / whole, area(a, p, c) / whole, area(a, b, p) / whole], axis=-1)


def naive_locate(vertices, triangles, triangle_polygon, points, polygons):
    """(best, other, weights, depth (Q,) of best, depth (Q,) of the runner-up or -inf), as locate documents."""
    best, other, weights = [], [], []
    best_depth, second_depth = [], []
    for p, polygon in zip(points, polygons, strict=True):
        ids = np.flatnonzero(triangle_polygon == polygon)
        found = coordinates(*(vertices[triangles[ids, k]] for k in range(3)), p)
        depth = found.min(axis=1)
        ranked = sorted((-d, int(t), k) for k, (t, d) in enumerate(zip(ids, depth, strict=True)) if not np.isnan(d))
        _, t, k = ranked[0]
        best.append(t)
        clipped = np.maximum(found[k], 0.0)
        weights.append(clipped / clipped.sum())
        best_depth.append(depth[k])
        runner_up = -ranked[1][0] if len(ranked) > 1 else -np.inf
        second_depth.append(runner_up)
        other.append(ranked[1][1] if runner_up >= -1e-9 else -1)
    return np.array(best), np.array(other), np.array(weights), np.array(best_depth), np.array(second_depth)
