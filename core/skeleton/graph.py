"""Arc assembly: node-arc incidences become the arcs of the skeleton graph, each bounded by two nodes.

Durand et al. 1997, section 3.3 and Figs. 11-12: when a node is inserted, each adjacent arc is looked up
among the arcs with the same generators and end faces; the node becomes its start or its end, or splits it.
Inserting nodes one by one into balanced trees gives the same result as sorting all incidences at once, which
is what this module does: incidences with the same key (arc kind, generators in line order, end faces) are
sorted by their coordinate s along the arc's parameter edge, and each node that starts an arc (the arc leaves
it towards larger s) is paired with the next node that ends one. An incidence left without a partner is a
dangling arc: with a complete node set there is none, so their count measures completeness.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from .validation import END_PLANAR


@dataclass(frozen=True, eq=False)
class Arcs:
    """A arcs. kind (A,) int8 ARC_*; codes (A, 3) int32 generators in canonical line order (vertex v -> v,
    edge e -> V + e, -1 padded); node (A, 2) int32 the start and end node (-1: dangling); s (A, 2) float64
    their coordinates on the arc's parameter edge (its lowest edge generator), start < end; ends (A, 2, 2)
    int32 the face groups beyond the first / last generator (END_*) as found at the start node and at the end
    node (they differ where the lines end exactly on a blocker's edge)."""

    kind: np.ndarray
    codes: np.ndarray
    node: np.ndarray
    s: np.ndarray
    ends: np.ndarray

    def __len__(self) -> int:
        return len(self.kind)

    @property
    def end(self) -> np.ndarray:
        """(A, 2) the end face groups as found at the start node."""
        return self.ends[:, 0]

    @property
    def dangling(self) -> np.ndarray:
        """(A,) bool: arcs missing a start or an end node."""
        return (self.node < 0).any(axis=1)


def coincident_nodes(start: np.ndarray, direction: np.ndarray, scale: float, tol: float) -> np.ndarray:
    """(N,) int64: for each node line (start (N, 3), unit direction (N, 3)), the lowest id of the nodes on the
    same line (within tol, lengths; scale: the scene's diagonal).

    In degenerate scenes one extremal line goes through more generators than its kind needs (a vertex, a
    parallel edge and a floor edge aligned): every subset of them validates as a node of its own. The simplest
    configuration (seed 000 section 2.2) is one node for one line, so that the arcs met there meet each other.
    """
    n = len(start)
    if n == 0:
        return np.empty(0, dtype=np.int64)
    foot = start - np.einsum("ij,ij->i", start, direction)[:, None] * direction
    # a line's foot moves by |foot| times the direction error: both scaled to lengths of the scene. Each line
    # is entered with both orientations (no sign convention is safe where two components tie, a diagonal)
    keys = np.vstack([np.hstack([foot / scale, direction]), np.hstack([foot / scale, -direction])])
    pairs = cKDTree(keys).query_pairs(tol / scale, output_type="ndarray") % n
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    if len(pairs) == 0:
        return np.arange(n, dtype=np.int64)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    lowest = np.full(labels.max() + 1, n, dtype=np.int64)
    np.minimum.at(lowest, labels, np.arange(n, dtype=np.int64))
    return lowest[labels]


def assemble_arcs(kind, codes, end, s, direction, node, s_tol) -> Arcs:
    """Pair the incidences (M,) (see core.skeleton.validation.IncidenceChunk; node: global node ids, coincident
    nodes already merged) into arcs. An incidence repeated by merged nodes counts once.

    An arc is keyed by its generators alone: through a point of its parameter edge there is one line meeting
    the others, so two arcs with the same generators never overlap, and consecutive nodes along the edge bound
    one arc even where they disagree about the face its lines end on (a line ending exactly on a blocker's
    edge: either face at that edge, decided by rounding at each node). Coordinates closer than s_tol (M,)
    (the tolerance length over the parameter edge's length) are one point, where ends come before starts: an
    arc of zero length is not invented and merged nodes meeting one arc from both sides pair up."""
    if len(kind) == 0:
        return Arcs(
            np.empty(0, np.int8), np.empty((0, 3), np.int32), np.empty((0, 2), np.int32), np.empty((0, 2)),
            np.empty((0, 2, 2), np.int32),
        )  # fmt: skip
    order = np.lexsort((s, codes[:, 2], codes[:, 1], codes[:, 0], kind))
    order = order[_ends_first(_new_keys(kind, codes, order), s[order], s_tol[order], direction[order], node[order])]
    new_key = _new_keys(kind, codes, order)
    pair_node, pair_s, pair_row, pair_other = _pair(new_key, direction[order], s[order], node[order])
    rows = order[pair_row]
    ends = np.stack([end[rows], end[order[pair_other]]], axis=1)
    ends[pair_other < 0, 1] = ends[pair_other < 0, 0]
    # lines lying in a face's plane at one node lie in it all along the arc (a plane holds the whole swath
    # or meets it in one line, a node): a node whose end line pokes past that face reports where it ends
    planar = (ends == END_PLANAR).any(axis=1)
    ends[np.repeat(planar[:, None, :], 2, axis=1)] = END_PLANAR
    return Arcs(kind[rows], codes[rows].astype(np.int32), pair_node.astype(np.int32), pair_s, ends.astype(np.int32))


def _new_keys(kind, codes, order) -> np.ndarray:
    """(M,) bool: where the arc key (kind, generators) changes along `order`."""
    key_kind = kind[order]
    key_codes = codes[order]
    new_key = np.ones(len(order), dtype=np.bool_)
    new_key[1:] = (key_kind[1:] != key_kind[:-1]) | (key_codes[1:] != key_codes[:-1]).any(axis=1)
    return new_key


@njit(cache=True)
def _ends_first(new_key, s, s_tol, direction, node):
    """Positions of the incidences sorted by key then s, reordered so that within each run of coordinates
    closer than s_tol to the run's first the ends (direction -1) come before the starts; an incidence
    repeating one of its run (same node, same direction: merged nodes) is left out."""
    m = len(new_key)
    result = np.empty(m, dtype=np.int64)
    k = 0
    i = 0
    while i < m:
        j = i + 1
        while j < m and not new_key[j] and s[j] - s[i] <= max(s_tol[i], s_tol[j]):
            j += 1
        run = k
        for kept in (-1, 1):
            for r in range(i, j):
                if direction[r] != kept:
                    continue
                repeated = False
                for q in range(run, k):
                    if node[result[q]] == node[r] and direction[result[q]] == kept:
                        repeated = True
                        break
                if not repeated:
                    result[k] = r
                    k += 1
        i = j
    return result[:k]


@njit(cache=True)
def _pair(new_key, direction, s, node):
    m = len(new_key)
    out_node = np.full((m, 2), -1, dtype=np.int64)
    out_s = np.full((m, 2), np.nan)
    out_row = np.empty(m, dtype=np.int64)
    out_other = np.full(m, -1, dtype=np.int64)
    count = 0
    pending = -1
    for i in range(m):
        if new_key[i] and pending >= 0:
            out_node[count, 0] = node[pending]
            out_s[count, 0] = s[pending]
            out_row[count] = pending
            count += 1
            pending = -1
        if direction[i] > 0:
            if pending >= 0:
                out_node[count, 0] = node[pending]
                out_s[count, 0] = s[pending]
                out_row[count] = pending
                count += 1
            pending = i
        else:
            if pending >= 0:
                out_node[count, 0] = node[pending]
                out_s[count, 0] = s[pending]
                out_node[count, 1] = node[i]
                out_s[count, 1] = s[i]
                out_row[count] = pending
                out_other[count] = i
                pending = -1
            else:
                out_node[count, 1] = node[i]
                out_s[count, 1] = s[i]
                out_row[count] = i
            count += 1
    if pending >= 0:
        out_node[count, 0] = node[pending]
        out_s[count, 0] = s[pending]
        out_row[count] = pending
        count += 1
    return out_node[:count], out_s[:count], out_row[:count], out_other[:count]
