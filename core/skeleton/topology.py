"""Scene adjacencies the skeleton walks: faces around a vertex, edges around a vertex, faces along an edge.

Durand et al. 1997, section 3 ("Preliminaries: our scene model provides the adjacencies between vertices,
edges and faces"): a node's adjacent arcs are found by sliding a vertex generator along one of its edges and
by looking at the faces around each generator, so these lists are built once per scene, as CSR arrays.

Face groups: polygons joined by flat edges (coplanar neighbours, e.g. the two triangles of a split quad) form
one *face* for the skeleton. A flat edge is never a visual event (DESIGN.md section 4), so the arcs ending on
such a surface must not be split where the end point crosses it; arcs store face groups, not polygons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..scene import EDGE_FLAT, Scene


@dataclass(frozen=True, eq=False)
class Topology:
    """Adjacency lists of one scene, CSR (offsets (n+1,) int64, then the entries).

    vertex_face_offsets, vertex_faces, vertex_face_corner: the polygons around each vertex and the local
    corner index of the vertex in each; vertex_edge_offsets, vertex_edges: the edges at each vertex;
    edge_face_local (M,) int64: for each entry of scene.edge_faces, the local index k of the edge in that
    polygon (edge from corner k to k + 1); face_group (P,) int64: the flat-connected surface of each polygon;
    group_polygon_offsets, group_polygons: the polygons of each group.
    """

    vertex_face_offsets: np.ndarray
    vertex_faces: np.ndarray
    vertex_face_corner: np.ndarray
    vertex_edge_offsets: np.ndarray
    vertex_edges: np.ndarray
    edge_face_local: np.ndarray
    face_group: np.ndarray
    group_polygon_offsets: np.ndarray
    group_polygons: np.ndarray

    @property
    def n_groups(self) -> int:
        return len(self.group_polygon_offsets) - 1

    def polygons_of_group(self, group: int) -> np.ndarray:
        return self.group_polygons[self.group_polygon_offsets[group] : self.group_polygon_offsets[group + 1]]


def scene_topology(scene: Scene) -> Topology:
    """Build the adjacency lists of `scene` (vectorised, a few milliseconds for thousands of polygons)."""
    offsets = scene.polygon_offsets
    counts = np.diff(offsets)
    owner = np.repeat(np.arange(scene.n_polygons, dtype=np.int64), counts)
    corner = np.arange(len(scene.polygon_vertex_ids), dtype=np.int64) - offsets[owner]

    order = np.argsort(scene.polygon_vertex_ids, kind="stable")
    vertex_face_offsets = _csr_offsets(scene.polygon_vertex_ids, scene.n_vertices)
    vertex_faces = owner[order]
    vertex_face_corner = corner[order]

    ends = np.concatenate([scene.edges[:, 0], scene.edges[:, 1]])
    edge_ids = np.concatenate([np.arange(len(scene.edges))] * 2).astype(np.int64)
    order = np.argsort(ends, kind="stable")
    vertex_edge_offsets = _csr_offsets(ends, scene.n_vertices)
    vertex_edges = edge_ids[order]

    # scene.edge_faces lists, per edge, the polygons in the order of their corners: recover the local index
    edge_of_corner = scene.polygon_edge_ids
    entry_edge = np.repeat(np.arange(len(scene.edges), dtype=np.int64), np.diff(scene.edge_face_offsets))
    lookup = {(int(e), int(p)): int(k) for e, p, k in zip(edge_of_corner, owner, corner, strict=True)}
    edge_face_local = np.array(
        [lookup[(int(e), int(p))] for e, p in zip(entry_edge, scene.edge_faces, strict=True)], dtype=np.int64
    )

    face_group = _flat_groups(scene)
    order = np.argsort(face_group, kind="stable")
    group_polygon_offsets = _csr_offsets(face_group, int(face_group.max()) + 1 if len(face_group) else 0)
    group_polygons = order.astype(np.int64)

    arrays = (
        vertex_face_offsets,
        vertex_faces,
        vertex_face_corner,
        vertex_edge_offsets,
        vertex_edges,
        edge_face_local,
        face_group,
        group_polygon_offsets,
        group_polygons,
    )
    for array in arrays:
        array.flags.writeable = False
    return Topology(*arrays)


def _csr_offsets(keys: np.ndarray, n: int) -> np.ndarray:
    offsets = np.zeros(n + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(keys, minlength=n))
    return offsets


def _flat_groups(scene: Scene) -> np.ndarray:
    """Connected components of the polygons through flat edges, numbered in order of their first polygon."""
    first = scene.edge_face_offsets[:-1]
    pairs = np.flatnonzero(scene.edge_kind == EDGE_FLAT)
    rows = scene.edge_faces[first[pairs]]
    cols = scene.edge_faces[first[pairs] + 1]
    n = scene.n_polygons
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    _, first_seen = np.unique(labels, return_index=True)
    rank = np.empty(len(first_seen), dtype=np.int64)
    rank[np.argsort(first_seen)] = np.arange(len(first_seen))
    return rank[labels].astype(np.int64)
