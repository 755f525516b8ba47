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

from ..jit import njit_leaf
from ..unionfind import find_root
from .validation import END_PLANAR


@dataclass(frozen=True, eq=False)
class Arcs:
    """A arcs. kind (A,) int8 ARC_*; codes (A, 3) int32 generators in canonical line order (vertex v -> v,
    edge e -> V + e, -1 padded); node (A, 2) int32 the start and end node (-1: dangling); s (A, 2) float64
    their coordinates on the arc's parameter edge (its lowest edge generator), start < end; ends (A, 2, 2)
    (the incidences' integer type: a Skeleton's narrowest that fits its face groups) the face groups beyond the
    first / last generator (END_*) as found at the start node and at the end node (they differ where the lines
    end exactly on a blocker's edge)."""

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
    """(N,) int32: for each node line (start (N, 3), unit direction (N, 3)), the lowest id of the nodes on the
    same line (within tol, lengths; scale: the scene's diagonal).

    In degenerate scenes one extremal line goes through more generators than its kind needs (a vertex, a
    parallel edge and a floor edge aligned): every subset of them validates as a node of its own. The simplest
    configuration (seed 000 section 2.2) is one node for one line, so that the arcs met there meet each other.
    """
    n = len(start)
    if n == 0:
        return np.empty(0, dtype=np.int32)
    radius = tol / scale
    # a line's key is its foot (scaled to lengths of the scene: the foot moves by |foot| times the direction
    # error) and its direction, entered with its largest component positive; two directions within the radius
    # have the same largest component unless the two largest of either tie within twice the radius (a
    # diagonal): those lines are entered with both orientations (keys n.. stand for the tied lines). Keys
    # within the radius project within |_PROJECTION| radius of each other (plus rounding): only keys that
    # close in projection order are compared, each made again from its line when needed. Neither the keys
    # nor a search tree are held: they would set the peak memory of a build
    tied = np.flatnonzero(_tied_lines(direction, 2.0 * radius))
    projection, largest = _key_projections(start, direction, scale, tied, _PROJECTION)
    order = np.argsort(projection)
    width = np.linalg.norm(_PROJECTION) * radius * (1.0 + 1e-6) + 64.0 * np.finfo(float).eps * (
        np.abs(_PROJECTION).sum() * largest
    )
    parent = np.arange(n, dtype=np.int32)
    _merge_in_order(parent, start, direction, scale, tied, projection, order, width, radius)
    return _lowest_of_sets(parent)


#: a projection of the keys mixing all six coordinates, so that distinct lines rarely project close together
_PROJECTION = 1.0 / np.sqrt(np.array([2.0, 3.0, 5.0, 7.0, 11.0, 13.0]))


@njit(cache=True)
def _tied_lines(direction, gap):
    """(N,) bool: the unit directions (N, 3) whose two largest components in magnitude differ by gap or less."""
    tied = np.empty(direction.shape[0], dtype=np.bool_)
    for i in range(direction.shape[0]):
        a, b, c = abs(direction[i, 0]), abs(direction[i, 1]), abs(direction[i, 2])
        top = max(a, b, c)
        second = max(min(a, b), min(max(a, b), c))
        tied[i] = top - second <= gap
    return tied


@njit(cache=True)
def _write_key(start, direction, scale, line, negate, out):
    """The key (6,) of a line (see coincident_nodes) into out: its foot over scale, then its direction with
    the largest component positive (the other orientation when negate)."""
    along = 0.0
    for k in range(3):
        along += start[line, k] * direction[line, k]
    largest = 0
    for k in range(1, 3):
        if abs(direction[line, k]) > abs(direction[line, largest]):
            largest = k
    sign = -1.0 if (direction[line, largest] < 0.0) != negate else 1.0
    for k in range(3):
        out[k] = (start[line, k] - along * direction[line, k]) / scale
        out[3 + k] = sign * direction[line, k]


@njit(cache=True)
def _key_projections(start, direction, scale, tied, projection_axis):
    """((N + T,) float64, float): each key's projection on projection_axis (6,) (keys N.. the tied lines (T,)
    int64 in their other orientation) and the largest magnitude of any key coordinate."""
    n = start.shape[0]
    projection = np.empty(n + tied.shape[0])
    key = np.empty(6)
    largest = 0.0
    for row in range(n + tied.shape[0]):
        _write_key(start, direction, scale, row if row < n else tied[row - n], row >= n, key)
        total = 0.0
        for k in range(6):
            total += key[k] * projection_axis[k]
            largest = max(largest, abs(key[k]))
        projection[row] = total
    return projection, largest


