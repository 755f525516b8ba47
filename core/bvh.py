"""Bounding volume hierarchy over axis-aligned boxes (the polygons of a scene), float64 throughout.

The skeleton finds its nodes by casting many rays and by culling candidate blockers against shafts
(Durand et al. 1997, sections 3.2.1-3.2.2; Durand et al. 1999, section 2.2). Both queries go through this
tree: `core.raycast` walks it along segments, and other numba kernels call `bvh_collect_in_planes` to gather
the primitives whose box meets a convex region (a shaft, a double wedge, a pyramid).

Layout (flat arrays, M nodes, P primitives): node_min, node_max (M, 3) boxes; node_child (M,) index of the
first child, the second child being node_child + 1, or -1 for a leaf; node_first, node_count (M,) the leaf's
range in `order` (count 0 for inner nodes); order (P,) primitive ids; box_min, box_max (P, 3) the (grown)
primitive boxes, tested one by one in the leaves. Node 0 is the root.

The build is binned SAH over the box centroids on all three axes; below `_SAH_DEPTH` levels it falls back to
object-median splits, so the depth stays below `STACK_SIZE` and every traversal can use a fixed stack.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from .errors import SceneError
from .jit import njit_leaf

STACK_SIZE = 128
"""Traversal stack length; the build guarantees depth + 1 <= STACK_SIZE."""

LEAF_SIZE = 4
"""Largest number of primitives in a leaf."""

_SAH_BINS = 16
_SAH_DEPTH = 48


@dataclass(frozen=True, eq=False)
class BVH:
    """A bounding volume hierarchy; every array is read-only.

    node_min, node_max (M, 3) float64; node_child, node_first, node_count (M,) int64; order (P,) int64;
    box_min, box_max (P, 3) float64 primitive boxes (grown by pad); depth: levels below the root;
    pad: how far each primitive box was grown on every side at build time.
    """

    node_min: np.ndarray
    node_max: np.ndarray
    node_child: np.ndarray
    node_first: np.ndarray
    node_count: np.ndarray
    order: np.ndarray
    box_min: np.ndarray
    box_max: np.ndarray
    depth: int
    pad: float

    @property
    def n_nodes(self) -> int:
        return len(self.node_child)

    @property
    def n_primitives(self) -> int:
        return len(self.order)

    @property
    def arrays(self) -> tuple:
        """The leading arguments of every numba traversal helper, in order:
        (node_min, node_max, node_child, node_first, node_count, order, box_min, box_max),
        e.g. `bvh_collect_in_planes(*bvh.arrays, planes, 0.0, out)`."""
        return (
            self.node_min,
            self.node_max,
            self.node_child,
            self.node_first,
            self.node_count,
            self.order,
            self.box_min,
            self.box_max,
        )

    def query_planes(self, planes, slack: float = 0.0) -> np.ndarray:
        """Sorted primitive ids whose box is not cut away by any of the half-spaces n . x + d <= 0.

        planes: (K, 3+1) float64 rows (n_x, n_y, n_z, d), n need not be unit; slack: a distance added to
        every half-space. Returns (Q,) int64. See `bvh_collect_in_planes` for the exact criterion.
        """
        rows = np.array(planes, dtype=np.float64, copy=True)
        if rows.ndim != 2 or rows.shape[1] != 4:
            raise ValueError(f"planes must have shape (K, 4), got {rows.shape}")
        if not np.isfinite(rows).all():
            raise ValueError("planes must be finite")
        if not np.isfinite(slack) or slack < 0.0:
            raise ValueError(f"slack must be a finite distance >= 0, got {slack}")
        out = np.empty(max(self.n_primitives, 1), dtype=np.int64)
        count = bvh_collect_in_planes(*self.arrays, rows, float(slack), out)
        return np.sort(out[:count])

    def query_segment(self, start, end) -> np.ndarray:
        """Sorted primitive ids whose box meets the closed segment start-end (3,). Returns (Q,) int64."""
        a = _point(start, "start")
        b = _point(end, "end")
        out = np.empty(max(self.n_primitives, 1), dtype=np.int64)
        count = bvh_collect_on_segment(*self.arrays, a, b, out)
        return np.sort(out[:count])


def build_bvh(scene) -> BVH:
    """The BVH of a scene's polygon boxes, each grown by scene.tol.length so flat boxes stay hittable."""
    return build_bvh_from_boxes(scene.polygon_min, scene.polygon_max, pad=scene.tol.length)


