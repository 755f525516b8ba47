"""The Visibility Skeleton: nodes and arcs with per-polygon and per-vertex storage, and its exact queries.

Durand et al. 1997, sections 3.1 and 4 (views of a polygon from a vertex, discontinuity meshes between two
polygons, exact blocker lists, interactions of an object) and section 5 (source-driven, lazy construction);
Durand et al. 1999, section 2.1.1 (storage per polygon and per vertex instead of the n^2 arrays) and section
4.2.1 (exact point-to-polygon form factors: the arcs of a vertex's view are the boundary of what it sees, their
end nodes are the corners R_i of Lambert's formula).

Storage (all CSR arrays, nothing quadratic): arcs by face-group pair (a, b) -> the arcs whose lines touch
surface a at one end and surface b at the other, sorted by a then b (the paper's DM(i, j), per polygon); EV
arcs by vertex -> the arcs through that vertex (its views of every polygon).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

import numpy as np
from numba import njit

from ..bvh import build_bvh
from ..errors import CancelledError, SceneError, VisradError
from ..formfactor import clip_to_hemisphere, lambert_sum
from ..scene import EDGE_FLAT, VERTEX_SILHOUETTE, Scene
from ..visibility import exact_form_factors
from .candidates import NodeCandidates
from .graph import assemble_arcs
from .topology import scene_topology
from .validation import (
    ARC_EV,
    ARC_NAMES,
    NODE_NAMES,
    REJECT_NAMES,
    IncidenceChunk,
    NodeChunk,
    validate_candidates,
)

Progress = Callable[[str, float], None]
Cancel = Callable[[], bool]


class Skeleton:
    """The skeleton of one scene, built for a set of source polygons (all of them after `complete`).

    nodes: NodeChunk of every node (see core.skeleton.validation); arcs: core.skeleton.graph.Arcs;
    sources: sorted (S,) int64 polygons the skeleton is complete for, or None when complete for every line.
    Queries about a source not built yet build it first (lazily), so every answer is exact.
    """

    def __init__(self, scene: Scene):
        self.scene = scene
        self.topology = scene_topology(scene)
        self.bvh = build_bvh(scene)
        self.vertex_mask = scene.vertex_kind == VERTEX_SILHOUETTE
        self.edge_mask = scene.edge_kind != EDGE_FLAT
        self.sources: np.ndarray | None = np.empty(0, dtype=np.int64)
        self._node_parts: list[NodeChunk] = []
        self._incidence_parts: list[IncidenceChunk] = []
        self._n_nodes = 0
        self.rejected = np.zeros(len(REJECT_NAMES), dtype=np.int64)
        self.seconds = 0.0
        self._finish()

    # ------------------------------------------------------------------------------------------------------
    # construction

    def build(self, sources=None, progress: Progress | None = None, cancel: Cancel | None = None) -> Skeleton:
        """Add the nodes whose line meets one of `sources` (None: every node); already built lines are kept.

        Raises CancelledError when `cancel()` turns true; the skeleton is then unchanged.
        """
        for _ in self.build_steps(sources, cancel):
            if progress is not None:
                progress("skeleton", _)
        return self

    def build_steps(self, sources=None, cancel: Cancel | None = None):
        """Generator form of `build`: yields the fraction done; the new nodes are committed at the end only."""
        from .enumeration import iter_candidates

        if self.sources is None:
            return
        wanted = None if sources is None else _polygon_ids(self.scene, sources)
        if wanted is not None:
            wanted = np.setdiff1d(wanted, self.sources)
            if len(wanted) == 0:
                return
        started = time.perf_counter()
        built = self.sources
        node_parts: list[NodeChunk] = []
        incidence_parts: list[IncidenceChunk] = []
        n_nodes = self._n_nodes
        rejected = np.zeros_like(self.rejected)
        for candidates, fraction in iter_candidates(
            self.scene, self.vertex_mask, self.edge_mask, sources=None if wanted is None else wanted.tolist(),
            cancel=cancel,
        ):  # fmt: skip
            if cancel is not None and cancel():
                raise CancelledError("skeleton construction cancelled")
            if len(built):
                candidates = _not_through(self.scene, candidates, built)
            nodes, incidences, counters = validate_candidates(
                self.scene, self.topology, self.bvh, candidates, self.edge_mask
            )
            rejected += counters
            node_parts.append(nodes)
            incidence_parts.append(
                IncidenceChunk(
                    incidences.node + n_nodes, incidences.kind, incidences.codes, incidences.end, incidences.s,
                    incidences.direction,
                )
            )
            n_nodes += len(nodes)
            yield fraction
        if cancel is not None and cancel():
            raise CancelledError("skeleton construction cancelled")
        self._node_parts.extend(node_parts)
        self._incidence_parts.extend(incidence_parts)
        self._n_nodes = n_nodes
        self.rejected = self.rejected + rejected
        self.sources = None if wanted is None else np.union1d(built, wanted)
        self.seconds += time.perf_counter() - started
        self._finish()
        yield 1.0

    def complete(self, progress: Progress | None = None, cancel: Cancel | None = None) -> Skeleton:
        """Build every node not built yet (seed 003 section 5, "final computation")."""
        return self.build(None, progress, cancel)

    def _finish(self) -> None:
        self.nodes = _concatenate_nodes(self._node_parts)
        incidences = _concatenate_incidences(self._incidence_parts)
        self._node_parts = [self.nodes]
        self._incidence_parts = [incidences]
        self.arcs = assemble_arcs(
            incidences.kind, incidences.codes, incidences.end, incidences.s, incidences.direction, incidences.node
        )
        self._index()

    def _index(self) -> None:
        scene, topo, arcs = self.scene, self.topology, self.arcs
        n_vertices = scene.n_vertices
        ev = np.flatnonzero(arcs.kind == ARC_EV)
        ev_vertex = arcs.codes[ev, 0]
        order = np.argsort(ev_vertex, kind="stable")
        self._vertex_arcs = ev[order]
        self._vertex_offsets = np.zeros(n_vertices + 1, dtype=np.int64)
        self._vertex_offsets[1:] = np.cumsum(np.bincount(ev_vertex, minlength=n_vertices))
        first, second, arc = _touch_pairs(
            arcs.kind, arcs.codes, arcs.end, n_vertices, topo.vertex_face_offsets, topo.vertex_faces,
            scene.edge_face_offsets, scene.edge_faces, topo.face_group,
        )  # fmt: skip
        order = np.lexsort((arc, second, first))
        self._pair_first = first[order]
        self._pair_second = second[order]
        self._pair_arcs = arc[order]

    # ------------------------------------------------------------------------------------------------------
    # statistics

    @property
    def stats(self) -> dict:
        """nodes and arcs per type, dangling arcs, rejected candidates per reason, seconds, bytes."""
        nodes = {name: int(np.count_nonzero(self.nodes.kind == kind)) for kind, name in NODE_NAMES.items()}
        arcs = {name: int(np.count_nonzero(self.arcs.kind == kind)) for kind, name in ARC_NAMES.items()}
        return {
            "nodes": nodes,
            "arcs": arcs,
            "dangling_arcs": int(np.count_nonzero(self.arcs.dangling)),
            "rejected": dict(zip(REJECT_NAMES, self.rejected.tolist(), strict=True)),
            "seconds": self.seconds,
            "bytes": self.nbytes,
            "sources": None if self.sources is None else self.sources.tolist(),
        }

    @property
    def nbytes(self) -> int:
        """Bytes held by nodes, arcs, kept incidences and the indexes."""
        arrays = [*vars(self.nodes).values(), *vars(self.arcs).values(), *vars(self._incidence_parts[0]).values()]
        arrays += [self._vertex_arcs, self._vertex_offsets, self._pair_first, self._pair_second, self._pair_arcs]
        return int(sum(a.nbytes for a in arrays))

    # ------------------------------------------------------------------------------------------------------
    # queries

    def _require(self, source: int) -> None:
        if self.sources is not None and source not in self.sources:
            self.build([source])

    def _group(self, polygon: int, name: str) -> int:
        if not 0 <= polygon < self.scene.n_polygons:
            raise SceneError(f"{name} {polygon} is not a polygon of the scene (0..{self.scene.n_polygons - 1})")
        return int(self.topology.face_group[polygon])

    def _pair(self, a: int, b: int) -> np.ndarray:
        lo = np.searchsorted(self._pair_first, a, side="left")
        hi = np.searchsorted(self._pair_first, a, side="right")
        inner = self._pair_second[lo:hi]
        return self._pair_arcs[lo + np.searchsorted(inner, b, side="left") : lo + np.searchsorted(inner, b, "right")]

    def interactions(self, polygon: int) -> np.ndarray:
        """Sorted (K,) int64 polygons that `polygon` sees: some critical line joins them (section 4.4)."""
        group = self._group(polygon, "polygon")
        self._require(polygon)
        lo = np.searchsorted(self._pair_first, group, side="left")
        hi = np.searchsorted(self._pair_first, group, side="right")
        groups = np.unique(self._pair_second[lo:hi])
        groups = groups[groups != group]
        return _polygons_of_groups(self.topology, groups)

    def blockers(self, source: int, receiver: int) -> np.ndarray:
        """Sorted (K,) int64 exact blocker list of the pair (section 4.4): the polygons around the generators
        of the critical lines joining source and receiver, the two polygons' own surfaces excluded."""
        a = self._group(source, "source")
        b = self._group(receiver, "receiver")
        self._require(source)
        arcs = self._pair(a, b)
        faces = []
        topo, scene = self.topology, self.scene
        for arc in arcs:
            for code in self.arcs.codes[arc]:
                if code < 0:
                    continue
                faces.append(_element_faces(scene, topo, int(code)))
        if not faces:
            return np.empty(0, dtype=np.int64)
        polygons = np.unique(np.concatenate(faces))
        return polygons[(topo.face_group[polygons] != a) & (topo.face_group[polygons] != b)]

    def discontinuities(self, source: int, receiver: int) -> np.ndarray:
        """(M, 2, 3) float64 segments on the receiver's plane: the traces of the EV and EEE swaths between
        source and receiver (EEE traces, quadric curves, as polylines within tol.curve)."""
        a = self._group(source, "source")
        b = self._group(receiver, "receiver")
        self._require(source)
        scene = self.scene
        normal = scene.normals[receiver]
        offset = scene.plane_offsets[receiver]
        pieces = []
        for arc in self._pair(a, b):
            if self.arcs.dangling[arc]:
                continue
            codes = self.arcs.codes[arc]
            if any(
                code >= 0 and b in self.topology.face_group[_element_faces(scene, self.topology, int(code))]
                for code in codes
            ):
                continue
            pieces.append(self._trace(arc, normal, offset))
        if not pieces:
            return np.empty((0, 2, 3))
        return np.concatenate(pieces)

    def _arc_line(self, arc: int, s: float) -> tuple[np.ndarray, np.ndarray]:
        """A point (3,) and direction (3,) of the arc's line at parameter s."""
        scene = self.scene
        codes = [int(c) for c in self.arcs.codes[arc] if c >= 0]
        nv = scene.n_vertices
        edges = sorted(c - nv for c in codes if c >= nv)
        param = edges[0]
        a, b = scene.vertices[scene.edges[param]]
        point = a + s * (b - a)
        others = [c for c in codes if c != param + nv]
        if self.arcs.kind[arc] == ARC_EV:
            vertex = scene.vertices[others[0]]
            return vertex, point - vertex
        normals = []
        for c in others:
            p, q = scene.vertices[scene.edges[c - nv]]
            normals.append(np.cross(p - point, q - point))
        return point, np.cross(normals[0], normals[1])

    def _trace(self, arc: int, normal: np.ndarray, offset: float) -> np.ndarray:
        """(k, 2, 3) segments: where the arc's lines meet the plane normal . x + offset = 0."""
        s0, s1 = self.arcs.s[arc]

        def hit(s):
            point, direction = self._arc_line(arc, s)
            return point - (normal @ point + offset) / (normal @ direction) * direction

        if self.arcs.kind[arc] == ARC_EV:
            return np.stack([hit(s0), hit(s1)])[None]
        samples = [(s0, hit(s0)), (s1, hit(s1))]
        limit = self.scene.tol.curve
        i = 0
        while i < len(samples) - 1 and len(samples) < 4096:
            (sa, pa), (sb, pb) = samples[i], samples[i + 1]
            sm = 0.5 * (sa + sb)
            pm = hit(sm)
            chord = pb - pa
            length2 = chord @ chord
            t = 0.0 if length2 == 0.0 else np.clip((pm - pa) @ chord / length2, 0.0, 1.0)
            if np.linalg.norm(pa + t * chord - pm) > limit:
                samples.insert(i + 1, (sm, pm))
            else:
                i += 1
        points = np.array([p for _, p in samples])
        return np.stack([points[:-1], points[1:]], axis=1)

    def visible_boundary(self, vertex: int, source: int) -> list[np.ndarray]:
        """The part of `source`'s surface seen from scene vertex `vertex` as closed loops (K, 3) float64 on its
        plane, counter-clockwise seen from the vertex around visible regions (holes clockwise). Raises
        VisradError when the vertex is not a generator (its view is not stored: use `form_factor`)."""
        scene = self.scene
        if not 0 <= vertex < scene.n_vertices:
            raise SceneError(f"vertex {vertex} is not a vertex of the scene (0..{scene.n_vertices - 1})")
        group = self._group(source, "source")
        self._require(source)
        if not self.vertex_mask[vertex]:
            raise VisradError(f"vertex {vertex} is not a silhouette vertex: the skeleton stores no view from it")
        return self._loops(vertex, source, group)

    def _loops(self, vertex: int, source: int, group: int) -> list[np.ndarray]:
        scene, arcs = self.scene, self.arcs
        nv = scene.n_vertices
        apex = scene.vertices[vertex]
        normal = scene.normals[source]
        offset = scene.plane_offsets[source]
        candidates = self._vertex_arcs[self._vertex_offsets[vertex] : self._vertex_offsets[vertex + 1]]
        traces: dict[tuple, list] = {}
        for arc in candidates:
            edge = int(arcs.codes[arc, 1]) - nv
            faces = scene.edge_faces[scene.edge_face_offsets[edge] : scene.edge_face_offsets[edge + 1]]
            own = faces[self.topology.face_group[faces] == group]
            if arcs.end[arc, 1] != group and len(own) == 0:
                continue
            traces.setdefault((edge, int(arcs.end[arc, 1])), []).append(arc)
        segments = []
        for (edge, _), pieces in traces.items():
            pieces.sort(key=lambda arc: arcs.s[arc, 0])
            merged = []
            for arc in pieces:
                s0, s1 = arcs.s[arc]
                n0, n1 = arcs.node[arc]
                # pieces split where only the far side behind the vertex changes (a face plane of the vertex,
                # an FvE node) abut on the same trace
                if merged and (merged[-1][1] == s0 or (merged[-1][3] < 0 and n0 < 0)):
                    merged[-1] = (merged[-1][0], s1, merged[-1][2], n1)
                else:
                    merged.append((s0, s1, n0, n1))
            for s0, s1, n0, n1 in merged:
                if n0 < 0 or n1 < 0:
                    raise VisradError(
                        f"the view of polygon {source} from vertex {vertex} is not closed: an arc along edge "
                        f"{edge} lacks a node (build the skeleton completely or report the scene)"
                    )
                a, b = scene.vertices[scene.edges[edge]]
                p0 = _onto_plane(apex, a + s0 * (b - a), normal, offset)
                p1 = _onto_plane(apex, a + s1 * (b - a), normal, offset)
                if _visible_on_left(scene, self.topology, edge, group, apex, p0, p1, normal):
                    segments.append((n0, n1, p0, p1))
                else:
                    segments.append((n1, n0, p1, p0))
        segments += _horizon_segments(scene, self.topology, segments, vertex, normal)
        return _chain(segments, vertex, source)

    def form_factor(self, vertex: int, source: int, receiver: int) -> float:
        """Exact occluded form factor from scene vertex `vertex`, with the normal of `receiver` (a polygon using
        that vertex), to polygon `source` (seed 000 section 4.2.1). Vertices whose view is not stored (flat
        ones) get it computed from the exact blocker list of the pair, as for vertices created by subdivision
        (seed 000 section 2.1.2)."""
        scene = self.scene
        if not 0 <= vertex < scene.n_vertices:
            raise SceneError(f"vertex {vertex} is not a vertex of the scene (0..{scene.n_vertices - 1})")
        group = self._group(source, "source")
        self._group(receiver, "receiver")
        if vertex not in scene.polygon_vertices(receiver):
            raise SceneError(f"receiver {receiver} does not use vertex {vertex}")
        if receiver == source:
            return 0.0
        self._require(source)
        point = scene.vertices[vertex]
        normal = scene.normals[receiver]
        if not self.vertex_mask[vertex]:
            blockers = self.blockers(source, receiver)
            return float(exact_form_factors(scene, point[None], normal[None], source, blockers=blockers)[0])
        total = 0.0
        clip = scene.polygon(source) if len(self.topology.polygons_of_group(group)) > 1 else None
        for loop in self._loops(vertex, source, group):
            if clip is not None:
                loop = _clip_to_convex(loop, clip, scene.normals[source])
            buffer = np.empty((2 * len(loop) + 1, 3))
            count = clip_to_hemisphere(loop, point, normal, buffer)
            if count >= 3:
                total += lambert_sum(point, normal, buffer, count)
        return abs(total) / (2.0 * np.pi)


