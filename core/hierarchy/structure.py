"""HPolygon / HTriangulation / HEdge: the hierarchy of constrained Delaunay triangulations (section 3.1).

Elements are numbered globally: element p < P is input polygon p (an HPolygon, level 0); every other element
is a triangle of the constrained Delaunay triangulation (an HTriangulation, built with pythoncdt) that
subdivides its parent. The children of an element are created together and have consecutive ids.

HEdges are segments shared by every element, at any level, whose side is exactly that segment; splitting an
HEdge at a vertex gives it two sub-HEdges. Inserting a point on an element's side splits the HEdge there
(the same vertex for the neighbour: matching); after each subdivision step every leaf whose side was split
is subdivided with the split points (anchoring), so leaves conform. Sides of different input polygons with
the same two endpoints are twins: splitting one splits the others at the same 3-D point.
"""

import copy
import functools
import math

import numpy as np
import pythoncdt
from scipy.spatial import cKDTree

from ..errors import VisradError
from .frames import build_frames, shared_edges
from .geometry import (
    barycentric,
    clip_segment_to_polygon,
    cross2,
    side_parameters,
)
from .grid import GridSettings, interior_grid_points, side_grid_parameters
from .shape import ShapeSettings, fan_min_angle, piece_feet

# The triangulation works on integers, 1/1024 of the length tolerance: points further apart than the
# tolerance never share a cell, needles a few tolerances wide keep their shape, and coordinates stay far
# below 2**53 (1e12 units across the scene). pythoncdt's own snapping to constraints is off (0.0): the
# hierarchy snaps to sides itself, and snapping inside needles would break the ring.
_CDT_UNITS_PER_TOLERANCE = 1024.0

_NO_POINTS = np.zeros((0, 2))
_NO_IDS = np.zeros(0, dtype=np.int64)
_NO_KINDS = np.zeros(0, dtype=np.int8)

# What made a vertex (its provenance, for the quality statistics): a polygon corner, the regular grid, an
# inserted point, or a constrained segment (an end, a crossing, or where it crosses an element side).
CORNER, GRID, POINT, SEGMENT = 0, 1, 2, 3

# Point location compares points with all children of an element at once; this bounds that array's size.
_LOCATE_BATCH = 1 << 20


class _Column:
    """A growable array of rows: amortised O(1) append, views of the filled part without copying."""

    def __init__(self, width: int, dtype, fill):
        self._width = width
        self._fill = fill
        self.buf = np.full((256, width) if width else 256, fill, dtype=dtype)
        self.size = 0

    def grow(self, count: int) -> int:
        """Reserve `count` rows; return the index of the first."""
        start = self.size
        need = start + count
        if need > len(self.buf):
            capacity = max(need, 2 * len(self.buf))
            bigger = np.full((capacity, self._width) if self._width else capacity, self._fill, dtype=self.buf.dtype)
            bigger[:start] = self.buf[:start]
            self.buf = bigger
        self.size = need
        return start

    @property
    def data(self) -> np.ndarray:
        return self.buf[: self.size]

    def __deepcopy__(self, memo) -> "_Column":
        twin = object.__new__(_Column)
        twin._width, twin._fill, twin.buf, twin.size = self._width, self._fill, self.buf.copy(), self.size
        return twin