def build_bvh_from_boxes(box_min, box_max, pad: float = 0.0) -> BVH:
    """The BVH of P boxes box_min, box_max (P, 3) float64 (min <= max), each grown by `pad` >= 0."""
    lo = np.array(box_min, dtype=np.float64, copy=True)
    hi = np.array(box_max, dtype=np.float64, copy=True)
    for name, array in (("box_min", lo), ("box_max", hi)):
        if array.ndim != 2 or array.shape[1] != 3:
            raise SceneError(f"{name} must have shape (P, 3), got {array.shape}")
        if not np.isfinite(array).all():
            bad = int(np.argwhere(~np.isfinite(array))[0, 0])
            raise SceneError(f"{name} has a non-finite coordinate (box {bad})")
    if lo.shape != hi.shape:
        raise SceneError(f"box_min {lo.shape} and box_max {hi.shape} must have the same shape")
    if len(lo) == 0:
        raise SceneError("a BVH needs at least one box")
    inverted = np.any(lo > hi, axis=1)
    if inverted.any():
        raise SceneError(f"box {int(np.flatnonzero(inverted)[0])} has box_min > box_max")
    if not np.isfinite(pad) or pad < 0.0:
        raise SceneError(f"pad must be a finite distance >= 0, got {pad}")
    lo -= pad
    hi += pad
    node_min, node_max, node_child, node_first, node_count, order, depth = _build(lo, hi)
    if depth + 1 > STACK_SIZE:
        raise SceneError(f"BVH depth {depth} exceeds the traversal stack ({STACK_SIZE})")
    arrays = [node_min, node_max, node_child, node_first, node_count, order, lo, hi]
    for array in arrays:
        array.flags.writeable = False
    return BVH(*arrays, depth=int(depth), pad=float(pad))


def _point(value, name: str) -> np.ndarray:
    array = np.array(value, dtype=np.float64, copy=True)
    if array.shape != (3,):
        raise ValueError(f"{name} must have shape (3,), got {array.shape}")
    if not np.isfinite(array).all():
        raise ValueError(f"{name} must be finite, got {array.tolist()}")
    return array


@njit(cache=True)
def _half_area(lo, hi):
    ex = hi[0] - lo[0]
    ey = hi[1] - lo[1]
    ez = hi[2] - lo[2]
    return ex * ey + ey * ez + ez * ex


