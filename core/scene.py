"""The validated polygon scene every stage works on (Durand et al. 1999, section 2; DESIGN.md sections 3-4).

`Scene.from_polygons` checks the caller's description, splits non-planar and non-convex polygons into
triangles (never dropping one), and derives what visibility needs: planes, areas, AABBs, the edges with their
adjacent faces and kind (boundary / crease / flat; flat edges can never be silhouettes and so never generate
visual events), vertex kinds, object ids, two-sided flags and the tolerance of the scene.

All arrays are float64 / int64 copies flagged read-only: the caller's arrays are never touched, and no stage
can modify the scene by accident.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from .errors import SceneError
from .tolerance import Tolerance

EDGE_BOUNDARY = 0
EDGE_CREASE = 1
EDGE_FLAT = 2

VERTEX_UNUSED = 0
VERTEX_FLAT = 1
VERTEX_SILHOUETTE = 2


@dataclass(frozen=True, eq=False)
class Scene:
    """A scene of planar convex polygons, counter-clockwise around their normals.

    Polygons are stored CSR: polygon i is `polygon_vertex_ids[polygon_offsets[i]:polygon_offsets[i + 1]]`.

    vertices (V, 3) float64; polygon_offsets (P+1,) int64; polygon_vertex_ids (N,) int64;
    polygon_points (N, 3) float64 = vertices[polygon_vertex_ids];
    polygon_edge_ids (N,) int64: edge from local vertex k to k+1 of each polygon;
    source_polygon (P,) int64: index of the caller's polygon each polygon comes from;
    normals (P, 3) unit; plane_offsets (P,): normals[i] . x + plane_offsets[i] = 0 on polygon i;
    areas (P,); centroids (P, 3) area centroids; polygon_min, polygon_max (P, 3) bounding boxes;
    reflectance (P, 3) in [0, 1); emission (P, 3) exitance W/m^2; object_ids (P,) int64; two_sided (P,) bool;
    solid (P,) bool: polygons of closed objects whose normals point outwards (from outside, whatever the
    object hides is hidden by its faces turned towards the viewer);
    edges (E, 2) int64 vertex ids, first < second; edge_kind (E,) int8 (EDGE_*);
    edge_face_offsets (E+1,), edge_faces: CSR of the polygons adjacent to each edge;
    vertex_kind (V,) int8 (VERTEX_*); bbox_min, bbox_max (3,); diagonal; tol.
    """

    vertices: np.ndarray
    polygon_offsets: np.ndarray
    polygon_vertex_ids: np.ndarray
    polygon_points: np.ndarray
    polygon_edge_ids: np.ndarray
    source_polygon: np.ndarray
    normals: np.ndarray
    plane_offsets: np.ndarray
    areas: np.ndarray
    centroids: np.ndarray
    polygon_min: np.ndarray
    polygon_max: np.ndarray
    reflectance: np.ndarray
    emission: np.ndarray
    object_ids: np.ndarray
    two_sided: np.ndarray
    solid: np.ndarray
    edges: np.ndarray
    edge_kind: np.ndarray
    edge_face_offsets: np.ndarray
    edge_faces: np.ndarray
    vertex_kind: np.ndarray
    bbox_min: np.ndarray
    bbox_max: np.ndarray
    diagonal: float
    tol: Tolerance

    @property
    def n_polygons(self) -> int:
        return len(self.normals)

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    def polygon(self, index: int) -> np.ndarray:
        """The (K, 3) float64 corners of polygon `index`, counter-clockwise around its normal."""
        return self.polygon_points[self.polygon_offsets[index] : self.polygon_offsets[index + 1]]

    def polygon_vertices(self, index: int) -> np.ndarray:
        """The (K,) int64 vertex ids of polygon `index`."""
        return self.polygon_vertex_ids[self.polygon_offsets[index] : self.polygon_offsets[index + 1]]

    def edge_polygons(self, edge: int) -> np.ndarray:
        """The polygons adjacent to `edge`, (M,) int64."""
        return self.edge_faces[self.edge_face_offsets[edge] : self.edge_face_offsets[edge + 1]]

    @property
    def lights(self) -> np.ndarray:
        """Indices of the emitting polygons, (L,) int64."""
        return np.flatnonzero(self.emission.max(axis=1) > 0.0)

    @staticmethod
    def from_polygons(
        vertices,
        polygons: Sequence[Sequence[int]],
        reflectance,
        emission,
        object_ids=None,
        two_sided=None,
    ) -> Scene:
        """Validate a polygon scene and build it.

        vertices: (V, 3) float-like world-space positions.
        polygons: P sequences of vertex indices (at least 3 each, no index repeated), planar or not,
            convex or not; the right-hand rule of their order gives the front side.
        reflectance: (P, 3) in [0, 1). emission: (P, 3) exitance in W/m^2, >= 0.
        object_ids: (P,) ints, or None for the connected components of the polygons.
        two_sided: (P,) bools, or None: polygons of closed objects are one-sided, of open ones two-sided.

        Raises SceneError naming the offending polygon, vertex or argument.
        """
        points = _as_vertices(vertices)
        loops = _as_polygons(polygons, len(points))
        count = len(loops)
        rho = _as_rgb(reflectance, count, "reflectance")
        if np.any(rho < 0.0) or np.any(rho >= 1.0):
            bad = int(np.flatnonzero(np.any((rho < 0.0) | (rho >= 1.0), axis=1))[0])
            raise SceneError(f"reflectance of polygon {bad} is {rho[bad].tolist()}: must lie in [0, 1)")
        exitance = _as_rgb(emission, count, "emission")
        if np.any(exitance < 0.0):
            bad = int(np.flatnonzero(np.any(exitance < 0.0, axis=1))[0])
            raise SceneError(f"emission of polygon {bad} is {exitance[bad].tolist()}: must be >= 0")
        ids = None if object_ids is None else _as_per_polygon(object_ids, count, "object_ids", np.int64)
        sides = None if two_sided is None else _as_per_polygon(two_sided, count, "two_sided", np.bool_)

        used = np.unique(np.concatenate(loops))
        tol = Tolerance.for_points(points[used])

        pieces: list[np.ndarray] = []
        origin: list[int] = []
        for index, loop in enumerate(loops):
            for piece in _convex_pieces(points, loop, index, tol):
                pieces.append(piece)
                origin.append(index)
        source = np.asarray(origin, dtype=np.int64)

        if ids is None:
            ids_in = _connected_components(loops, len(points))
        else:
            ids_in = ids
        object_of_piece = ids_in[source]

        offsets = np.zeros(len(pieces) + 1, dtype=np.int64)
        offsets[1:] = np.cumsum([len(p) for p in pieces])
        vertex_ids = np.concatenate(pieces).astype(np.int64)
        corner_points = points[vertex_ids]

        normals, areas, centroids = _polygon_geometry(corner_points, offsets)
        plane_offsets = -np.einsum("ij,ij->i", normals, centroids)
        poly_min = np.minimum.reduceat(corner_points, offsets[:-1], axis=0)
        poly_max = np.maximum.reduceat(corner_points, offsets[:-1], axis=0)

        edge_data = _edges(vertex_ids, offsets, normals, tol)
        edges, edge_kind, edge_face_offsets, edge_faces, polygon_edge_ids, closed_edges = edge_data
        vertex_kind = _vertex_kinds(len(points), edges, edge_kind)

        if sides is None:
            sides_out = _open_objects(object_of_piece, edges, edge_face_offsets, edge_faces, closed_edges)
        else:
            sides_out = sides[source]

        bbox_min = points[used].min(axis=0)
        bbox_max = points[used].max(axis=0)
        arrays = dict(
            vertices=points,
            polygon_offsets=offsets,
            polygon_vertex_ids=vertex_ids,
            polygon_points=corner_points,
            polygon_edge_ids=polygon_edge_ids,
            source_polygon=source,
            normals=normals,
            plane_offsets=plane_offsets,
            areas=areas,
            centroids=centroids,
            polygon_min=poly_min,
            polygon_max=poly_max,
            reflectance=rho[source],
            emission=exitance[source],
            object_ids=object_of_piece,
            two_sided=sides_out,
            solid=_solid_objects(
                object_of_piece, edges, edge_face_offsets, edge_faces, closed_edges, normals, centroids, areas, tol
            ),
            edges=edges,
            edge_kind=edge_kind,
            edge_face_offsets=edge_face_offsets,
            edge_faces=edge_faces,
            vertex_kind=vertex_kind,
            bbox_min=bbox_min,
            bbox_max=bbox_max,
        )
        for array in arrays.values():
            array.flags.writeable = False
        return Scene(**arrays, diagonal=tol.scale, tol=tol)


def _as_vertices(vertices) -> np.ndarray:
    try:
        points = np.array(vertices, dtype=np.float64, copy=True)
    except (TypeError, ValueError) as exc:
        raise SceneError(f"vertices must be a (V, 3) array of numbers: {exc}") from None
    if points.ndim != 2 or points.shape[1] != 3:
        raise SceneError(f"vertices must have shape (V, 3), got {points.shape}")
    finite = np.isfinite(points).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise SceneError(f"vertex {bad} has a non-finite coordinate: {points[bad].tolist()}")
    return points


def _as_polygons(polygons, n_vertices: int) -> list[np.ndarray]:
    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        polygons = list(polygons)
    loops = []
    for index, polygon in enumerate(polygons):
        try:
            loop = np.array(polygon, copy=True)
        except (TypeError, ValueError):
            raise SceneError(f"polygon {index} is not a sequence of vertex indices") from None
        if loop.ndim != 1 or (loop.size and not np.issubdtype(loop.dtype, np.integer)):
            raise SceneError(f"polygon {index} must be a flat sequence of integer vertex indices")
        loop = loop.astype(np.int64)
        if len(loop) < 3:
            raise SceneError(f"polygon {index} has {len(loop)} vertices: at least 3 are needed")
        out_of_range = (loop < 0) | (loop >= n_vertices)
        if out_of_range.any():
            bad = int(loop[np.flatnonzero(out_of_range)[0]])
            raise SceneError(f"polygon {index} uses vertex index {bad}, outside 0..{n_vertices - 1}")
        if len(np.unique(loop)) != len(loop):
            raise SceneError(f"polygon {index} repeats a vertex index: {loop.tolist()}")
        loops.append(loop)
    if not loops:
        raise SceneError("the scene has no polygons")
    return loops


def _as_rgb(values, count: int, name: str) -> np.ndarray:
    try:
        array = np.array(values, dtype=np.float64, copy=True)
    except (TypeError, ValueError):
        raise SceneError(f"{name} must be a (P, 3) array of numbers") from None
    if array.shape != (count, 3):
        raise SceneError(f"{name} must have shape ({count}, 3) (one RGB row per polygon), got {array.shape}")
    finite = np.isfinite(array).all(axis=1)
    if not finite.all():
        bad = int(np.flatnonzero(~finite)[0])
        raise SceneError(f"{name} of polygon {bad} is not finite: {array[bad].tolist()}")
    return array


def _as_per_polygon(values, count: int, name: str, dtype) -> np.ndarray:
    array = np.array(values, copy=True)
    if array.shape != (count,):
        raise SceneError(f"{name} must have shape ({count},) (one value per polygon), got {array.shape}")
    if dtype is np.int64 and not np.issubdtype(array.dtype, np.integer):
        raise SceneError(f"{name} must hold integers, got dtype {array.dtype}")
    return array.astype(dtype)


def _newell(corners: np.ndarray) -> np.ndarray:
    """Newell's vector of a (K, 3) loop: twice the area times the unit normal."""
    following = np.roll(corners, -1, axis=0)
    return np.cross(corners, following).sum(axis=0)