@njit(cache=True)
def _merge_in_order(parent, start, direction, scale, tied, projection, order, width, radius):
    """Union, in the forest parent (N,) int32 whose roots are their sets' lowest ids, of the lines whose keys
    (see coincident_nodes; rows N.. the tied lines (T,) int64 in their other orientation) lie within radius:
    each key is compared with those after it in projection order (order (N + T,) of projection (N + T,))
    while the projections stay within width."""
    n = start.shape[0]
    key = np.empty(6)
    other = np.empty(6)
    for a in range(order.shape[0]):
        row = order[a]
        line = row if row < n else tied[row - n]
        written = False
        for b in range(a + 1, order.shape[0]):
            next_row = order[b]
            if projection[next_row] - projection[row] > width:
                break
            next_line = next_row if next_row < n else tied[next_row - n]
            if find_root(parent, line) == find_root(parent, next_line):
                continue
            if not written:
                _write_key(start, direction, scale, line, row >= n, key)
                written = True
            _write_key(start, direction, scale, next_line, next_row >= n, other)
            squared = 0.0
            for k in range(6):
                squared += (key[k] - other[k]) ** 2
            if np.sqrt(squared) <= radius:
                low = find_root(parent, line)
                high = find_root(parent, next_line)
                if high < low:
                    low, high = high, low
                parent[high] = low


@njit(cache=True)
def _lowest_of_sets(parent):
    for i in range(len(parent)):
        parent[i] = find_root(parent, i)
    return parent


def assemble_arcs(kind, codes, end, s, direction, node, edge_tol, n_vertices) -> Arcs:
    """Pair the incidences (M,) (see core.skeleton.validation.IncidenceChunk; node: global node ids, coincident
    nodes already merged) into arcs. An incidence repeated by merged nodes counts once.

    An arc is keyed by its generators alone: through a point of its parameter edge there is one line meeting
    the others, so two arcs with the same generators never overlap, and consecutive nodes along the edge bound
    one arc even where they disagree about the face its lines end on (a line ending exactly on a blocker's
    edge: either face at that edge, decided by rounding at each node). Coordinates closer than the tolerance
    length are one point (edge_tol (E,): that length over each edge's length, taken on the arc's parameter
    edge, code - n_vertices), where ends come before starts: an arc of zero length is not invented and merged
    nodes meeting one arc from both sides pair up."""
    if len(kind) == 0:
        return Arcs(
            np.empty(0, np.int8), np.empty((0, 3), np.int32), np.empty((0, 2), np.int32), np.empty((0, 2)),
            np.empty((0, 2, 2), end.dtype),
        )  # fmt: skip
    # the kernels read the incidences through `order`: gathered copies of them set the peak memory of a build
    order = _by_key_then_s(kind, codes, s)
    order = _ends_first(order, kind, codes, s, edge_tol, n_vertices, direction, node)
    arcs = Arcs(*_pair(order, kind, codes, end, direction, s, node, _count_arcs(order, kind, codes, direction)))
    del order
    _planar_at_both_nodes(arcs.ends)
    return arcs


@njit(cache=True, nogil=True)
def _planar_at_both_nodes(ends):
    """Lines lying in a face's plane at one node lie in it all along the arc (a plane holds the whole swath or
    meets it in one line, a node): a node whose end line pokes past that face reports where it ends. Sets both
    nodes' end on a side to END_PLANAR where one has it; ends (A, 2, 2) int32 (arc, node, side), in place.
    (numpy's any over the middle axis of two took 2 ms for office-84's 21 580 arcs.)"""
    for arc in range(ends.shape[0]):
        for side in range(2):
            if ends[arc, 0, side] == END_PLANAR or ends[arc, 1, side] == END_PLANAR:
                ends[arc, 0, side] = END_PLANAR
                ends[arc, 1, side] = END_PLANAR


#: longest run of one key sorted by insertion (quadratic); longer ones by a merge sort
_INSERTION_RUN = 32


def _by_key_then_s(kind, codes, s) -> np.ndarray:
    """(M,) int32 the incidences (kind (M,) int8, codes (M, 3) int32, s (M,) float64) sorted by kind, then
    generators, then s; ties in index order (np.lexsort's order). The key (kind, generators) packed into one
    int64 when it fits is sorted once; each run of one key, a handful of incidences, then by s."""
    bits = (int(codes.max(initial=-1)) + 2).bit_length()
    if int(kind.min(initial=0)) < 0 or 3 * bits + int(kind.max(initial=0)).bit_length() > 63:
        return np.lexsort((s, codes[:, 2], codes[:, 1], codes[:, 0], kind)).astype(np.int32)
    key = kind.astype(np.int64)
    for column in range(3):
        key <<= bits
        key += codes[:, column]
        key += 1
    order = np.argsort(key, kind="stable").astype(np.int32)
    _runs_by_s(order, key, s)
    return order


@njit(cache=True, nogil=True)
def _runs_by_s(order, key, s):
    """Sort each run of equal key[order] (M,) int64 in `order` (M,) int32 by s (M,) float64, stably, NaN last
    as np.lexsort puts it: most runs are a handful of incidences, sorted by insertion in place."""
    m = len(order)
    i = 0
    while i < m:
        j = i + 1
        while j < m and key[order[j]] == key[order[i]]:
            j += 1
        if j - i > _INSERTION_RUN:
            run = order[i:j].copy()
            order[i:j] = run[np.argsort(s[run], kind="mergesort")]
            i = j
            continue
        for p in range(i + 1, j):
            moving = order[p]
            value = s[moving]
            q = p
            while q > i and _before(value, s[order[q - 1]]):
                order[q] = order[q - 1]
                q -= 1
            order[q] = moving
        i = j