def build_skeleton(scene: Scene, sources=None, progress: Progress | None = None, cancel: Cancel | None = None):
    """The Visibility Skeleton of `scene`: complete (sources=None) or only the nodes whose lines meet one of
    `sources` (polygon ids; seed 003 section 5); `skel.build(more)` / `skel.complete()` extend it later."""
    skeleton = Skeleton(scene)
    if sources is not None and len(list(sources)) == 0:
        return skeleton
    return skeleton.build(sources, progress, cancel)


# ----------------------------------------------------------------------------------------------------------
# helpers


def _polygon_ids(scene: Scene, sources: Iterable[int]) -> np.ndarray:
    ids = np.unique(np.asarray(list(sources), dtype=np.int64))
    bad = ids[(ids < 0) | (ids >= scene.n_polygons)]
    if len(bad):
        raise SceneError(f"source {int(bad[0])} is not a polygon of the scene (0..{scene.n_polygons - 1})")
    return ids


def _concatenate_nodes(parts: list[NodeChunk]) -> NodeChunk:
    if not parts:
        return NodeChunk(
            np.empty(0, np.int8), np.zeros((0, 4), np.int8), np.full((0, 4), -1, np.int64), np.empty((0, 3)),
            np.empty((0, 3)), np.empty((0, 4)), np.empty((0, 2), np.int64),
        )  # fmt: skip
    fields = vars(parts[0]).keys()
    return NodeChunk(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in fields})