def _frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors completing `normal` into a right-handed orthonormal frame."""
    helper = np.zeros(3)
    helper[int(np.argmin(np.abs(normal)))] = 1.0
    u = np.cross(helper, normal)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def _convex_pieces(points: np.ndarray, loop: np.ndarray, index: int, tol: Tolerance) -> list[np.ndarray]:
    """Split input polygon `index` into planar convex pieces (vertex-id loops, counter-clockwise)."""
    corners = points[loop]
    steps = np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)
    keep = steps > tol.length
    if not keep.all():
        loop, corners, steps = loop[keep], corners[keep], steps[keep]
    newell = _newell(corners) if len(loop) >= 3 else np.zeros(3)
    twice_area = float(np.linalg.norm(newell))
    perimeter = float(steps.sum())
    if len(loop) < 3 or perimeter == 0.0 or twice_area / perimeter <= tol.length:
        raise SceneError(
            f"polygon {index} has zero area (its vertices are coincident or collinear, or it folds onto itself)"
        )
    normal = newell / twice_area
    u, v = _frame(normal)
    flat = np.stack([corners @ u, corners @ v], axis=1)
    if _self_intersects(flat, tol.length):
        raise SceneError(f"polygon {index} is self-intersecting")
    planar = np.abs((corners - corners.mean(axis=0)) @ normal).max() <= tol.planarity
    if planar and _is_convex(flat, tol.length):
        return [loop]
    return [loop[list(tri)] for tri in _ear_clip(flat, index, tol.length)]


def _turns(flat: np.ndarray) -> np.ndarray:
    """Signed turn (cross product of incoming and outgoing edge directions, normalised) at each corner."""
    incoming = flat - np.roll(flat, 1, axis=0)
    outgoing = np.roll(flat, -1, axis=0) - flat
    incoming /= np.linalg.norm(incoming, axis=1)[:, None]
    outgoing /= np.linalg.norm(outgoing, axis=1)[:, None]
    return incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]


def _is_convex(flat: np.ndarray, length_eps: float) -> bool:
    """Counter-clockwise convex, collinear corners allowed (a corner may dent by less than length_eps)."""
    incoming = flat - np.roll(flat, 1, axis=0)
    outgoing = np.roll(flat, -1, axis=0) - flat
    cross = incoming[:, 0] * outgoing[:, 1] - incoming[:, 1] * outgoing[:, 0]
    # the dent of a corner: its distance to the line through its neighbours, signed
    chord = np.linalg.norm(np.roll(flat, -1, axis=0) - np.roll(flat, 1, axis=0), axis=1)
    dent = np.where(chord > 0.0, cross / np.maximum(chord, 1e-300), -np.inf)
    return bool(np.all(dent >= -length_eps))


def _self_intersects(flat: np.ndarray, length_eps: float) -> bool:
    """True when two non-adjacent edges of the closed 2-D loop touch or cross."""
    k = len(flat)
    if k <= 3:
        return False
    starts = flat
    ends = np.roll(flat, -1, axis=0)
    for i in range(k):
        for j in range(i + 2, k):
            if i == 0 and j == k - 1:
                continue
            if _segment_distance(starts[i], ends[i], starts[j], ends[j]) <= length_eps:
                return True
    return False


def _segment_distance(a0, a1, b0, b1) -> float:
    """Distance between two 2-D segments (0 when they cross)."""

    def orient(p, q, r):
        return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0])

    d1, d2 = orient(a0, a1, b0), orient(a0, a1, b1)
    d3, d4 = orient(b0, b1, a0), orient(b0, b1, a1)
    if ((d1 > 0) != (d2 > 0)) and ((d3 > 0) != (d4 > 0)) and d1 != 0 and d2 != 0 and d3 != 0 and d4 != 0:
        return 0.0
    return min(
        _point_segment_distance(a0, b0, b1),
        _point_segment_distance(a1, b0, b1),
        _point_segment_distance(b0, a0, a1),
        _point_segment_distance(b1, a0, a1),
    )


def _point_segment_distance(p, a, b) -> float:
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom == 0.0 else min(1.0, max(0.0, float((p - a) @ ab) / denom))
    return float(np.linalg.norm(p - (a + t * ab)))


def _ear_clip(flat: np.ndarray, index: int, length_eps: float) -> list[tuple[int, int, int]]:
    """Triangulate a simple counter-clockwise 2-D loop; local corner triples, collinear corners skipped."""
    remaining = list(range(len(flat)))
    triangles: list[tuple[int, int, int]] = []

    def dent(a, b, c):
        chord = np.linalg.norm(flat[c] - flat[a])
        cross = (flat[b, 0] - flat[a, 0]) * (flat[c, 1] - flat[b, 1]) - (flat[b, 1] - flat[a, 1]) * (
            flat[c, 0] - flat[b, 0]
        )
        return cross / chord if chord > 0.0 else 0.0

    while len(remaining) > 3:
        n = len(remaining)
        clipped = False
        for position in range(n):
            a, b, c = remaining[position - 1], remaining[position], remaining[(position + 1) % n]
            height = dent(a, b, c)
            if abs(height) <= length_eps:
                # a straight corner spans no area: drop it from the loop without a sliver triangle
                remaining.pop(position)
                clipped = True
                break
            if height < 0.0:
                continue
            if any(
                _inside_triangle(flat[other], flat[a], flat[b], flat[c])
                for other in remaining
                if other not in (a, b, c)
            ):
                continue
            triangles.append((a, b, c))
            remaining.pop(position)
            clipped = True
            break
        if not clipped:
            raise SceneError(f"polygon {index} could not be split into triangles (is it self-overlapping?)")
    a, b, c = remaining
    if abs(dent(a, b, c)) > length_eps:
        triangles.append((a, b, c))
    return triangles


def _inside_triangle(p, a, b, c) -> bool:
    def orient(q, r, s):
        return (r[0] - q[0]) * (s[1] - q[1]) - (r[1] - q[1]) * (s[0] - q[0])

    return orient(a, b, p) >= 0.0 and orient(b, c, p) >= 0.0 and orient(c, a, p) >= 0.0


def _polygon_geometry(corners: np.ndarray, offsets: np.ndarray):
    """Unit normals (P, 3), areas (P,) and area centroids (P, 3) of the CSR loops."""
    count = len(offsets) - 1
    normals = np.empty((count, 3))
    areas = np.empty(count)
    centroids = np.empty((count, 3))
    for i in range(count):
        loop = corners[offsets[i] : offsets[i + 1]]
        newell = _newell(loop)
        twice_area = np.linalg.norm(newell)
        normals[i] = newell / twice_area
        areas[i] = 0.5 * twice_area
        # fan triangles from the first corner, weighted by their signed area along the normal
        first = loop[0]
        a = loop[1:-1] - first
        b = loop[2:] - first
        weights = np.cross(a, b) @ normals[i]
        centres = first + (a + b) / 3.0
        centroids[i] = (weights[:, None] * centres).sum(axis=0) / weights.sum()
    return normals, areas, centroids


def _edges(vertex_ids: np.ndarray, offsets: np.ndarray, normals: np.ndarray, tol: Tolerance):
    """Unique undirected edges with their adjacent faces and kinds.

    Returns edges (E, 2), edge_kind (E,) int8, edge_face_offsets (E+1,), edge_faces (M,),
    polygon_edge_ids (N,), and for each edge whether exactly two faces traverse it in opposite directions.
    """
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(len(counts)), counts)
    position = np.arange(len(vertex_ids)) - offsets[owner]
    following = offsets[owner] + (position + 1) % counts[owner]
    start, end = vertex_ids, vertex_ids[following]
    low, high = np.minimum(start, end), np.maximum(start, end)
    edges, polygon_edge_ids = np.unique(np.stack([low, high], axis=1), axis=0, return_inverse=True)
    polygon_edge_ids = polygon_edge_ids.reshape(-1).astype(np.int64)
    edges = edges.astype(np.int64)

    order = np.argsort(polygon_edge_ids, kind="stable")
    edge_faces = owner[order].astype(np.int64)
    per_edge = np.bincount(polygon_edge_ids, minlength=len(edges))
    edge_face_offsets = np.zeros(len(edges) + 1, dtype=np.int64)
    edge_face_offsets[1:] = np.cumsum(per_edge)

    forward = (start < end)[order]
    kind = np.full(len(edges), EDGE_CREASE, dtype=np.int8)
    kind[per_edge == 1] = EDGE_BOUNDARY
    pair = np.flatnonzero(per_edge == 2)
    first = edge_face_offsets[pair]
    opposite = forward[first] != forward[first + 1]
    alignment = np.einsum("ij,ij->i", normals[edge_faces[first]], normals[edge_faces[first + 1]])
    flat = opposite & (alignment >= 1.0 - tol.cosine)
    kind[pair[flat]] = EDGE_FLAT
    closed = np.zeros(len(edges), dtype=bool)
    closed[pair[opposite]] = True
    return edges, kind, edge_face_offsets, edge_faces, polygon_edge_ids, closed


def _vertex_kinds(n_vertices: int, edges: np.ndarray, edge_kind: np.ndarray) -> np.ndarray:
    kinds = np.full(n_vertices, VERTEX_UNUSED, dtype=np.int8)
    kinds[edges.ravel()] = VERTEX_FLAT
    silhouette = edges[edge_kind != EDGE_FLAT].ravel()
    kinds[silhouette] = VERTEX_SILHOUETTE
    return kinds


def _connected_components(loops: list[np.ndarray], n_vertices: int) -> np.ndarray:
    """Object id of each input polygon: polygons sharing a vertex belong to the same object."""
    rows = np.concatenate([np.full(len(loop), i) for i, loop in enumerate(loops)])
    cols = np.concatenate(loops) + len(loops)
    size = len(loops) + n_vertices
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(size, size))
    _, labels = connected_components(graph, directed=False)
    polygon_labels = labels[: len(loops)]
    _, dense = np.unique(polygon_labels, return_inverse=True)
    return dense.astype(np.int64)


def _solid_objects(
    object_ids, edges, edge_face_offsets, edge_faces, closed_edges, normals, centroids, areas, tol: Tolerance
):
    """solid per polygon: its object is closed (every edge between two of its faces, walked both ways) and
    encloses a positive volume (divergence theorem: V = sum A (c . n) / 3, here taken about the object's first
    centroid so that far-off scenes do not cancel), so its normals point outwards. A flat closed object (two
    faces back to back) encloses nothing and is not solid."""
    closed = ~_open_objects(object_ids, edges, edge_face_offsets, edge_faces, closed_edges)
    count = int(object_ids.max()) + 1
    anchor = np.zeros((count, 3))
    anchor[object_ids[::-1]] = centroids[::-1]
    heights = np.einsum("ij,ij->i", centroids - anchor[object_ids], normals)
    volume = np.zeros(count)
    surface = np.zeros(count)
    np.add.at(volume, object_ids, areas * heights / 3.0)
    np.add.at(surface, object_ids, areas)
    return closed & (volume[object_ids] > tol.length * surface[object_ids])


def _open_objects(object_ids, edges, edge_face_offsets, edge_faces, closed_edges) -> np.ndarray:
    """two_sided per polygon: True for polygons of objects that are not closed (watertight) surfaces."""
    first_object = object_ids[edge_faces[edge_face_offsets[:-1]]]
    last_object = object_ids[edge_faces[edge_face_offsets[1:] - 1]]
    open_edge = ~closed_edges | (first_object != last_object)
    open_object = np.zeros(int(object_ids.max()) + 1, dtype=bool)
    open_object[first_object[open_edge]] = True
    open_object[last_object[open_edge]] = True
    return open_object[object_ids]