@njit_leaf
def _before(x, y):
    """Whether x sorts strictly before y, NaN after every number."""
    return x < y or (y != y and x == x)


@njit_leaf
def _same_key(kind, codes, i, j):
    """Whether incidences i and j have the same arc key (kind, generators)."""
    return (kind[i] == kind[j] and codes[i, 0] == codes[j, 0] and codes[i, 1] == codes[j, 1]
            and codes[i, 2] == codes[j, 2])


@njit(cache=True, nogil=True)
def _ends_first(order, kind, codes, s, edge_tol, n_vertices, direction, node):
    """The incidences sorted by key then s (`order` (M,) int32), reordered so that within each run of
    coordinates closer than the tolerance to the run's first the ends (direction -1) come before the starts;
    an incidence repeating one of its run (same node, same direction: merged nodes) is left out. The result
    is a prefix of `order`, overwritten."""
    m = len(order)
    run = np.empty(16, dtype=order.dtype)
    k = 0
    i = 0
    while i < m:
        first = order[i]
        # one key, one parameter edge: the lowest edge generator
        edge = 2**31
        for column in range(3):
            if codes[first, column] >= n_vertices:
                edge = min(edge, codes[first, column] - n_vertices)
        gap = edge_tol[edge]
        j = i + 1
        while j < m and _same_key(kind, codes, first, order[j]) and s[order[j]] - s[first] <= gap:
            j += 1
        if j - i > len(run):
            run = np.empty(2 * (j - i), dtype=order.dtype)
        for x in range(j - i):
            run[x] = order[i + x]
        begin = k
        for kept in (-1, 1):
            for x in range(j - i):
                r = run[x]
                if direction[r] != kept:
                    continue
                repeated = False
                for q in range(begin, k):
                    if node[order[q]] == node[r] and direction[order[q]] == kept:
                        repeated = True
                        break
                if not repeated:
                    order[k] = r
                    k += 1
        i = j
    return order[:k]


@njit(cache=True, nogil=True)
def _count_arcs(order, kind, codes, direction):
    """How many arcs `_pair` makes of the incidences in `order`."""
    count = 0
    pending = False
    for i in range(len(order)):
        r = order[i]
        if pending and not _same_key(kind, codes, order[i - 1], r):
            count += 1
            pending = False
        if direction[r] > 0:
            if pending:
                count += 1
            pending = True
        else:
            count += 1
            pending = False
    return count + (1 if pending else 0)


@njit(cache=True, nogil=True)
def _pair(order, kind, codes, end, direction, s, node, n_arcs):
    """The arcs (fields of Arcs, planar ends not spread yet): each incidence in `order` that starts an arc
    paired with the next one ending it, if of the same key; an incidence left alone is a dangling arc."""
    out_kind = np.empty(n_arcs, dtype=np.int8)
    out_codes = np.empty((n_arcs, 3), dtype=np.int32)
    out_node = np.full((n_arcs, 2), -1, dtype=np.int32)
    out_s = np.full((n_arcs, 2), np.nan)
    out_ends = np.empty((n_arcs, 2, 2), dtype=end.dtype)
    count = 0
    pending = -1
    for i in range(len(order) + 1):
        r = order[i] if i < len(order) else -1
        if pending >= 0 and (r < 0 or direction[r] > 0 or not _same_key(kind, codes, pending, r)):
            # a start not ended: by the end, another start or another key
            _arc(count, pending, pending, kind, codes, end, out_kind, out_codes, out_ends)
            out_node[count, 0] = node[pending]
            out_s[count, 0] = s[pending]
            count += 1
            pending = -1
        if r < 0:
            break
        if direction[r] > 0:
            pending = r
            continue
        if pending >= 0:
            _arc(count, pending, r, kind, codes, end, out_kind, out_codes, out_ends)
            out_node[count, 0] = node[pending]
            out_s[count, 0] = s[pending]
            pending = -1
        else:
            _arc(count, r, r, kind, codes, end, out_kind, out_codes, out_ends)
        out_node[count, 1] = node[r]
        out_s[count, 1] = s[r]
        count += 1
    return out_kind, out_codes, out_node, out_s, out_ends


@njit_leaf
def _arc(row, start, stop, kind, codes, end, out_kind, out_codes, out_ends):
    """Arc `row` keyed by incidence `start`, its ends as found there and at incidence `stop`."""
    out_kind[row] = kind[start]
    for k in range(3):
        out_codes[row, k] = codes[start, k]
    for k in range(end.shape[1]):
        out_ends[row, 0, k] = end[start, k]
        out_ends[row, 1, k] = end[stop, k]