def _concatenate_incidences(parts: list[IncidenceChunk]) -> IncidenceChunk:
    if not parts:
        return IncidenceChunk(
            np.empty(0, np.int64), np.empty(0, np.int8), np.empty((0, 3), np.int64), np.empty((0, 2), np.int64),
            np.empty(0), np.empty(0, np.int8),
        )  # fmt: skip
    fields = vars(parts[0]).keys()
    return IncidenceChunk(**{name: np.concatenate([getattr(p, name) for p in parts]) for name in fields})


def _element_faces(scene: Scene, topology, code: int) -> np.ndarray:
    nv = scene.n_vertices
    if code < nv:
        return topology.vertex_faces[topology.vertex_face_offsets[code] : topology.vertex_face_offsets[code + 1]]
    edge = code - nv
    return scene.edge_faces[scene.edge_face_offsets[edge] : scene.edge_face_offsets[edge + 1]]


def _polygons_of_groups(topology, groups: np.ndarray) -> np.ndarray:
    if len(groups) == 0:
        return np.empty(0, dtype=np.int64)
    return np.sort(np.concatenate([topology.polygons_of_group(int(g)) for g in groups]))


@njit(cache=True)
def _touch_pairs(kind, codes, end, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group):
    """For every arc, the (surface, surface) pairs it joins, both ways: the surfaces touched at each end are
    the one its lines end on and those around its outer generator (the lines graze it or stop on it)."""
    count = 0
    for arc in range(kind.shape[0]):
        last = 1 if kind[arc] == ARC_EV else 2
        sizes = np.zeros(2, dtype=np.int64)
        for side in range(2):
            code = codes[arc, 0 if side == 0 else last]
            sizes[side] = 1 + (vf_off[code + 1] - vf_off[code] if code < n_vertices else
                               ef_off[code - n_vertices + 1] - ef_off[code - n_vertices])
        count += 2 * sizes[0] * sizes[1]
    first = np.empty(count, dtype=np.int64)
    second = np.empty(count, dtype=np.int64)
    owner = np.empty(count, dtype=np.int64)
    touched = np.empty((2, 64), dtype=np.int64)
    n = 0
    for arc in range(kind.shape[0]):
        last = 1 if kind[arc] == ARC_EV else 2
        sizes = np.zeros(2, dtype=np.int64)
        for side in range(2):
            code = codes[arc, 0 if side == 0 else last]
            if end[arc, side] >= 0:
                sizes[side] = _add_unique(touched[side], sizes[side], end[arc, side])
            if code < n_vertices:
                for i in range(vf_off[code], vf_off[code + 1]):
                    sizes[side] = _add_unique(touched[side], sizes[side], face_group[vf_face[i]])
            else:
                e = code - n_vertices
                for i in range(ef_off[e], ef_off[e + 1]):
                    sizes[side] = _add_unique(touched[side], sizes[side], face_group[ef_face[i]])
        for i in range(sizes[0]):
            for j in range(sizes[1]):
                a = touched[0, i]
                b = touched[1, j]
                if a == b:
                    continue
                first[n] = a
                second[n] = b
                owner[n] = arc
                first[n + 1] = b
                second[n + 1] = a
                owner[n + 1] = arc
                n += 2
    return first[:n], second[:n], owner[:n]


