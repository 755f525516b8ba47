"""Lazy-wavelet push-pull over a hierarchy of triangulations (seed 000 section 3.2, Figs. 6 and 12, eq. 1).

Each vertex v that is not a polygon corner has one ancestor triangle: the triangle (at the level above) in
whose sub-triangulation v first appeared, with v's barycentric coordinates c_i in it. The vertex stores
Delta B_v, the difference between its radiosity and the linear interpolation of the ancestor's values.
"""

import numpy as np


def lazy_delta(
    vertex_ids: np.ndarray, gathered: np.ndarray, ancestors: np.ndarray, weights: np.ndarray
) -> np.ndarray:
    """Delta B of equation 1 for one source: Delta B_v = B_l(v) - sum_i c_i B_nl(ancestor_i of v).

    vertex_ids (M,) int: the vertices holding a point-polygon link to the source; gathered (M,) or (M, C):
    the radiosity each gathers from it (positive link). The negative links are the same source's values at
    the ancestors, which must be among vertex_ids (a vertex inserted into a linked triangle always has its
    triangle's corners linked). Polygon corners (ancestor -1) get Delta B = B_l.
    ancestors (N, 3) int64, weights (N, 3) float64: the whole hierarchy's ancestry. Returns gathered's shape.
    """
    ids = np.asarray(vertex_ids, dtype=np.int64)
    values = np.asarray(gathered, dtype=np.float64)
    flat = values.reshape(len(ids), -1)
    lookup = np.full(len(ancestors), -1, dtype=np.int64)
    lookup[ids] = np.arange(len(ids))
    anc = ancestors[ids]
    has_ancestor = anc[:, 0] >= 0
    rows = lookup[np.where(anc >= 0, anc, 0)]
    missing = has_ancestor[:, None] & (rows < 0)
    if missing.any():
        bad = int(ids[np.nonzero(missing.any(axis=1))[0][0]])
        raise ValueError(f"vertex {bad}: an ancestor has no link to this source (negative link missing)")
    negative = np.einsum("mk,mkc->mc", weights[ids], flat[np.where(rows >= 0, rows, 0)])
    delta = flat - np.where(has_ancestor[:, None], negative, 0.0)
    return delta.reshape(values.shape)


def push(delta: np.ndarray, ancestors: np.ndarray, weights: np.ndarray, levels: np.ndarray) -> np.ndarray:
    """Push: B_v = Delta B_v + sum_i c_i B(ancestor_i), breadth first (by level), for all N vertices.

    delta (N,) or (N, C) float64; ancestors (N, 3) int64 (-1 for polygon corners); weights (N, 3) float64;
    levels (N,) int64, every ancestor's level lower than its vertex's. Returns B with delta's shape.
    """
    values = np.array(delta, dtype=np.float64).reshape(len(delta), -1)
    order = np.argsort(levels, kind="stable")
    bounds = np.searchsorted(levels[order], np.arange(levels.max(initial=0) + 2))
    for level in range(1, len(bounds) - 1):
        idx = order[bounds[level] : bounds[level + 1]]
        values[idx] += np.einsum("mk,mkc->mc", weights[idx], values[ancestors[idx]])
    return values.reshape(np.shape(delta))


def pull(
    leaf_values: np.ndarray, is_leaf: np.ndarray, parent: np.ndarray, levels: np.ndarray, areas: np.ndarray
) -> np.ndarray:
    """Pull: every element's value is the area-weighted average of its children's, from the leaves up.

    leaf_values (E,) or (E, C): the value of each leaf (the average of its vertices, section 3.2), ignored
    elsewhere; is_leaf (E,) bool; parent (E,) int64 (-1 for polygons); levels (E,) int64; areas (E,).
    Returns (E,) or (E, C) float64.
    """
    shape = np.shape(leaf_values)
    values = np.where(is_leaf[:, None], np.asarray(leaf_values, dtype=np.float64).reshape(len(is_leaf), -1), 0.0)
    for level in range(int(levels.max(initial=0)), 0, -1):
        kids = np.nonzero(levels == level)[0]
        mothers = parent[kids]
        total = np.zeros_like(values)
        weight = np.zeros(len(values))
        np.add.at(total, mothers, areas[kids, None] * values[kids])
        np.add.at(weight, mothers, areas[kids])
        done = np.unique(mothers)
        values[done] = total[done] / weight[done, None]
    return values.reshape(shape)