class HierarchyCore:
    """The hierarchical triangulations of a set of convex planar polygons (see the package docstring)."""

    def __init__(self, polygons: list, tolerance, grid: GridSettings | None = None,
                 shape: ShapeSettings | None = None):
        self.polygons = [np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in polygons]
        for i, p in enumerate(self.polygons):
            if len(p) < 3:
                raise ValueError(f"polygon {i}: needs at least 3 corners, got {len(p)}")
        self.tol = tolerance
        self.eps = float(tolerance.length)
        self.grid = grid or GridSettings()
        self.shape = shape or ShapeSettings()
        self.frames = build_frames(self.polygons, self.eps)
        self.polygon_count = len(self.polygons)

        # vertices
        self._xy = _Column(2, np.float64, 0.0)
        self._v_polygon = _Column(0, np.int64, -1)
        self._v_level = _Column(0, np.int64, -1)
        self._v_element = _Column(0, np.int64, -1)
        self._v_anc = _Column(3, np.int64, -1)
        self._v_w = _Column(3, np.float64, 0.0)
        self._v_constrained = _Column(0, np.bool_, False)
        self._v_kind = _Column(0, np.int8, CORNER)
        # elements
        self._e_polygon = _Column(0, np.int64, -1)
        self._e_level = _Column(0, np.int64, 0)
        self._e_parent = _Column(0, np.int64, -1)
        self._e_vertices = _Column(3, np.int64, -1)
        self._e_hedges = _Column(3, np.int64, -1)
        self._e_first_child = _Column(0, np.int64, -1)
        self._e_child_count = _Column(0, np.int64, 0)
        # HEdges: plain lists, because the matching walks them one node at a time
        self._he_a: list[int] = []
        self._he_b: list[int] = []
        self._he_kids: list = []
        self._he_split: list[int] = []
        self._he_parent: list[int] = []
        self._he_elements: list[list[int]] = []
        self._he_constrained: list[bool] = []
        self._he_twins: dict[int, list] = {}
        self._dirty: list[int] = []
        self._queue: dict[int, list] = {}
        # inner segments left out of an element whose outline they crossed by a rounding error (see _subdivide)
        self.dropped_segments = 0

        self._root_corners: list[np.ndarray] = []
        self._root_hedges: list[list[int]] = []
        self._root_fans: list[np.ndarray] = []
        for p in range(self.polygon_count):
            self._add_root(p)
        for pa, sa, pb, sb, flipped in shared_edges(self.polygons, self.eps):
            ha = self._root_hedges[pa][sa]
            hb = self._root_hedges[pb][sb]
            self._he_twins.setdefault(ha, []).append((hb, flipped))
            self._he_twins.setdefault(hb, []).append((ha, flipped))

    # ------------------------------------------------------------------ construction helpers


    #: half-edge lists whose items are immutable (ints, bools, tuples, None) or lists of such: copied shallowly,
    #: one level down for the lists of lists
    _FLAT_LISTS = ("_he_a", "_he_b", "_he_kids", "_he_split", "_he_parent", "_he_constrained", "_dirty")
    _NESTED_LISTS = ("_he_elements", "_root_hedges")

    def __deepcopy__(self, memo) -> "HierarchyCore":
        """A copy sharing nothing mutable (the solver refines a copy and keeps the last good hierarchy). The
        generic walk of copy.deepcopy visits every int of the half-edge lists and leaves the garbage collector
        millions of objects to track: a fifth of the Cornell box solve's time."""
        twin = object.__new__(type(self))
        memo[id(self)] = twin
        for name, value in vars(self).items():
            if name in self._FLAT_LISTS:
                value = list(value)
            elif name in self._NESTED_LISTS:
                value = [list(items) for items in value]
            elif name == "_he_twins":
                value = {hedge: list(twins) for hedge, twins in value.items()}
            else:
                value = copy.deepcopy(value, memo)
            setattr(twin, name, value)
        return twin

    def _new_vertices(self, polygon: int, xy: np.ndarray, kind, constrained: bool = False) -> np.ndarray:
        count = len(xy)
        if count == 0:
            return _NO_IDS
        start = self._xy.grow(count)
        for column in (self._v_polygon, self._v_level, self._v_element, self._v_anc, self._v_w, self._v_kind):
            column.grow(count)
        self._v_constrained.grow(count)
        self._xy.buf[start : start + count] = xy
        self._v_polygon.buf[start : start + count] = polygon
        self._v_constrained.buf[start : start + count] = constrained
        self._v_kind.buf[start : start + count] = kind
        return np.arange(start, start + count)

    def _new_vertex(self, polygon: int, x: float, y: float, kind: int) -> int:
        """One vertex (see _new_vertices), without building arrays."""
        vertex = self._xy.grow(1)
        for column in (self._v_polygon, self._v_level, self._v_element, self._v_anc, self._v_w, self._v_kind):
            column.grow(1)
        self._v_constrained.grow(1)
        self._xy.buf[vertex] = (x, y)
        self._v_polygon.buf[vertex] = polygon
        self._v_constrained.buf[vertex] = False
        self._v_kind.buf[vertex] = kind
        return vertex

    def _new_hedge(self, a: int, b: int, constrained: bool = False) -> int:
        self._he_a.append(a)
        self._he_b.append(b)
        self._he_kids.append(None)
        self._he_split.append(-1)
        self._he_parent.append(-1)
        self._he_elements.append([])
        self._he_constrained.append(constrained)
        return len(self._he_a) - 1

    def _new_elements(self, count: int, polygon: int, level: int, parent: int) -> int:
        start = self._e_polygon.grow(count)
        for column in (
            self._e_level, self._e_parent, self._e_vertices, self._e_hedges, self._e_first_child,
            self._e_child_count,
        ):
            column.grow(count)
        self._e_polygon.buf[start : start + count] = polygon
        self._e_level.buf[start : start + count] = level
        self._e_parent.buf[start : start + count] = parent
        return start

    def _add_root(self, p: int) -> None:
        corners_2d = self.frames.corners_2d[p]
        ids = self._new_vertices(p, corners_2d, CORNER)
        self._v_level.buf[ids] = 0
        element = self._new_elements(1, p, 0, -1)
        assert element == p
        hedges = []
        k = len(ids)
        for i in range(k):
            h = self._new_hedge(int(ids[i]), int(ids[(i + 1) % k]))
            self._he_elements[h].append(element)
            hedges.append(h)
        self._root_corners.append(ids)
        self._root_hedges.append(hedges)
        # Below the first subdivision a polygon's radiosity is linear on a fan of its corners.
        self._root_fans.append(np.stack([np.full(k - 2, ids[0]), ids[1:-1], ids[2:]], axis=1))

    # ------------------------------------------------------------------ element queries

    def _sides(self, element: int) -> tuple:
        if element < self.polygon_count:
            return self._root_corners[element], self._root_hedges[element]
        return self._e_vertices.buf[element], self._e_hedges.buf[element]

    def is_leaf(self, element: int) -> bool:
        return self._e_child_count.buf[element] == 0

    def _chain(self, hedge: int, forward: bool) -> tuple:
        """Leaf sub-HEdges of hedge in side order, and the vertex each starts from: (vertices, leaves)."""
        leaves = []
        stack = [hedge]
        while stack:
            h = stack.pop()
            kids = self._he_kids[h]
            if kids is None:
                leaves.append(h)
            else:
                stack.append(kids[1])
                stack.append(kids[0])
        if forward:
            return [self._he_a[h] for h in leaves], leaves
        leaves.reverse()
        return [self._he_b[h] for h in leaves], leaves

    # ------------------------------------------------------------------ matching

    def _side_vertex(self, hedge: int, forward: bool, t_side: float, snap_distance: float, kind: int) -> int:
        """The vertex at parameter t_side along an element side (its HEdge `hedge`, in side order): an
        existing vertex within snap_distance, or a new one of provenance `kind` splitting the leaf sub-HEdge."""
        # Plain floats: this runs once per point on a side, and numpy's per-call overhead on 2-vectors
        # dominated grid steps.
        xy = self._xy.buf
        ax, ay = xy[self._he_a[hedge]].tolist()
        bx, by = xy[self._he_b[hedge]].tolist()
        t = t_side if forward else 1.0 - t_side
        dx, dy = bx - ax, by - ay
        length2 = dx * dx + dy * dy
        snap = snap_distance / math.sqrt(length2)

        def param(vertex: int) -> float:
            x, y = xy[vertex].tolist()
            return ((x - ax) * dx + (y - ay) * dy) / length2

        h = hedge
        while True:
            kids = self._he_kids[h]
            if kids is None:
                break
            ts = param(self._he_split[h])
            if abs(t - ts) <= snap:
                return self._he_split[h]
            h = kids[0] if t < ts else kids[1]
        ta = param(self._he_a[h])
        tb = param(self._he_b[h])
        if abs(t - ta) <= snap:
            return self._he_a[h]
        if abs(t - tb) <= snap:
            return self._he_b[h]
        return self._split_leaf(h, (t - ta) / (tb - ta), kind)

    def _split_leaf(self, hedge: int, t_local: float, kind: int) -> int:
        """Split a leaf HEdge and all its twins at local parameter t_local with new vertices of provenance
        `kind`; return hedge's new vertex."""
        group = [(hedge, False)] + self._he_twins.get(hedge, [])
        xy = self._xy.buf
        low, high, made = [], [], []
        for member, flipped in group:
            a = self._he_a[member]
            b = self._he_b[member]
            t = 1.0 - t_local if flipped else t_local
            (ax, ay), (bx, by) = xy[a].tolist(), xy[b].tolist()
            vertex = self._new_vertex(int(self._v_polygon.buf[a]), ax + t * (bx - ax), ay + t * (by - ay), kind)
            xy = self._xy.buf
            constrained = self._he_constrained[member]
            first = self._new_hedge(a, vertex, constrained)
            second = self._new_hedge(vertex, b, constrained)
            self._he_parent[first] = self._he_parent[second] = member
            self._side_ancestry(member, vertex)
            self._he_kids[member] = (first, second)
            self._he_split[member] = vertex
            self._dirty.append(member)
            low.append((second, flipped) if flipped else (first, flipped))
            high.append((first, flipped) if flipped else (second, flipped))
            made.append(vertex)
        if len(group) > 1:
            for side in (low, high):
                for i, (h, fi) in enumerate(side):
                    self._he_twins[h] = [(g, fi ^ fj) for j, (g, fj) in enumerate(side) if j != i]
        return made[0]

    def _side_ancestry(self, hedge: int, vertex: int) -> None:
        """Ancestry of a new vertex splitting leaf HEdge `hedge`. It first appears in the sub-triangulations of
        the leaves whose side is `hedge` or an HEdge containing it (one per side, the coarser still waiting
        for anchoring); its ancestor is the coarsest of them, which keeps every ancestor at a lower level
        whichever is subdivided first. It interpolates between the ends of that leaf's side alone."""
        owner, side = -1, -1
        h = hedge
        while h >= 0:
            for e in self._he_elements[h]:
                if self._e_child_count.buf[e] == 0 and (owner < 0 or self._e_level.buf[e] < self._e_level.buf[owner]):
                    owner, side = e, h
            h = self._he_parent[h]
        a, b = self._he_a[side], self._he_b[side]
        if owner < self.polygon_count:
            corners = self._root_corners[owner].tolist()
            i, j = sorted((corners.index(a), corners.index(b)))
            # Side c_i c_j lies in fan triangle c_0 c_m c_(m+1): m = 1 for the first side, k - 2 for the last.
            fan = 0 if (i, j) == (0, 1) else (len(corners) - 3 if i == 0 else i - 1)
            ancestors = self._root_fans[owner][fan]
        else:
            ancestors = self._e_vertices.buf[owner]
        xy = self._xy.buf
        (ax, ay), (bx, by), (x, y) = xy[a].tolist(), xy[b].tolist(), xy[vertex].tolist()
        dx, dy = bx - ax, by - ay
        t = ((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy)
        self._v_level.buf[vertex] = self._e_level.buf[owner] + 1
        self._v_element.buf[vertex] = owner
        self._v_anc.buf[vertex] = ancestors
        self._v_w.buf[vertex] = [1.0 - t if c == a else (t if c == b else 0.0) for c in ancestors.tolist()]

    # ------------------------------------------------------------------ subdivision of one element

    def _subdivide(self, element: int, points: np.ndarray, segments: np.ndarray, step: float | None) -> bool:
        """Build the sub-triangulation of leaf `element` with points (M, 2), segments (S, 2, 2) clipped to
        it, the grid of spacing `step` (None: no grid) and every point already on its sides.
        Returns False when there was nothing to insert (the element stays a leaf)."""
        eps = self.eps
        snap = self.tol.snap
        corners, hedges = self._sides(element)
        corners = [int(c) for c in corners]
        hedges = [int(h) for h in hedges]
        k = len(corners)
        forward = [self._he_a[hedges[i]] == corners[i] for i in range(k)]
        corner_xy = self._xy.buf[corners]
        side_a = corner_xy
        side_b = np.concatenate([corner_xy[1:], corner_xy[:1]])
        side_vectors = side_b - side_a
        side_lengths = np.hypot(side_vectors[:, 0], side_vectors[:, 1])

        # Points inserted with a grid (light maxima) stay put and the grid avoids them, and so do points given
        # on a side (matching them is the point, Fig. 6); the others are free samples, moved where their
        # triangles stay well shaped.
        free = _NO_POINTS
        if step is None and self.shape.enabled and len(points):
            inside = cross2(side_vectors, points[:, None, :] - side_a) / side_lengths
            interior = inside.min(axis=1) > snap
            free = points[interior]
            points = points[~interior]
        features = np.concatenate([points, segments.reshape(-1, 2)]) if len(segments) else points
        feature_vertex = np.full(len(features), -1, dtype=np.int64)
        interior_xy = _NO_POINTS
        interior_kind = _NO_KINDS
        if len(features):
            t, distance = side_parameters(features, side_a, side_b)
            feature_sides = distance <= snap
            inside = cross2(side_vectors, features[:, None, :] - side_a) / side_lengths
            on_boundary = feature_sides.any(axis=1)
            ring_now = [v for s in range(k) for v in self._chain(hedges[s], forward[s])[0]]
            ring_xy = self._xy.buf[ring_now]
            for f in np.nonzero(on_boundary)[0]:
                # Near a sharp corner a point can be within the tolerance of a vertex on another side.
                gap = np.hypot(*(ring_xy - features[f]).T)
                if gap.min() <= snap:
                    feature_vertex[f] = ring_now[int(np.argmin(gap))]
                    continue
                s = int(np.argmin(distance[f]))
                kind = POINT if f < len(points) else SEGMENT
                feature_vertex[f] = self._side_vertex(hedges[s], forward[s], float(t[f, s]), snap, kind)
            interior = np.nonzero(~on_boundary & (inside.min(axis=1) > 0.0))[0]
            unique_xy, representative = _merge_close(features[interior], snap)
            feature_vertex[interior] = -2 - representative
            interior_xy = unique_xy
            # A point merged with a segment end lies on the segment: the segment made it.
            interior_kind = np.full(len(unique_xy), POINT, dtype=np.int8)
            np.maximum.at(interior_kind, representative, np.where(interior < len(points), POINT, SEGMENT))
        if len(free):
            placed = self._place_free_points(element, free, interior_xy)
            interior_xy = np.concatenate([interior_xy, placed])
            interior_kind = np.concatenate([interior_kind, np.full(len(placed), POINT, dtype=np.int8)])

        seg_ends = feature_vertex[len(points) :].reshape(-1, 2)
        if len(seg_ends):
            seg_sides = feature_sides[len(points) :].reshape(-1, 2, k)
            keep = (seg_ends[:, 0] != seg_ends[:, 1]) & (seg_ends != -1).all(axis=1)
            keep &= ~(seg_sides[:, 0] & seg_sides[:, 1]).any(axis=1)
            seg_ends = seg_ends[keep]
            kept_segments = segments[keep]
        else:
            kept_segments = segments

        # the side chains known not to have changed since they were walked
        chains = [None] * k
        if step is not None:
            radius = self.grid.skip_radius * step
            feature_xy = features[feature_vertex != -1]
            for s in range(k):
                chain, leaves = self._chain(hedges[s], forward[s])
                away = np.concatenate([self._xy.buf[chain], feature_xy]) if len(feature_xy) else self._xy.buf[chain]
                grid_t = side_grid_parameters(side_a[s], side_b[s], step, away, radius, eps)
                for tg in grid_t.tolist():
                    self._side_vertex(hedges[s], forward[s], tg, eps, GRID)
                if len(grid_t) == 0:
                    chains[s] = chain, leaves
            grid_xy = interior_grid_points(corner_xy, step, feature_xy, kept_segments, radius, eps)
            if len(grid_xy):
                interior_xy = np.concatenate([interior_xy, grid_xy])
                interior_kind = np.concatenate([interior_kind, np.full(len(grid_xy), GRID, dtype=np.int8)])

        ring, ring_hedges = [], []
        for s in range(k):
            chain, leaves = chains[s] or self._chain(hedges[s], forward[s])
            ring.extend(chain)
            ring_hedges.extend(leaves)
        n_ring = len(ring)
        # an element whose corners lie on one line within the tolerance (integer rounding in the triangulation
        # of its parent can leave such a needle, even turned over): nothing fits inside it, and a triangulation
        # of its outline would see the outline cross itself. Its points go elsewhere; its sides are joined by a
        # fan so that the leaves around still conform.
        if k == 3:
            (ux, uy), (wx, wy) = side_vectors[0].tolist(), side_vectors[2].tolist()
            needle = wx * uy - wy * ux <= eps * max(side_lengths.tolist())
        else:
            needle = False
        if needle:
            interior_xy, interior_kind = _NO_POINTS, _NO_KINDS
            seg_ends = seg_ends[:0]
        if n_ring == k and len(interior_xy) == 0 and len(seg_ends) == 0:
            return False

        polygon = int(self._e_polygon.buf[element])
        interior_ids = self._new_vertices(polygon, interior_xy, interior_kind)
        ring_position = {v: i for i, v in enumerate(ring)}
        seg_local = np.array(
            [[ring_position[v] if v >= 0 else n_ring - 2 - v for v in pair] for pair in seg_ends.tolist()],
            dtype=np.int64,
        ).reshape(-1, 2)

        cdt_xy = np.concatenate([self._xy.buf[ring], interior_xy])
        origin = corner_xy[0]
        unit = eps / _CDT_UNITS_PER_TOLERANCE
        if needle:
            cdt = None
            made = len(cdt_xy)
            triangles = np.array([[0, i, i + 1] for i in range(1, n_ring - 1)], dtype=np.int64)
        else:
            pieces = _split_at_points(cdt_xy, seg_local, snap) if len(seg_local) else seg_local
            triangles, cdt = _triangulate(cdt_xy, origin, unit, n_ring, pieces)
            if cdt.vertices_count() > len(cdt_xy) and len(seg_local) < 2:
                # A point made where no two inner segments cross: a segment ending a rounding error beyond the
                # element's outline crossed it. The element is triangulated without its segments (the mesh does
                # not follow them here; their ends stay vertices), which the statistics count.
                self.dropped_segments += len(seg_local)
                seg_local = seg_local[:0]
                triangles, cdt = _triangulate(cdt_xy, origin, unit, n_ring, seg_local)
            made = cdt.vertices_count()
        crossing_ids = _NO_IDS
        # where the triangulation's points go: a crossing that lands on a point already there is that point
        local = np.arange(made)
        if made > len(cdt_xy):
            out_xy = cdt.vertices_array()
            estimates = np.stack([out_xy["x"][len(cdt_xy) :], out_xy["y"][len(cdt_xy) :]], axis=1) * unit + origin
            crossings = _exact_crossings(estimates, cdt_xy[seg_local], snap)
            local[len(cdt_xy) :] = _same_points(cdt_xy, crossings, snap)
            fresh = np.flatnonzero(local[len(cdt_xy) :] == np.arange(len(cdt_xy), made))
            crossing_ids = np.full(len(crossings), -1, dtype=np.int64)
            crossing_ids[fresh] = self._new_vertices(polygon, crossings[fresh], SEGMENT, True)
            triangles = local[triangles]
            flat = (triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2])
            triangles = triangles[~(flat | (triangles[:, 0] == triangles[:, 2]))]
        global_of_local = np.concatenate([np.asarray(ring, dtype=np.int64), interior_ids, crossing_ids])

        constrained_pairs = set()
        if len(seg_local):
            for e in cdt.fixed_edges:
                u, v = int(local[e.v1]), int(local[e.v2])
                if u != v and not (u < n_ring and v < n_ring and (v - u) % n_ring in (1, n_ring - 1)):
                    constrained_pairs.add((min(u, v), max(u, v)))
                    self._v_constrained.buf[global_of_local[[u, v]]] = True

        level = int(self._e_level.buf[element]) + 1
        self._set_ancestry(element, corners, global_of_local[global_of_local >= 0], level)

        count = len(triangles)
        first = self._new_elements(count, polygon, level, element)
        self._e_first_child.buf[element] = first
        self._e_child_count.buf[element] = count
        self._e_vertices.buf[first : first + count] = global_of_local[triangles]
        self._e_hedges.buf[first : first + count] = self._child_hedges(
            first, triangles.tolist(), global_of_local.tolist(), ring_hedges, constrained_pairs
        )
        return True

    def _ring(self, element: int) -> tuple:
        """The element's ring: its corners and the points on its sides, counter-clockwise, with the leaf
        sub-HEdge starting at each: (vertices, hedges), two lists of ints."""
        corners, hedges = self._sides(element)
        ring, ring_hedges = [], []
        for corner, hedge in zip(corners, hedges, strict=True):
            chain, leaves = self._chain(int(hedge), self._he_a[hedge] == corner)
            ring.extend(chain)
            ring_hedges.extend(leaves)
        return ring, ring_hedges

    def _leaves_across(self, hedge: int, element: int) -> list:
        """Leaves other than `element` whose side is leaf HEdge `hedge` or an HEdge containing it."""
        found = []
        while hedge >= 0:
            found.extend(e for e in self._he_elements[hedge] if e != element and self._e_child_count.buf[e] == 0)
            hedge = self._he_parent[hedge]
        return found

    def _place_free_points(self, element: int, points: np.ndarray, interior_xy: np.ndarray) -> np.ndarray:
        """Place free points (M, 2) of leaf `element` one by one (see shape.py). A point stays inside if its
        fan keeps the snap angle; else it moves to the foot, on one of the two nearest ring pieces, whose fans
        in this element and in the leaves across keep it best, splitting that piece's HEdge (matching: the
        leaves across are anchored). When neither reaches the snap angle, a point near a vertex merges with
        it and one further away takes its best place. A kept point within the merge fraction of its distance
        to the ring from an interior point (I, 2) merges with it. Returns the points kept inside (K, 2)."""
        snap = self.tol.snap
        angle = self.shape.snap_angle_degrees
        ring, ring_hedges = self._ring(element)
        corners_xy = self._xy.buf[self._sides(element)[0]]
        longest = float(np.hypot(*(np.roll(corners_xy, -1, axis=0) - corners_xy).T).max())
        kept = [interior_xy]
        already = len(interior_xy)
        for p in points:
            ring_xy = self._xy.buf[ring]
            s, distance, length = piece_feet(p, ring_xy)
            gaps = np.hypot(*(ring_xy - p).T)
            options = []
            if distance.min() > snap:
                options.append((fan_min_angle(p, ring_xy, snap), -1))
            for i in np.argsort(distance)[:2].tolist():
                if min(s[i], 1.0 - s[i]) * length[i] <= snap:
                    continue
                foot = ring_xy[i] + s[i] * (ring_xy[(i + 1) % len(ring)] - ring_xy[i])
                quality = fan_min_angle(foot, ring_xy, snap)
                for other in self._leaves_across(ring_hedges[i], element):
                    quality = min(quality, fan_min_angle(foot, self._xy.buf[self._ring(other)[0]], snap))
                options.append((quality, i))
            best_quality, best = max(options, default=(0.0, -2))
            if best == -2 or (best_quality < angle and gaps.min() <= max(self.shape.merge_fraction * longest, snap)):
                continue
            if best >= 0:
                h = ring_hedges[best]
                along = self._he_a[h] == ring[best]
                vertex = self._split_leaf(h, s[best] if along else 1.0 - s[best], POINT)
                first, second = self._he_kids[h]
                ring.insert(best + 1, vertex)
                ring_hedges[best : best + 1] = [first, second] if along else [second, first]
                continue
            others = np.concatenate(kept)
            if len(others) and np.hypot(*(others - p).T).min() <= max(self.shape.merge_fraction * gaps.min(), snap):
                continue
            kept.append(p[None, :])
        return np.concatenate(kept)[already:]

    def _child_hedges(self, first: int, triangles: list, global_of_local: list, ring_hedges: list,
                      constrained_pairs: set) -> list:
        """HEdges of new children first.. (local triangles): ring sides reuse the leaf sub-HEdges of the
        parent's sides, each inner edge gets one new HEdge shared by its two triangles."""
        n_ring = len(ring_hedges)
        he_a, he_b, he_kids, he_split = self._he_a, self._he_b, self._he_kids, self._he_split
        he_parent, he_elements, he_constrained = self._he_parent, self._he_elements, self._he_constrained
        inner_edge: dict = {}
        result = []
        for c, (t0, t1, t2) in enumerate(triangles):
            row = []
            for u, v in ((t0, t1), (t1, t2), (t2, t0)):
                if u < n_ring and v == (u + 1) % n_ring:
                    h = ring_hedges[u]
                else:
                    key = (u, v) if u < v else (v, u)
                    h = inner_edge.get(key)
                    if h is None:
                        h = len(he_a)
                        he_a.append(global_of_local[u])
                        he_b.append(global_of_local[v])
                        he_kids.append(None)
                        he_split.append(-1)
                        he_parent.append(-1)
                        he_elements.append([])
                        he_constrained.append(key in constrained_pairs)
                        inner_edge[key] = h
                row.append(h)
                he_elements[h].append(first + c)
            result.append(row)
        return result

    def _set_ancestry(self, element: int, corners: list, vertices: np.ndarray, level: int) -> None:
        """Vertices first appearing in element's sub-triangulation get it as ancestor (barycentric coords)."""
        fresh = vertices[self._v_level.buf[vertices] < 0]
        if len(fresh) == 0:
            return
        xy = self._xy.buf[fresh]
        if element < self.polygon_count:
            fan = self._root_fans[element]
            coords = barycentric(self._xy.buf[fan], xy)
            best = np.argmax(coords.min(axis=2), axis=1)
            ancestors = fan[best]
            weights = coords[np.arange(len(fresh)), best]
        else:
            ancestors = np.broadcast_to(np.asarray(corners, dtype=np.int64), (len(fresh), 3))
            weights = barycentric(self._xy.buf[corners][None, :, :], xy)[:, 0, :]
        self._v_level.buf[fresh] = level
        self._v_element.buf[fresh] = element
        self._v_anc.buf[fresh] = ancestors
        self._v_w.buf[fresh] = weights

    # ------------------------------------------------------------------ routing insertions to leaves

    def _element_corners_xy(self, elements: np.ndarray) -> np.ndarray:
        return self._xy.buf[self._e_vertices.buf[elements]]

    def _locate(self, polygon: int, points: np.ndarray) -> np.ndarray:
        """Leaf elements of polygon containing points (M, 2): (M,) int64."""
        current = np.full(len(points), polygon, dtype=np.int64)
        while True:
            counts = self._e_child_count.buf[current]
            if not counts.any():
                return current
            for element in np.unique(current[counts > 0]):
                idx = np.nonzero(current == element)[0]
                first = int(self._e_first_child.buf[element])
                kids = np.arange(first, first + int(self._e_child_count.buf[element]))
                triangles = self._element_corners_xy(kids)
                batch = max(1, _LOCATE_BATCH // len(kids))
                for start in range(0, len(idx), batch):
                    part = idx[start : start + batch]
                    coords = barycentric(triangles, points[part])
                    current[part] = kids[np.argmax(coords.min(axis=2), axis=1)]

    def _route_segment(self, polygon: int, p: np.ndarray, q: np.ndarray) -> None:
        """Clip segment p q (2-D) to the polygon and queue its pieces on the leaves it crosses."""
        stack = [(polygon, p, q)]
        while stack:
            element, a, b = stack.pop()
            if self.is_leaf(element):
                self._queue_item(element, 1, np.stack([a, b]))
                continue
            first = int(self._e_first_child.buf[element])
            kids = np.arange(first, first + int(self._e_child_count.buf[element]))
            t_in, t_out = clip_segment_to_polygon(self._element_corners_xy(kids), a, b)
            length = float(np.linalg.norm(b - a))
            shortest = self.tol.snap
            for i in np.nonzero((t_out - t_in) * length > shortest)[0]:
                stack.append((int(kids[i]), a + t_in[i] * (b - a), a + t_out[i] * (b - a)))

    def _queue_item(self, element: int, kind: int, item) -> None:
        entry = self._queue.setdefault(element, [[], [], None])
        if kind == 2:
            entry[2] = item
        else:
            entry[kind].append(item)

    def _run_queue(self) -> tuple:
        """Subdivide every queued leaf, then anchor. Returns (elements subdivided, elements anchored)."""
        queue, self._queue = self._queue, {}
        subdivided = 0
        for element in sorted(queue):
            points, segments, step = queue[element]
            pts = np.array(points, dtype=np.float64).reshape(-1, 2)
            segs = np.array(segments, dtype=np.float64).reshape(-1, 2, 2)
            subdivided += bool(self._subdivide(element, pts, segs, step))
        anchored = 0
        empty_points = np.zeros((0, 2))
        empty_segments = np.zeros((0, 2, 2))
        while self._dirty:
            h = self._dirty.pop()
            for element in self._he_elements[h]:
                if self.is_leaf(element):
                    anchored += bool(self._subdivide(element, empty_points, empty_segments, None))
        return subdivided, anchored


def _merge_close(points: np.ndarray, eps: float) -> tuple:
    """Merge points (M, 2) closer than eps: (unique (U, 2), representative (M,) index into unique)."""
    if len(points) == 0:
        return np.zeros((0, 2)), np.zeros(0, dtype=np.int64)
    if len(points) <= 64:
        close = np.linalg.norm(points[:, None, :] - points[None, :, :], axis=2) <= eps
        first = np.argmax(close, axis=1)
    else:
        first = np.array([min(ball) for ball in cKDTree(points).query_ball_point(points, eps)], dtype=np.int64)
    keepers, representative = np.unique(first, return_inverse=True)
    return points[keepers], representative


def _triangulate(xy: np.ndarray, origin: np.ndarray, unit: float, n_ring: int, segments: np.ndarray) -> tuple:
    """Constrained Delaunay triangulation of points xy (N, 2) whose first n_ring make the outline, with inner
    segments (S, 2) local indices: (triangles (T, 3) int64, the triangulation, whose vertices are xy then the
    crossings it made). The triangulation sees integer coordinates in units of the length tolerance: its
    in-circle ties (regular grids are full of cocircular points) then break identically at every scene scale."""
    cdt = pythoncdt.Triangulation(
        pythoncdt.VertexInsertionOrder.AS_PROVIDED,
        pythoncdt.IntersectingConstraintEdges.TRY_RESOLVE,
        0.0,
    )
    cdt.insert_vertices(np.round((xy - origin) / unit))
    edges = _ring_edges(n_ring)
    if len(segments):
        edges = np.concatenate([edges, segments.astype(np.uint32)])
    cdt.insert_edges(edges)
    cdt.erase_outer_triangles()
    return cdt.triangles_array()["vertices"].astype(np.int64), cdt


@functools.cache
def _ring_edges(n_ring: int) -> np.ndarray:
    """(n_ring, 2) uint32 the sides of a ring of n_ring points, read-only (shared by every call)."""
    ring = np.arange(n_ring, dtype=np.uint32)
    edges = np.stack([ring, (ring + 1) % n_ring], axis=1)
    edges.flags.writeable = False
    return edges


def _split_at_points(xy: np.ndarray, segments: np.ndarray, snap: float) -> np.ndarray:
    """Inner segments (S, 2) (local indices into points xy (N, 2)) cut at every point within snap of their
    interior: (S', 2) int64 pieces. The triangulation sees such a point a rounding error beside the segment and
    would join it to the segment's ends by a flat triangle (a needle), leaving the leaves around unmatched."""
    if len(segments) == 0:
        return segments
    pieces = []
    for u, v in segments.tolist():
        a = xy[u]
        d = xy[v] - a
        length = float(np.hypot(d[0], d[1]))
        offset = xy - a
        along = offset @ d / length
        on = (np.abs(cross2(d, offset)) / length <= snap) & (along > snap) & (along < length - snap)
        on[[u, v]] = False
        inner = np.flatnonzero(on)
        chain = [u, *inner[np.argsort(along[inner])].tolist(), v]
        pieces.extend(zip(chain[:-1], chain[1:], strict=False))
    return np.array(pieces, dtype=np.int64)


def _exact_crossings(estimates: np.ndarray, segments: np.ndarray, snap: float) -> np.ndarray:
    """Recompute crossing points (M, 2), found on rounded coordinates, as the exact intersection of the two
    segments (S, 2, 2) passing nearest to each estimate; an intersection further than `snap` from its estimate
    (segments nearly parallel, where the exact point is ill-conditioned) keeps the estimate."""
    if len(estimates) == 0:
        return estimates
    if len(segments) < 2:
        raise VisradError(
            f"the triangulation of an element made {len(estimates)} crossing point(s) with fewer than two inner "
            "segments: its outline crosses itself (a hierarchy defect, please report the scene)"
        )
    a = segments[:, 0]
    d = segments[:, 1] - a
    length = np.linalg.norm(d, axis=1)
    exact = estimates.copy()
    for m, x in enumerate(estimates):
        distance = np.abs(cross2(d, x - a)) / length
        first, second = np.argsort(distance)[:2]
        det = cross2(d[first], d[second])
        if det != 0.0:
            s = cross2(a[second] - a[first], d[second]) / det
            point = a[first] + s * d[first]
            if np.hypot(*(point - x)) <= snap:
                exact[m] = point
    return exact


def _same_points(points: np.ndarray, extra: np.ndarray, snap: float) -> np.ndarray:
    """(E,) int64: for each extra point (E, 2), the index of the first of points (N, 2) or of the earlier kept
    extra points (N + j) within snap of it, or its own index N + e when there is none (it is kept)."""
    count = len(points)
    kept_xy = list(points)
    kept_index = list(range(count))
    result = np.empty(len(extra), dtype=np.int64)
    for e, x in enumerate(extra):
        gaps = np.hypot(*(np.asarray(kept_xy) - x).T)
        nearest = int(np.argmin(gaps))
        if gaps[nearest] <= snap:
            result[e] = kept_index[nearest]
        else:
            result[e] = count + e
            kept_xy.append(x)
            kept_index.append(count + e)
    return result