@njit(cache=True)
def _add_unique(values, count, value):
    for i in range(count):
        if values[i] == value:
            return count
    if count < values.shape[0]:
        values[count] = value
        return count + 1
    return count


def _not_through(scene: Scene, candidates: NodeCandidates, polygons: np.ndarray) -> NodeCandidates:
    """The candidates whose line meets none of `polygons` (their nodes are built already)."""
    keep = ~_lines_meet_polygons(
        scene.polygon_points, scene.polygon_offsets, scene.normals, scene.plane_offsets,
        np.ascontiguousarray(polygons, dtype=np.int64), candidates.origin, candidates.direction, scene.tol.length,
    )  # fmt: skip
    return NodeCandidates(
        candidates.kind[keep], candidates.vertices[keep], candidates.edges[keep], candidates.origin[keep],
        candidates.direction[keep],
    )  # fmt: skip


@njit(cache=True)
def _lines_meet_polygons(points, offsets, normals, plane_offsets, polygons, origins, directions, tol):
    result = np.zeros(origins.shape[0], dtype=np.bool_)
    for c in range(origins.shape[0]):
        o = origins[c]
        d = directions[c]
        for p in polygons:
            n = normals[p]
            nd = n[0] * d[0] + n[1] * d[1] + n[2] * d[2]
            dist = n[0] * o[0] + n[1] * o[1] + n[2] * o[2] + plane_offsets[p]
            first = offsets[p]
            count = offsets[p + 1] - first
            if abs(nd) * 1e12 <= np.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]):
                if abs(dist) <= tol:
                    result[c] = True
                continue
            t = -dist / nd
            x = o + t * d
            inside = True
            for k in range(count):
                a = points[first + k]
                b = points[first + (k + 1) % count]
                e = b - a
                m = np.array([e[1] * n[2] - e[2] * n[1], e[2] * n[0] - e[0] * n[2], e[0] * n[1] - e[1] * n[0]])
                m /= np.sqrt(m[0] * m[0] + m[1] * m[1] + m[2] * m[2])
                if (x[0] - a[0]) * m[0] + (x[1] - a[1]) * m[1] + (x[2] - a[2]) * m[2] > tol:
                    inside = False
                    break
            if inside:
                result[c] = True
                break
    return result