@njit(cache=True)
def _build(box_min, box_max):
    count = box_min.shape[0]
    capacity = 2 * count
    node_min = np.empty((capacity, 3))
    node_max = np.empty((capacity, 3))
    node_child = np.full(capacity, -1, dtype=np.int64)
    node_first = np.zeros(capacity, dtype=np.int64)
    node_count = np.zeros(capacity, dtype=np.int64)
    order = np.arange(count).astype(np.int64)
    centre = 0.5 * (box_min + box_max)

    # pending work: node, first, end (exclusive), depth
    tasks = np.empty((capacity, 4), dtype=np.int64)
    tasks[0, 0] = 0
    tasks[0, 1] = 0
    tasks[0, 2] = count
    tasks[0, 3] = 0
    n_tasks = 1
    n_nodes = 1
    max_depth = 0
    bin_min = np.empty((_SAH_BINS, 3))
    bin_max = np.empty((_SAH_BINS, 3))
    bin_count = np.empty(_SAH_BINS, dtype=np.int64)
    right_area = np.empty(_SAH_BINS)
    right_count = np.empty(_SAH_BINS, dtype=np.int64)
    lo = np.empty(3)
    hi = np.empty(3)
    while n_tasks > 0:
        n_tasks -= 1
        node = tasks[n_tasks, 0]
        first = tasks[n_tasks, 1]
        end = tasks[n_tasks, 2]
        depth = tasks[n_tasks, 3]
        if depth > max_depth:
            max_depth = depth
        c_lo = np.full(3, np.inf)
        c_hi = np.full(3, -np.inf)
        for axis in range(3):
            node_min[node, axis] = np.inf
            node_max[node, axis] = -np.inf
        for i in range(first, end):
            prim = order[i]
            for axis in range(3):
                node_min[node, axis] = min(node_min[node, axis], box_min[prim, axis])
                node_max[node, axis] = max(node_max[node, axis], box_max[prim, axis])
                c_lo[axis] = min(c_lo[axis], centre[prim, axis])
                c_hi[axis] = max(c_hi[axis], centre[prim, axis])
        n = end - first
        if n <= LEAF_SIZE:
            node_first[node] = first
            node_count[node] = n
            continue

        best_axis = -1
        best_split = -1
        best_cost = np.inf
        if depth < _SAH_DEPTH:
            for axis in range(3):
                extent = c_hi[axis] - c_lo[axis]
                if not extent > 0.0:
                    continue
                scale = _SAH_BINS / extent
                for b in range(_SAH_BINS):
                    bin_count[b] = 0
                    for k in range(3):
                        bin_min[b, k] = np.inf
                        bin_max[b, k] = -np.inf
                for i in range(first, end):
                    prim = order[i]
                    b = min(int((centre[prim, axis] - c_lo[axis]) * scale), _SAH_BINS - 1)
                    bin_count[b] += 1
                    for k in range(3):
                        bin_min[b, k] = min(bin_min[b, k], box_min[prim, k])
                        bin_max[b, k] = max(bin_max[b, k], box_max[prim, k])
                # sweep from the right, then from the left: cost of splitting after bin b
                acc = 0
                for k in range(3):
                    lo[k] = np.inf
                    hi[k] = -np.inf
                for b in range(_SAH_BINS - 1, 0, -1):
                    acc += bin_count[b]
                    for k in range(3):
                        lo[k] = min(lo[k], bin_min[b, k])
                        hi[k] = max(hi[k], bin_max[b, k])
                    right_count[b - 1] = acc
                    right_area[b - 1] = _half_area(lo, hi) if acc > 0 else 0.0
                acc = 0
                for k in range(3):
                    lo[k] = np.inf
                    hi[k] = -np.inf
                for b in range(_SAH_BINS - 1):
                    acc += bin_count[b]
                    for k in range(3):
                        lo[k] = min(lo[k], bin_min[b, k])
                        hi[k] = max(hi[k], bin_max[b, k])
                    if acc == 0 or right_count[b] == 0:
                        continue
                    cost = _half_area(lo, hi) * acc + right_area[b] * right_count[b]
                    if cost < best_cost:
                        best_cost = cost
                        best_axis = axis
                        best_split = b

        if best_axis >= 0:
            scale = _SAH_BINS / (c_hi[best_axis] - c_lo[best_axis])
            i = first
            j = end - 1
            while i <= j:
                b = min(int((centre[order[i], best_axis] - c_lo[best_axis]) * scale), _SAH_BINS - 1)
                if b <= best_split:
                    i += 1
                else:
                    tmp = order[i]
                    order[i] = order[j]
                    order[j] = tmp
                    j -= 1
            middle = i
        else:
            # too deep for SAH, or all centroids coincide: halve the range along the widest centroid axis
            axis = 0
            for k in range(1, 3):
                if c_hi[k] - c_lo[k] > c_hi[axis] - c_lo[axis]:
                    axis = k
            keys = np.empty(n)
            for i in range(n):
                keys[i] = centre[order[first + i], axis]
            sorted_ids = order[first:end][np.argsort(keys, kind="mergesort")]
            order[first:end] = sorted_ids
            middle = first + n // 2

        child = n_nodes
        n_nodes += 2
        node_child[node] = child
        tasks[n_tasks, 0] = child
        tasks[n_tasks, 1] = first
        tasks[n_tasks, 2] = middle
        tasks[n_tasks, 3] = depth + 1
        tasks[n_tasks + 1, 0] = child + 1
        tasks[n_tasks + 1, 1] = middle
        tasks[n_tasks + 1, 2] = end
        tasks[n_tasks + 1, 3] = depth + 1
        n_tasks += 2
    return (
        node_min[:n_nodes].copy(),
        node_max[:n_nodes].copy(),
        node_child[:n_nodes].copy(),
        node_first[:n_nodes].copy(),
        node_count[:n_nodes].copy(),
        order,
        max_depth,
    )


@njit_leaf
def box_outside_plane(box_lo, box_hi, nx, ny, nz, d, slack):
    """True when the whole box lies in n . x + d > slack * |n| (the box misses the grown half-space)."""
    lowest = d
    lowest += nx * (box_lo[0] if nx > 0.0 else box_hi[0])
    lowest += ny * (box_lo[1] if ny > 0.0 else box_hi[1])
    lowest += nz * (box_lo[2] if nz > 0.0 else box_hi[2])
    return lowest > slack * np.sqrt(nx * nx + ny * ny + nz * nz)


@njit_leaf
def _box_outside_planes(lo, hi, row, planes, slack):
    """Whether one half-space of planes (K, 4) cuts away box `row` of lo, hi (N, 3) (box_outside_plane). The
    arrays and the row, not the row's views: a view costs two atomic reference counts, and the shaft queries
    of the exact views test every node."""
    for k in range(planes.shape[0]):
        nx = planes[k, 0]
        ny = planes[k, 1]
        nz = planes[k, 2]
        lowest = planes[k, 3]
        lowest += nx * (lo[row, 0] if nx > 0.0 else hi[row, 0])
        lowest += ny * (lo[row, 1] if ny > 0.0 else hi[row, 1])
        lowest += nz * (lo[row, 2] if nz > 0.0 else hi[row, 2])
        if lowest > slack * np.sqrt(nx * nx + ny * ny + nz * nz):
            return True
    return False


