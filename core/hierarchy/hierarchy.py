"""The public Hierarchy: insertion, subdivision steps, ancestry, push-pull, export and statistics."""

import sys
from dataclasses import dataclass

import numpy as np

from . import lazy_wavelet
from .geometry import cross2, triangle_areas_2d, triangle_min_angles
from .grid import GridSettings
from .shape import ShapeSettings
from .structure import HierarchyCore

ANGLE_BINS = np.array([0.0, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 60.0])


@dataclass(frozen=True)
class StepReport:
    """What one complete_step() did: elements subdivided by insertions, elements subdivided by anchoring,
    and the vertex / element counts afterwards."""

    subdivided: int
    anchored: int
    vertices: int
    elements: int
    leaves: int


@dataclass(frozen=True)
class VertexAncestry:
    """The lazy-wavelet chain of every vertex (N = vertex count).

    level (N,) int64: 0 for polygon corners, else 1 + the level of `element`.
    element (N,) int64: the element in whose sub-triangulation the vertex first appeared (-1 for corners).
    ancestors (N, 3) int64: the three vertices of the triangle of the level above containing the vertex
        (element's corners, or a fan triangle of the polygon when element is an input polygon); -1 for corners.
    weights (N, 3) float64: the vertex's barycentric coordinates c_i in that triangle (zeros for corners).
    """

    level: np.ndarray
    element: np.ndarray
    ancestors: np.ndarray
    weights: np.ndarray