def _onto_plane(apex: np.ndarray, through: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Where the line from apex through `through` meets the plane normal . x + offset = 0."""
    direction = through - apex
    return apex - (normal @ apex + offset) / (normal @ direction) * direction


def _visible_on_left(scene: Scene, topology, edge: int, group: int, apex, p0, p1, normal) -> bool:
    """Whether the part of the source seen from apex lies left of p0 -> p1 (seen from the apex's side).

    The trace of the swath (apex, edge) separates lines that reach the source from lines that hit the edge's
    faces (a blocker edge: the seen side is away from its faces) or miss the source (the source's own edge:
    the seen side is the source's)."""
    a, b = scene.vertices[scene.edges[edge]]
    swath = np.cross(b - a, apex - a)
    faces = scene.edge_faces[scene.edge_face_offsets[edge] : scene.edge_face_offsets[edge + 1]]
    own = faces[topology.face_group[faces] == group]
    face = int(own[0]) if len(own) else int(faces[0])
    inward = np.cross(scene.normals[face], b - a)
    if _edge_runs_forward(scene, face, edge):
        side = np.sign(swath @ inward)
    else:
        side = -np.sign(swath @ inward)
    if not len(own):
        side = -side
    facing = normal if normal @ (apex - p0) > 0.0 else -normal
    left = np.cross(facing, p1 - p0)
    return np.sign(swath @ left) == side


def _edge_runs_forward(scene: Scene, face: int, edge: int) -> bool:
    """Whether polygon `face` runs along `edge` from its first vertex to its second (counter-clockwise)."""
    ids = scene.polygon_vertices(face)
    first, second = scene.edges[edge]
    k = int(np.flatnonzero(ids == first)[0])
    return ids[(k + 1) % len(ids)] == second


def _horizon_segments(scene: Scene, topology, segments, vertex: int, normal) -> list:
    """The pieces of boundary traced by lines lying in a face plane of the vertex (its horizons: Fv swaths,
    seed 003 section 2.3.1): they join, along the line where that plane cuts the source's plane, the trace
    ends that have no continuation. Walking that line with the seen region on the left, each arriving end
    joins the next leaving end."""
    arriving: dict[int, np.ndarray] = {}
    leaving: dict[int, np.ndarray] = {}
    for n0, n1, p0, p1 in segments:
        leaving[n0] = p0
        arriving[n1] = p1
    loose_arrive = {n: p for n, p in arriving.items() if n not in leaving}
    loose_leave = {n: p for n, p in leaving.items() if n not in arriving}
    if not loose_arrive:
        return []
    apex = scene.vertices[vertex]
    tol = scene.tol.length
    added = []
    faces = topology.vertex_faces[topology.vertex_face_offsets[vertex] : topology.vertex_face_offsets[vertex + 1]]
    for face in faces:
        along = np.cross(scene.normals[face], normal)
        if along @ along == 0.0:
            continue
        ends = [
            (n, p, kind)
            for kind, table in ((0, loose_arrive), (1, loose_leave))
            for n, p in table.items()
            if abs(scene.normals[face] @ (p - apex)) <= 16.0 * tol * max(1.0, np.linalg.norm(p - apex) / scene.diagonal)
        ]
        if not ends:
            continue
        facing = normal if normal @ (apex - ends[0][1]) > 0.0 else -normal
        if np.cross(facing, along) @ scene.normals[face] < 0.0:
            along = -along
        ends.sort(key=lambda end: end[1] @ along)
        pending = None
        for n, p, kind in ends:
            if kind == 0:
                pending = (n, p)
            elif pending is not None:
                added.append((pending[0], n, pending[1], p))
                loose_arrive.pop(pending[0], None)
                loose_leave.pop(n, None)
                pending = None
    return added


def _chain(segments, vertex: int, source: int) -> list[np.ndarray]:
    """Closed loops from oriented segments (from node, to node, from point, to point)."""
    outgoing: dict[int, list[int]] = {}
    for i, (n0, _, _, _) in enumerate(segments):
        outgoing.setdefault(n0, []).append(i)
    used = np.zeros(len(segments), dtype=bool)
    loops = []
    for i in range(len(segments)):
        if used[i]:
            continue
        start = segments[i][0]
        loop = []
        j = i
        while True:
            used[j] = True
            loop.append(segments[j][2])
            node = segments[j][1]
            if node == start:
                break
            following = [k for k in outgoing.get(node, []) if not used[k]]
            if not following:
                raise VisradError(
                    f"the view of polygon {source} from vertex {vertex} does not close at node {node}"
                )
            j = following[0]
        loops.append(np.array(loop))
    return loops


def _clip_to_convex(loop: np.ndarray, polygon: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Sutherland-Hodgman clip of a loop (K, 3) lying in the plane of a convex polygon (M, 3) to it."""
    result = loop
    for k in range(len(polygon)):
        a = polygon[k]
        inward = np.cross(normal, polygon[(k + 1) % len(polygon)] - a)
        side = (result - a) @ inward
        kept = []
        for i in range(len(result)):
            j = (i + 1) % len(result)
            if side[i] >= 0.0:
                kept.append(result[i])
            if (side[i] > 0.0 and side[j] < 0.0) or (side[i] < 0.0 and side[j] > 0.0):
                t = side[i] / (side[i] - side[j])
                kept.append(result[i] + t * (result[j] - result[i]))
        if not kept:
            return np.empty((0, 3))
        result = np.array(kept)
    return result