@njit(cache=True)
def bvh_collect_in_planes(
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, planes, slack, out
):
    """Gather the primitives whose box no single half-space of a convex region cuts away.

    Numba-callable (also from plain Python). Arguments:
        node_min, node_max (M, 3) float64, node_child, node_first, node_count (M,) int64, order (P,) int64,
            box_min, box_max (P, 3) float64: the arrays of a `BVH`, in its field order;
        planes (K, 4) float64: rows (n_x, n_y, n_z, d), the region being {x : n . x + d <= 0 for every row};
            n need not be unit; K = 0 means all space;
        slack float64 >= 0: every half-space is grown by this distance (pass tol.length to be conservative);
        out (C,) int64: filled with primitive ids in traversal order (unsorted).
    Returns the number Q of primitives found. Only min(Q, C) ids are written: when Q > C, call again with a
    buffer of at least Q. A box is reported unless one half-space excludes it entirely, the standard
    conservative culling test (a box near a corner of the region may be reported without meeting it).
    """
    capacity = out.shape[0]
    found = 0
    stack = np.empty(STACK_SIZE, dtype=np.int64)
    stack[0] = 0
    top = 1
    n_planes = planes.shape[0]
    while top > 0:
        top -= 1
        node = stack[top]
        if _box_outside_planes(node_min, node_max, node, planes, slack):
            continue
        child = node_child[node]
        if child < 0:
            start = node_first[node]
            for i in range(start, start + node_count[node]):
                prim = order[i]
                if n_planes > 0 and _box_outside_planes(box_min, box_max, prim, planes, slack):
                    continue
                if found < capacity:
                    out[found] = prim
                found += 1
        else:
            stack[top] = child
            stack[top + 1] = child + 1
            top += 2
    return found


@njit(cache=True)
def segment_box_range(start, inv_direction, direction, box_lo, box_hi, t_lo, t_hi):
    """Clip the parameter range [t_lo, t_hi] of start + t * direction to a closed box.

    start, direction, inv_direction (3,) float64 arrays or 3-tuples (inv_direction[k] = 1 / direction[k], unused where
    direction[k] == 0), box_lo, box_hi (3,). Returns (entry, exit); entry > exit means a miss.
    """
    entry = t_lo
    leave = t_hi
    for k in range(3):
        if direction[k] == 0.0:
            if start[k] < box_lo[k] or start[k] > box_hi[k]:
                return 1.0, 0.0
        else:
            a = (box_lo[k] - start[k]) * inv_direction[k]
            b = (box_hi[k] - start[k]) * inv_direction[k]
            if a > b:
                a, b = b, a
            if a > entry:
                entry = a
            if b < leave:
                leave = b
            if entry > leave:
                return entry, leave
    return entry, leave


@njit(cache=True)
def inverse_direction(direction):
    """3-tuple of the reciprocals of the direction's components, 0 where a component is 0 (never used there)."""
    return (
        1.0 / direction[0] if direction[0] != 0.0 else 0.0,
        1.0 / direction[1] if direction[1] != 0.0 else 0.0,
        1.0 / direction[2] if direction[2] != 0.0 else 0.0,
    )


@njit(cache=True)
def bvh_collect_on_segment(
    node_min, node_max, node_child, node_first, node_count, order, box_min, box_max, start, end, out
):
    """Gather the primitives whose box meets the closed segment start-end (3,) float64.

    Same BVH arrays, `out` buffer and return convention as `bvh_collect_in_planes`.
    """
    direction = end - start
    inv = inverse_direction(direction)
    capacity = out.shape[0]
    found = 0
    stack = np.empty(STACK_SIZE, dtype=np.int64)
    stack[0] = 0
    top = 1
    while top > 0:
        top -= 1
        node = stack[top]
        entry, leave = segment_box_range(start, inv, direction, node_min[node], node_max[node], 0.0, 1.0)
        if entry > leave:
            continue
        child = node_child[node]
        if child < 0:
            first = node_first[node]
            for i in range(first, first + node_count[node]):
                prim = order[i]
                entry, leave = segment_box_range(start, inv, direction, box_min[prim], box_max[prim], 0.0, 1.0)
                if entry > leave:
                    continue
                if found < capacity:
                    out[found] = prim
                found += 1
        else:
            stack[top] = child
            stack[top + 1] = child + 1
            top += 2
    return found
