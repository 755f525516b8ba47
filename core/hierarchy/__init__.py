"""Hierarchical constrained-Delaunay triangulations with lazy-wavelet push-pull at vertices.

Implements seed 000 (Durand, Drettakis & Puech 1999): section 3.1 and Fig. 5 (HPolygon, HTriangulation,
HEdge; matching and anchoring), section 3.2 with Figs. 6 and 12 (lazy wavelets: Delta B at refined vertices,
push by barycentric interpolation breadth first, pull by averages), section 4.2.2 (negative links, eq. 1),
and the grid-like first subdivisions of section 6.2 with the light maxima of section 6.3.

Model. `Hierarchy(polygons, tolerance)` takes a list of convex planar (K, 3) float64 polygons (or
`Hierarchy.from_scene(scene)`) and works in each polygon's own 2-D frame (`hierarchy.frames`). Element p < P
is input polygon p (level 0); the other elements are triangles, each in the constrained Delaunay
triangulation (pythoncdt) that subdivides its parent; children are consecutive ids. Sides of different
polygons with the same endpoints (within tolerance.length) are matched too, so leaves conform across
polygons; a point on such a side is one vertex per polygon, at the same 3-D position.

Refinement, one step at a time (section 6, Fig. 20):
    h.insert_points(polygon, (M, 3)) / h.insert_points_2d(polygon, (M, 2))     # e.g. light maxima
    h.insert_segments(polygon, (S, 2, 3)) / h.insert_segments_2d(polygon, (S, 2, 2))  # discontinuities
    h.insert_into_element(element, points_2d, segments_2d)
    h.queue_regular_grid(leaf_elements, GridSettings(...))                     # first two subdivisions
    report = h.complete_step()        # builds the sub-triangulations, then anchors: leaves conform

What the solver needs per vertex (stable integer ids 0..N-1, never renumbered):
    h.vertex_positions() (N, 3), h.vertex_positions_2d() (N, 2), h.vertex_polygon() (N,)
    a = h.ancestry(): a.level (N,), a.element (N,) (the element whose sub-triangulation the vertex first
        appeared in, -1 for polygon corners), a.ancestors (N, 3) vertex ids of the triangle of the level
        above containing it (a fan triangle of the polygon for level-1 vertices) and a.weights (N, 3) its
        barycentric coordinates c_i: the negative links of eq. 1.
Lazy wavelets:
    dB = sum over sources of h.lazy_delta(linked_vertex_ids, gathered)   # B_l - sum_i c_i B_nl^i
    B = h.push(dB)              # (N,) or (N, C): interpolation of the ancestor + Delta B, breadth first
    E = h.pull(B)               # (E,) or (E, C): leaf = mean of its vertices, above: area-weighted mean
Export: h.export_leaves(values) and h.export_level(level, cut=False, values) -> TriangleMesh (vertices,
triangles, triangle_polygon, triangle_element, triangle_level, vertex_polygon, values);
h.statistics() -> HierarchyStats (smallest-angle histograms, depth, leaves per polygon, memory).
"""

from .grid import GridSettings
from .hierarchy import ANGLE_BINS, Hierarchy, HierarchyStats, StepReport, TriangleMesh, VertexAncestry
from .shape import ShapeSettings

__all__ = [
    "ANGLE_BINS",
    "GridSettings",
    "Hierarchy",
    "HierarchyStats",
    "ShapeSettings",
    "StepReport",
    "TriangleMesh",
    "VertexAncestry",
]