@dataclass(frozen=True)
class TriangleMesh:
    """Triangles exported for the Blender layer.

    vertices (N, 3) float64: every hierarchy vertex, indexed by its stable vertex id.
    triangles (T, 3) int64: vertex ids, counter-clockwise seen from the polygon's normal.
    triangle_polygon (T,) int64: the input polygon of each triangle.
    triangle_element (T,) int64: its element (an input polygon not yet subdivided exports a fan of its corners).
    triangle_level (T,) int64: the element's level.
    vertex_polygon (N,) int64: the input polygon of each vertex.
    values (N, ...) float64 or None: per-vertex values passed to the export.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_polygon: np.ndarray
    triangle_element: np.ndarray
    triangle_level: np.ndarray
    vertex_polygon: np.ndarray
    values: np.ndarray | None = None


@dataclass(frozen=True)
class HierarchyStats:
    """Quality and size of the hierarchy.

    min_angle_histogram: counts of leaf triangles per bin of ANGLE_BINS (degrees, smallest angle);
    free_min_angle_histogram: the same for leaves none of whose vertices lies on a constrained segment.
    leaves_per_polygon (P,) int64; memory_bytes: the hierarchy's arrays and lists (approximate for lists).
    """

    vertices: int
    elements: int
    leaves: int
    hedges: int
    max_depth: int
    mean_depth: float
    leaves_per_polygon: np.ndarray
    min_angle: float
    free_min_angle: float
    min_angle_histogram: np.ndarray
    free_min_angle_histogram: np.ndarray
    memory_bytes: int

    def as_dict(self) -> dict:
        return {
            "vertices": self.vertices,
            "elements": self.elements,
            "leaves": self.leaves,
            "hedges": self.hedges,
            "max_depth": self.max_depth,
            "mean_depth": self.mean_depth,
            "leaves_per_polygon_min": int(self.leaves_per_polygon.min(initial=0)),
            "leaves_per_polygon_mean": float(self.leaves_per_polygon.mean()) if len(self.leaves_per_polygon) else 0.0,
            "leaves_per_polygon_max": int(self.leaves_per_polygon.max(initial=0)),
            "min_angle": self.min_angle,
            "free_min_angle": self.free_min_angle,
            "angle_bins": ANGLE_BINS.tolist(),
            "min_angle_histogram": self.min_angle_histogram.tolist(),
            "free_min_angle_histogram": self.free_min_angle_histogram.tolist(),
            "memory_bytes": self.memory_bytes,
        }


class Hierarchy(HierarchyCore):
    """Hierarchical constrained Delaunay triangulations of convex planar polygons, with lazy-wavelet push-pull.

    polygons: list of (K, 3) float64 arrays, each convex and planar, K >= 3; tolerance: a
    core.tolerance.Tolerance (its `length` is the only distance epsilon); grid: the regular subdivision.
    """

    @classmethod
    def from_scene(cls, scene, grid: GridSettings | None = None, shape: ShapeSettings | None = None) -> "Hierarchy":
        """One hierarchy per polygon of a core.scene.Scene (polygon_points, polygon_offsets, tol)."""
        offsets = np.asarray(scene.polygon_offsets)
        points = np.asarray(scene.polygon_points, dtype=np.float64)
        polygons = [points[offsets[i] : offsets[i + 1]] for i in range(len(offsets) - 1)]
        return cls(polygons, scene.tol, grid, shape)

    # ------------------------------------------------------------------ insertion

    def insert_points(self, polygon: int, points: np.ndarray) -> None:
        """Queue points (M, 3) on polygon (projected onto its plane) for the next complete_step()."""
        self.insert_points_2d(polygon, self.frames.to_2d(polygon, points))

    def insert_points_2d(self, polygon: int, points: np.ndarray) -> None:
        """Queue points (M, 2) in polygon's frame; each goes to the leaf containing it. A point outside the
        polygon (beyond the tolerance) raises ValueError."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
        if not len(pts):
            return
        corners = self.frames.corners_2d[polygon]
        sides = np.roll(corners, -1, axis=0) - corners
        distance = cross2(sides[None], pts[:, None, :] - corners[None]) / np.linalg.norm(sides, axis=1)
        outside = distance.min(axis=1) < -self.eps
        if outside.any():
            raise ValueError(f"polygon {polygon}: point {pts[np.argmax(outside)].tolist()} lies outside it")
        for point, leaf in zip(pts, self._locate(polygon, pts), strict=True):
            self._queue_item(int(leaf), 0, point)

    def insert_segments(self, polygon: int, segments: np.ndarray) -> None:
        """Queue constrained segments (S, 2, 3) on polygon (projected onto its plane), clipped to it."""
        segs = np.asarray(segments, dtype=np.float64).reshape(-1, 3)
        self.insert_segments_2d(polygon, self.frames.to_2d(polygon, segs).reshape(-1, 2, 2))

    def insert_segments_2d(self, polygon: int, segments: np.ndarray) -> None:
        """Queue constrained segments (S, 2, 2) in polygon's frame; each is clipped to the polygon and to the
        leaves it crosses. Crossing segments get their intersection point when the step completes."""
        for p, q in np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2):
            self._route_segment(polygon, p, q)

    def insert_into_element(self, element: int, points: np.ndarray, segments: np.ndarray) -> None:
        """Queue points (M, 2) and segments (S, 2, 2), in the element's polygon frame, into leaf `element`
        itself: segments are clipped to it, points outside it are ignored."""
        if not self.is_leaf(element):
            raise ValueError(f"element {element} is already subdivided; insert into its leaves")
        for point in np.asarray(points, dtype=np.float64).reshape(-1, 2):
            self._queue_item(element, 0, point)
        for segment in np.asarray(segments, dtype=np.float64).reshape(-1, 2, 2):
            self._queue_item(element, 1, segment)

    def queue_regular_grid(self, elements, settings: GridSettings | None = None) -> None:
        """Mark leaf elements for grid-like subdivision (section 6.2) at the next complete_step(); points and
        segments queued on them in the same step (e.g. light maxima) keep grid points away."""
        grid = settings or self.grid
        elements = np.atleast_1d(np.asarray(elements, dtype=np.int64))
        busy = self._e_child_count.buf[elements] > 0
        if busy.any():
            raise ValueError(f"element {elements[np.argmax(busy)]} is already subdivided; grid its leaves")
        longest = np.empty(len(elements))
        roots = elements < self.polygon_count
        for i in np.nonzero(roots)[0]:
            corners = self.frames.corners_2d[elements[i]]
            longest[i] = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1).max()
        xy = self._xy.buf[self._e_vertices.buf[elements[~roots]]]
        longest[~roots] = np.linalg.norm(xy - xy[:, [1, 2, 0]], axis=2).max(axis=1)
        for element, length in zip(elements.tolist(), longest.tolist(), strict=True):
            self._queue_item(element, 2, grid.step(length, self.tol.scale))

    def complete_step(self) -> StepReport:
        """Build the sub-triangulations of every leaf that received insertions, then anchor (section 3.1)."""
        subdivided, anchored = self._run_queue()
        return StepReport(subdivided, anchored, self.vertex_count, self.element_count, len(self.leaves()))

    # ------------------------------------------------------------------ queries

    @property
    def vertex_count(self) -> int:
        return self._xy.size

    @property
    def element_count(self) -> int:
        return self._e_polygon.size

    def leaves(self, polygon: int | None = None) -> np.ndarray:
        """Leaf element ids (L,) int64, of one polygon or of all."""
        leaf = self._e_child_count.data == 0
        if polygon is not None:
            leaf &= self._e_polygon.data == polygon
        return np.nonzero(leaf)[0]

    def element_polygon(self) -> np.ndarray:
        """(E,) int64 input polygon of each element."""
        return self._e_polygon.data.copy()

    def element_level(self) -> np.ndarray:
        """(E,) int64 level of each element (0 for input polygons)."""
        return self._e_level.data.copy()

    def element_parent(self) -> np.ndarray:
        """(E,) int64 parent element (-1 for input polygons)."""
        return self._e_parent.data.copy()

    def element_tree(self) -> tuple:
        """Every element's corners and children at once: (vertices (E, 3) int64 corner vertex ids, -1 for input
        polygons; first_child (E,) int64, -1 for leaves; child_count (E,) int64)."""
        return self._e_vertices.data.copy(), self._e_first_child.data.copy(), self._e_child_count.data.copy()

    def element_children(self, element: int) -> np.ndarray:
        """Children of an element (C,) int64, consecutive ids; empty for a leaf."""
        first = int(self._e_first_child.buf[element])
        return np.arange(first, first + int(self._e_child_count.buf[element]))

    def element_vertices(self, element: int) -> np.ndarray:
        """Corner vertex ids of an element, counter-clockwise: (3,) or (K,) for an input polygon."""
        corners, _ = self._sides(element)
        return np.array(corners, dtype=np.int64)

    def element_areas(self) -> np.ndarray:
        """(E,) float64 area of each element."""
        areas = np.empty(self.element_count)
        tri = np.arange(self.polygon_count, self.element_count)
        areas[tri] = triangle_areas_2d(self._xy.buf[self._e_vertices.buf[tri]])
        for p in range(self.polygon_count):
            areas[p] = triangle_areas_2d(self._xy.buf[self._root_fans[p]]).sum()
        return areas

    def vertex_positions_2d(self) -> np.ndarray:
        """(N, 2) float64 vertex coordinates in their polygon's frame."""
        return self._xy.data.copy()

    def vertex_positions(self) -> np.ndarray:
        """(N, 3) float64 vertex positions in world space."""
        return self.frames.to_3d(self._v_polygon.data, self._xy.data)

    def vertex_polygon(self) -> np.ndarray:
        """(N,) int64 input polygon of each vertex (a point on a shared side has one vertex per polygon)."""
        return self._v_polygon.data.copy()

    def ancestry(self) -> VertexAncestry:
        """The ancestor triangle and barycentric coordinates of every vertex (negative links, eq. 1)."""
        return VertexAncestry(
            level=self._v_level.data.copy(),
            element=self._v_element.data.copy(),
            ancestors=self._v_anc.data.copy(),
            weights=self._v_w.data.copy(),
        )

    # ------------------------------------------------------------------ lazy wavelets

    def lazy_delta(self, vertex_ids: np.ndarray, gathered: np.ndarray) -> np.ndarray:
        """Delta B (eq. 1) at vertex_ids (M,) from one source's gathered radiosity (M,) or (M, C); see
        lazy_wavelet.lazy_delta. Sum the results of all sources into the (N, ...) array given to push()."""
        return lazy_wavelet.lazy_delta(vertex_ids, gathered, self._v_anc.data, self._v_w.data)

    def push(self, delta: np.ndarray) -> np.ndarray:
        """B at every vertex (N,) or (N, C) from Delta B (same shape), breadth first down the hierarchy."""
        if len(delta) != self.vertex_count:
            raise ValueError(f"push: delta has {len(delta)} rows, the hierarchy has {self.vertex_count} vertices")
        return lazy_wavelet.push(delta, self._v_anc.data, self._v_w.data, self._v_level.data)

    def pull(self, values: np.ndarray) -> np.ndarray:
        """Element values (E,) or (E, C): a leaf gets the average of its vertices' values (N,) or (N, C),
        an inner element the area-weighted average of its children (section 3.2)."""
        vals = np.asarray(values, dtype=np.float64)
        flat = vals.reshape(len(vals), -1)
        count = self.element_count
        leaf_values = np.zeros((count, flat.shape[1]))
        tri = np.arange(self.polygon_count, count)
        leaf_values[tri] = flat[self._e_vertices.buf[tri]].mean(axis=1)
        for p in range(self.polygon_count):
            fan = self._root_fans[p]
            weights = triangle_areas_2d(self._xy.buf[fan])
            leaf_values[p] = weights @ flat[fan].mean(axis=1) / weights.sum()
        pulled = lazy_wavelet.pull(
            leaf_values, self._e_child_count.data == 0, self._e_parent.data, self._e_level.data,
            self.element_areas(),
        )
        return pulled.reshape((count,) + vals.shape[1:])

    # ------------------------------------------------------------------ export

    def _mesh(self, elements: np.ndarray, values) -> TriangleMesh:
        elements = np.asarray(elements, dtype=np.int64)
        roots = elements[elements < self.polygon_count]
        tris = elements[elements >= self.polygon_count]
        triangles = [self._e_vertices.buf[tris]]
        owner = [tris]
        for p in roots:
            triangles.append(self._root_fans[p])
            owner.append(np.full(len(self._root_fans[p]), p))
        owner = np.concatenate(owner)
        return TriangleMesh(
            vertices=self.vertex_positions(),
            triangles=np.concatenate(triangles).astype(np.int64),
            triangle_polygon=self._e_polygon.buf[owner].copy(),
            triangle_element=owner,
            triangle_level=self._e_level.buf[owner].copy(),
            vertex_polygon=self.vertex_polygon(),
            values=None if values is None else np.asarray(values, dtype=np.float64),
        )

    def export_leaves(self, values: np.ndarray | None = None) -> TriangleMesh:
        """The leaf triangles: a conforming mesh of every polygon, for the Blender layer."""
        return self._mesh(self.leaves(), values)

    def export_level(self, level: int, cut: bool = False, values: np.ndarray | None = None) -> TriangleMesh:
        """The triangles of one level (seed 000 Fig. 22 f-g). With cut=True, the mesh of the hierarchy cut at
        that level: its elements plus the coarser leaves, covering every polygon once."""
        levels = self._e_level.data
        chosen = levels == level
        if cut:
            chosen |= (levels < level) & (self._e_child_count.data == 0)
        return self._mesh(np.nonzero(chosen)[0], values)

    # ------------------------------------------------------------------ statistics

    def statistics(self) -> HierarchyStats:
        """Quality (smallest-angle histograms), depth, leaves per polygon and memory of the hierarchy."""
        mesh = self.export_leaves()
        corners = self._xy.buf[mesh.triangles]
        angles = triangle_min_angles(corners)
        free = ~self._v_constrained.buf[mesh.triangles].any(axis=1)
        leaves = self.leaves()
        depth = self._e_level.buf[leaves]
        per_polygon = np.bincount(mesh.triangle_polygon, minlength=self.polygon_count)
        return HierarchyStats(
            vertices=self.vertex_count,
            elements=self.element_count,
            leaves=len(mesh.triangles),
            hedges=len(self._he_a),
            max_depth=int(depth.max(initial=0)),
            mean_depth=float(depth.mean()) if len(depth) else 0.0,
            leaves_per_polygon=per_polygon,
            min_angle=float(angles.min(initial=60.0)),
            free_min_angle=float(angles[free].min(initial=60.0)),
            min_angle_histogram=np.histogram(angles, ANGLE_BINS)[0],
            free_min_angle_histogram=np.histogram(angles[free], ANGLE_BINS)[0],
            memory_bytes=self._memory_bytes(),
        )

    def _memory_bytes(self) -> int:
        columns = [
            self._xy, self._v_polygon, self._v_level, self._v_element, self._v_anc, self._v_w,
            self._v_constrained, self._v_kind, self._e_polygon, self._e_level, self._e_parent, self._e_vertices,
            self._e_hedges, self._e_first_child, self._e_child_count,
        ]
        total = sum(c.buf.nbytes for c in columns)
        lists = [
            self._he_a, self._he_b, self._he_kids, self._he_split, self._he_parent, self._he_elements,
            self._he_constrained,
        ]
        total += sum(sys.getsizeof(x) for x in lists)
        # Python ints above 256 are separate 28-byte objects (a parent is the split HEdge's own int); element
        # lists and split tuples likewise.
        total += 28 * (len(self._he_a) + len(self._he_b) + len(self._he_split))
        total += sum(sys.getsizeof(x) for x in self._he_elements)
        total += sum(sys.getsizeof(x) for x in self._he_kids if x is not None)
        total += sys.getsizeof(self._he_twins) + sum(sys.getsizeof(x) for x in self._he_twins.values())
        return int(total)
