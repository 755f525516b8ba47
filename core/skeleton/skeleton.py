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

import ctypes
import os
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, fields, replace
from functools import cached_property

import numpy as np
from numba import njit

from ..bvh import build_bvh
from ..errors import CancelledError, SceneError, VisradError
from ..formfactor import clip_to_hemisphere, lambert_sum
from ..jit import njit_leaf
from ..raycast import CONTACT_EDGE, CONTACT_VERTEX, _perpendicular_frame, first_hits
from ..scene import EDGE_FLAT, VERTEX_SILHOUETTE, Scene
from ..visibility import exact_form_factors
from .candidates import NodeCandidates
from .graph import _INSERTION_RUN, Arcs, _before, assemble_arcs, coincident_nodes
from .topology import scene_topology
from .validation import (
    ARC_EV,
    ARC_NAMES,
    END_FREE,
    END_PLANAR,
    NODE_NAMES,
    REJECT_NAMES,
    WORKERS,
    IncidenceChunk,
    NodeChunk,
    _enters,
    element_solids,
    flat_regions,
    validate_candidates,
)

Progress = Callable[[str, float], None]
Cancel = Callable[[], bool]

try:
    _malloc_trim = ctypes.CDLL("libc.so.6").malloc_trim
except (OSError, AttributeError):
    _malloc_trim = None
_PAGE_BYTES = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096
#: growth of the resident memory (bytes) over its lowest since the last trim that makes _return_free_memory trim
_TRIM_GROWTH = 32 << 20
_resident_low = 0


_PROBE_LENGTHS = 1e3
"""How far (tolerance lengths) a probe line passes beside an arc's line at its edge: far above the tolerance a
contact is decided within, far below the size of any feature of a sane scene."""

_CHUNKS_IN_FLIGHT = 3
"""Candidate chunks (enumeration.DEFAULT_CHUNK candidates, about 10 MB each) a build lets wait for validation or
for their commit before it stops taking the enumeration's output."""


@dataclass(frozen=True, eq=False)
class Probes:
    """The probed pieces of EV arcs (see Skeleton._probe_arcs), CSR: offsets (A+1,) int32 into the pieces, an
    arc's pieces in increasing s (none for an arc not probed); s (K, 2) float64 and node (K, 2) int32 each
    piece's bounds on the arc's edge and their nodes; seen (K, 2) int32 the face group each side of the
    piece's swath sees (+1 side: the side cross(b - a, apex - a) points to, then -1 side; -1 none)."""

    offsets: np.ndarray
    s: np.ndarray
    node: np.ndarray
    seen: np.ndarray


def _return_free_memory(always: bool = False) -> None:
    """Hand the free pages of the C heap back to the system (glibc only) once the resident memory of the process
    has grown by _TRIM_GROWTH over its lowest since they last were. A build allocates and frees many arrays below
    malloc's mmap threshold (the kernels' worst-case buffers, the pieces joined at the end): malloc keeps their
    pages, and the resident memory of the process (Blender's) would stay at its peak. Pages handed back are
    faulted in again, zeroed, by the next allocations: trimmed at every call, office-84's repeated builds took 6 %
    longer (2026-11-28). always: trim whatever the growth."""
    global _resident_low
    if _malloc_trim is None:
        return
    resident = _resident_bytes()
    if not always and resident is not None and resident < _resident_low + _TRIM_GROWTH:
        _resident_low = min(_resident_low, resident)
        return
    _malloc_trim(0)
    _resident_low = _resident_bytes() or 0


def _resident_bytes() -> int | None:
    """The resident memory of this process in bytes (Linux), None where it cannot be read."""
    try:
        with open("/proc/self/statm", "rb") as statm:
            return int(statm.read().split()[1]) * _PAGE_BYTES
    except (OSError, ValueError, IndexError):
        return None


class Skeleton:
    """The skeleton of one scene, built for a set of source polygons (all of them after `complete`).

    nodes: NodeChunk of the nodes (see core.skeleton.validation); arcs: core.skeleton.graph.Arcs;
    sources: sorted (S,) int64 polygons the skeleton is complete for, or None when complete for every line.
    Queries about a source not built yet build it first (lazily), so every answer is exact.

    While partial, the skeleton keeps every node found and every node-arc incidence, to merge and pair them
    with those of later builds: node_line (N,) int32 is then the node standing for each one's line (nodes on
    one line merged, core.skeleton.graph.coincident_nodes), and the arcs' nodes are such representatives. Once
    complete it keeps one node per line (node_line None) and no incidence. The incidences a build holds keep
    their codes and end groups in the narrowest integers that fit (_narrowest_int), and so do the end groups of
    its nodes and arcs.
    """

    def __init__(self, scene: Scene):
        self.scene = scene
        self.topology = scene_topology(scene)
        self.bvh = build_bvh(scene)
        self.vertex_mask = scene.vertex_kind == VERTEX_SILHOUETTE
        self.edge_mask = scene.edge_kind != EDGE_FLAT
        self._rest_offsets, self._rest_faces = _resting_on(
            scene.vertices, scene.polygon_points, scene.polygon_offsets, scene.normals, scene.plane_offsets,
            scene.object_ids, self.topology.vertex_face_offsets, self.topology.vertex_faces, scene.tol.length,
        )  # fmt: skip
        self._other_offsets, self._other_codes = _elements_at(
            scene.vertices, scene.edges, scene.edge_face_offsets, scene.edge_faces, scene.object_ids,
            self.topology.vertex_face_offsets, self.topology.vertex_faces, scene.tol.length,
        )  # fmt: skip
        self.sources: np.ndarray | None = np.empty(0, dtype=np.int64)
        self._views_lock = threading.Lock()
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
        element_solid = element_solids(self.scene, self.topology)
        face_region = flat_regions(self.scene)
        edge_tol = _edge_tolerance(self.scene)
        held_codes = _narrowest_int(self.scene.n_vertices + len(self.scene.edges))
        held_ends = _narrowest_int(self.topology.n_groups)

        def check_cancel() -> None:
            if cancel is not None and cancel():
                raise CancelledError("skeleton construction cancelled")

        def validated(candidates: NodeCandidates):
            if len(built):
                candidates = _not_through(self.scene, candidates, built)
            return validate_candidates(
                self.scene, self.topology, self.bvh, candidates, self.edge_mask, element_solid=element_solid,
                face_region=face_region,
            )

        def commit(validation, last: bool) -> None:
            nonlocal n_nodes
            nodes, incidences, counters = validation.result()
            # merged here, on this thread, while the validation thread goes on with the next chunk: that thread's
            # one serial step would leave a core idle at the end of every chunk. The last chunk of a complete
            # build is not: _finish merges every node on one line and counts a repeated incidence once anyway,
            # and nothing runs beside this step then
            if not (last and wanted is None):
                nodes, incidences = _merged_within(self.scene, nodes, incidences, edge_tol)
            rejected[:] += counters
            node_parts.append(replace(nodes, end=nodes.end.astype(held_ends)))
            incidence_parts.append(
                IncidenceChunk(
                    (incidences.node + n_nodes).astype(np.int32), incidences.kind,
                    incidences.codes.astype(held_codes), incidences.end.astype(held_ends), incidences.s,
                    incidences.direction,
                )
            )
            n_nodes += len(nodes)
            _return_free_memory()

        # chunks are validated in order on a thread of their own while the next ones are enumerated: neither
        # stage waits for the other's slowest slice to end. A validated chunk is committed as soon as it is
        # done, and this loop waits for one only when _CHUNKS_IN_FLIGHT are queued: enumeration, which
        # produces no more than its few pending work units while nobody takes them, goes on meanwhile
        in_flight: deque = deque()

        def committed(ready, enumerated: bool = False):
            """Commit and report the oldest chunks while ready(); the cancel request is honoured after each
            chunk reported, not only between enumerated chunks. enumerated: no chunk comes after these."""
            while in_flight and ready():
                done, done_fraction = in_flight.popleft()
                commit(done, enumerated and not in_flight)
                yield done_fraction
                check_cancel()

        with ThreadPoolExecutor(1) as pool:
            try:
                for candidates, fraction in iter_candidates(
                    self.scene, self.vertex_mask, self.edge_mask, sources=None if wanted is None else wanted.tolist(),
                    cancel=cancel, topology=self.topology,
                ):  # fmt: skip
                    check_cancel()
                    in_flight.append((pool.submit(validated, candidates), fraction))
                    del candidates
                    yield from committed(lambda: in_flight[0][0].done() or len(in_flight) > _CHUNKS_IN_FLIGHT)
                yield from committed(lambda: True, enumerated=True)
            except BaseException:
                # cancelled, failed or closed: the queued chunks are dropped, only the one being validated is
                # waited for
                for queued, _ in in_flight:
                    queued.cancel()
                raise
        check_cancel()
        self._node_parts.extend(node_parts)
        self._incidence_parts.extend(incidence_parts)
        # _finish lets each piece go once joined: no other reference may keep it
        node_parts.clear()
        incidence_parts.clear()
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
        scene = self.scene
        # the previous graph and its indexes go before the new ones are made
        self.nodes = self.arcs = self._vertex_arcs = self._views = None
        self._pair_first = self._pair_second = self._pair_offsets = self._pair_arcs = None
        nodes = _concatenated(NodeChunk, self._node_parts)
        _return_free_memory()
        node_line = coincident_nodes(nodes.start, nodes.direction, scene.diagonal, scene.tol.length)
        edge_tol = _edge_tolerance(scene)
        if self.sources is None:
            # no later build merges nodes or pairs incidences: the duplicates go before the arcs are assembled,
            # and the incidences as they are
            columns = dict(vars(nodes))
            del nodes
            nodes, node_id = _one_node_per_line(columns, node_line)
            del node_line
            _return_free_memory()
            self.arcs = _arcs_by_key_range(
                self._incidence_parts, node_id, edge_tol, scene.n_vertices, len(scene.edges), release=True
            )
            del node_id
            self.node_line = None
        else:
            incidences = _concatenated(IncidenceChunk, self._incidence_parts)
            _return_free_memory()
            self._incidence_parts = [incidences]
            self.arcs = _arcs_by_key_range(
                [incidences], node_line, edge_tol, scene.n_vertices, len(scene.edges), release=False
            )
            self._node_parts = [nodes]
            self.node_line = node_line
        self._n_nodes = len(nodes)
        self.nodes = nodes
        # the indexes are the build's last arrays, made beside the whole graph: the heap the assembly freed goes
        # first (office-1488's build, end groups in int32, peaked 436 MB above its baseline with this trim, 453 MB
        # without: 2026-12-02)
        _return_free_memory(always=True)
        self._index()
        _return_free_memory()

    def _index(self) -> None:
        scene, topo, arcs = self.scene, self.topology, self.arcs
        n_vertices = scene.n_vertices
        self._vertex_arcs, self._vertex_offsets = _vertex_index(arcs.kind, arcs.codes, n_vertices)
        self._pair_first, self._pair_second, self._pair_offsets, self._pair_arcs = _pair_index(
            arcs.kind, arcs.codes, arcs.ends, n_vertices, topo.vertex_face_offsets, topo.vertex_faces,
            scene.edge_face_offsets, scene.edge_faces, topo.face_group, topo.n_groups, WORKERS,
        )  # fmt: skip

    # ------------------------------------------------------------------------------------------------------
    # statistics

    @property
    def stats(self) -> dict:
        """nodes and arcs per type, dangling arcs, rejected candidates per reason, seconds, bytes."""
        distinct = True if self.node_line is None else self.node_line == np.arange(len(self.nodes))
        nodes = {
            name: int(np.count_nonzero(distinct & (self.nodes.kind == kind))) for kind, name in NODE_NAMES.items()
        }
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
        """Bytes held by nodes, arcs, the indexes (the vertex views' once a view was asked for) and, while partial,
        every node's line and the incidences."""
        arrays = [*vars(self.nodes).values(), *vars(self.arcs).values()]
        arrays += [self._vertex_arcs, self._vertex_offsets]
        if self._views is not None:
            arc_free, probes = self._views
            arrays += [arc_free, *vars(probes).values()]
        arrays += [self._pair_first, self._pair_second, self._pair_offsets, self._pair_arcs]
        if self.node_line is not None:
            arrays += [self.node_line, *vars(self._incidence_parts[0]).values()]
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
        """(K,) int64 the arcs joining surfaces a and b (either way round), in increasing order."""
        # keys of the index's own dtype: another one would have searchsorted convert the whole index
        a, b = np.int32(min(a, b)), np.int32(max(a, b))
        lo = np.searchsorted(self._pair_first, a, side="left")
        hi = np.searchsorted(self._pair_first, a, side="right")
        k = lo + np.searchsorted(self._pair_second[lo:hi], b, side="left")
        if k == hi or self._pair_second[k] != b:
            return np.empty(0, dtype=np.int64)
        return self._pair_arcs[self._pair_offsets[k] : self._pair_offsets[k + 1]].astype(np.int64)

    def interactions(self, polygon: int) -> np.ndarray:
        """Sorted (K,) int64 the polygons `polygon` sees (section 4.4), among those facing it (a vertex of each
        strictly in front of the other's plane): joined to it by the line of an arc along a free segment from a
        point of one to a point of the other, or seen from a vertex of it or seeing one of its vertices (the
        exact vertex views: form_factor > 0, see _sees). On a lazy skeleton the polygons tried are built as
        sources."""
        group = self._group(polygon, "polygon")
        self._require(polygon)
        scene, tol = self.scene, self.scene.tol.length
        offsets, ids = scene.polygon_offsets, scene.polygon_vertex_ids
        in_front_of_polygon = scene.vertices[ids] @ scene.normals[polygon] + scene.plane_offsets[polygon] > tol
        own = scene.polygon_vertices(polygon)
        own_in_front = scene.vertices[own] @ scene.normals.T + scene.plane_offsets > tol
        facing = np.logical_or.reduceat(in_front_of_polygon, offsets[:-1]) & own_in_front.any(axis=0)
        facing &= self.topology.face_group != group
        seen = facing & self._joined_freely(polygon, group)
        # two surfaces seeing each other with no silhouette between (the walls of a room) share no arc
        for other in np.flatnonzero(facing & ~seen).tolist():
            corners = slice(offsets[other], offsets[other + 1])
            theirs = ids[corners][in_front_of_polygon[corners]]
            seen[other] = any(self._sees(v, polygon, other) for v in theirs.tolist()) or any(
                self._sees(v, other, polygon) for v in own[own_in_front[:, other]].tolist()
            )
        return np.flatnonzero(seen).astype(np.int64)

    def _sees(self, vertex: int, source: int, receiver: int) -> bool:
        """Whether the points of `receiver` near its corner `vertex` see `source`, read from the vertex's view.
        A vertex resting on another object's face (see _resting_on) sees into that object through the face's
        plane, as a point of contact does in the exact form factors: only sources wholly in front of those
        planes are read from it (a leg's top corner under a table top sees the room through the top). A vertex
        at another object's vertex or edge (see _elements_at) is not read: where the receiver lies flush on
        that object, its corner sees through it along the contact (a box stacked flush on another). Nor is a
        view form_factor refuses (one that does not close: none known)."""
        if self._other_offsets[vertex + 1] > self._other_offsets[vertex]:
            return False
        rests = self._rest_faces[self._rest_offsets[vertex] : self._rest_offsets[vertex + 1]]
        heights = self.scene.polygon(source) @ self.scene.normals[rests].T + self.scene.plane_offsets[rests]
        if not (heights >= -self.scene.tol.length).all():
            return False
        try:
            return self.form_factor(vertex, source, receiver) > 0.0
        except VisradError:
            return False

    def _joined_freely(self, polygon: int, group: int) -> np.ndarray:
        """(P,) bool: the polygons the line of an arc joining their surface and `polygon`'s (`group`) runs to,
        at the arc's middle, from a point of `polygon` to a point of theirs, leaving the front of one and
        reaching the front of the other. The lines of an arc are free between the surfaces it joins."""
        scene = self.scene
        joined = np.zeros(scene.n_polygons, dtype=bool)
        rows = np.flatnonzero((self._pair_first == group) | (self._pair_second == group))
        counts = self._pair_offsets[rows + 1] - self._pair_offsets[rows]
        if counts.sum() == 0:
            return joined
        first = np.repeat(self._pair_offsets[rows] - np.cumsum(counts) + counts, counts)
        arcs = self._pair_arcs[first + np.arange(counts.sum())].astype(np.int64)
        others = np.repeat(np.where(self._pair_first[rows] == group, self._pair_second[rows], self._pair_first[rows]),
                           counts)  # fmt: skip
        middle = self.arcs.s[arcs].mean(axis=1)
        # lines lying in a face's plane slide along it: onto the corner of a face pressed flush against another,
        # they join it edge-on only
        known = np.isfinite(middle) & ~(self.arcs.ends[arcs] == END_PLANAR).any(axis=(1, 2))
        arcs, others, middle = arcs[known], others[known], middle[known]
        origin, direction = _arc_lines(self.arcs.kind, self.arcs.codes, arcs, middle, scene.vertices, scene.edges,
                                       scene.n_vertices)  # fmt: skip
        at_polygon = _line_meets_polygon(scene, polygon, origin, direction)
        normal = scene.normals[polygon]
        for other_group in np.unique(others).tolist():
            lines = np.flatnonzero((others == other_group) & np.isfinite(at_polygon))
            for other in self.topology.polygons_of_group(other_group).tolist():
                at_other = _line_meets_polygon(scene, other, origin[lines], direction[lines])
                towards = (at_other - at_polygon[lines])[:, None] * direction[lines]
                joined[other] = np.any(
                    (np.abs(at_other - at_polygon[lines]) * np.linalg.norm(direction[lines], axis=1)
                     > scene.tol.length)
                    & (towards @ normal > 0.0) & (towards @ scene.normals[other] < 0.0)
                )  # fmt: skip
        return joined

    def blockers(self, source: int, receiver: int) -> np.ndarray:
        """Sorted (K,) int64 exact blocker list of the pair (section 4.4): the polygons around the generators
        of the critical lines joining source and receiver, the two polygons' own surfaces excluded."""
        a = self._group(source, "source")
        b = self._group(receiver, "receiver")
        self._require(source)
        codes = np.unique(self.arcs.codes[self._pair(a, b)])
        topo, scene = self.topology, self.scene
        faces = [_element_faces(scene, topo, int(code)) for code in codes[codes >= 0]]
        if not faces:
            return np.empty(0, dtype=np.int64)
        polygons = np.unique(np.concatenate(faces))
        return polygons[(topo.face_group[polygons] != a) & (topo.face_group[polygons] != b)]

    def element_faces(self, code: int) -> np.ndarray:
        """(K,) int64 the polygons around a generator element (vertex v as code v, edge e as n_vertices + e)."""
        return _element_faces(self.scene, self.topology, int(code))

    def discontinuities(self, source: int, receiver: int) -> np.ndarray:
        """(M, 2, 3) float64 segments on the receiver's plane: the traces of the EV and EEE swaths between
        source and receiver (EEE traces, quadric curves, as polylines within tol.curve)."""
        return self.discontinuity_events(source, receiver)[0]

    def discontinuity_events(self, source: int, receiver: int) -> tuple[np.ndarray, np.ndarray]:
        """The segments of `discontinuities` (M, 2, 3) float64 and the generators of the swath each traces,
        (M, 3) int64 element codes (vertex v as v, edge e as n_vertices + e, -1 unused): what the ranking of
        seed 000 section 6.4 needs to find the blocker of each visual event."""
        a = self._group(source, "source")
        b = self._group(receiver, "receiver")
        self._require(source)
        scene = self.scene
        normal = scene.normals[receiver]
        offset = scene.plane_offsets[receiver]
        pieces = []
        generators = []
        for arc in self._pair(a, b):
            if (self.arcs.node[arc] < 0).any():
                continue
            codes = self.arcs.codes[arc]
            if any(
                code >= 0 and b in self.topology.face_group[_element_faces(scene, self.topology, int(code))]
                for code in codes
            ):
                continue
            trace = self._trace(arc, normal, offset)
            pieces.append(trace)
            generators.append(np.repeat(codes[None, :3].astype(np.int64), len(trace), axis=0))
        if not pieces:
            return np.empty((0, 2, 3)), np.empty((0, 3), dtype=np.int64)
        return np.concatenate(pieces), np.concatenate(generators)

    def _trace(self, arc: int, normal: np.ndarray, offset: float) -> np.ndarray:
        """(k, 2, 3) float64 segments, k >= 0: where the arc's lines meet the plane normal . x + offset = 0.

        Only the lines meeting the plane inside the scene's bounding box grown by its diagonal are traced: a
        line parallel to the plane (an arc ending at a node whose line slides in the receiver's plane) meets
        it nowhere or at infinity, and every point a receiver can use lies in the box. The arc's range is cut
        down to those lines by bisection from each end; an arc with none of them traces nothing. EEE traces are
        cut in halves until each piece's middle lies within tol.curve of its chord (at most _TRACE_SAMPLES
        points)."""
        scene = self.scene
        # a writable copy whatever the caller passes (a row of the scene's read-only normals): a read-only array
        # is another signature, which numba would compile on the first query that traces one (seconds)
        return _traced(
            self.arcs.kind[arc], self.arcs.codes[arc], self.arcs.s[arc, 0], self.arcs.s[arc, 1], scene.vertices,
            scene.edges, scene.n_vertices, np.array(normal, dtype=np.float64), float(offset),
            scene.bbox_min - scene.diagonal, scene.bbox_max + scene.diagonal, scene.tol.cosine, scene.tol.curve,
        )  # fmt: skip

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
        """The view of `source` (face group `group`) from scene vertex `vertex`, chained from its arcs.

        Its boundary is traced by the EV arcs (vertex, e) whose lines leave the vertex into free space and
        either graze a blocker edge e and end on the source, or meet an edge e of the source that the lines just
        inside it reach (seed 003 section 4.1). The horizons of the vertex's own faces are such arcs too: lines
        sliding over a face of the vertex to its far edge. Each arc's end nodes are corners of the view."""
        scene, arcs, topo = self.scene, self.arcs, self.topology
        nv = scene.n_vertices
        apex = scene.vertices[vertex]
        normal = scene.normals[source]
        offset = scene.plane_offsets[source]
        if abs(normal @ apex + offset) <= scene.tol.length:
            # a surface is seen edge-on from its own plane: it subtends no solid angle
            return []
        candidates = self._vertex_arcs[self._vertex_offsets[vertex] : self._vertex_offsets[vertex + 1]]
        edges = arcs.codes[candidates, 1] - nv
        # an arc whose lines end exactly on the edge between the source and another face (its two nodes found
        # either) ends on the source
        ends_on_source = (arcs.ends[candidates, :, 1] == group).any(axis=1)
        bounds_source = self._edge_touches_group(edges, group)
        # lines lying in a face's plane end where rounding puts them (END_PLANAR), lines said to leave the scene
        # may end exactly on an edge (the concave edge of a room, where rounding finds neither wall), and an arc
        # with nodes inside it changes what its lines meet there (see _arc_cuts): those are read piece by piece
        # from their probes (see _probe_arcs)
        arc_free, probes = self._view_index()
        first, last = probes.offsets[candidates], probes.offsets[candidates + 1]
        probed = (last - first > 1) | ((last > first) & ~bounds_source)
        # only the probed arcs with a piece seeing the source on one side bound its view
        counts = (last - first)[probed]
        pieces = np.arange(counts.sum()) + np.repeat(first[probed] - np.cumsum(counts) + counts, counts)
        seen = probes.seen[pieces] == group
        bounding = np.zeros(len(candidates), dtype=bool)
        bounding[np.repeat(np.flatnonzero(probed), counts)[seen[:, 0] != seen[:, 1]]] = True
        related = ((ends_on_source | bounds_source) & ~probed) | bounding
        dangling = (arcs.node[candidates] < 0).any(axis=1)
        segments = []
        # arcs along collinear edges overlapping (the top edges of two boxes side by side) are the same lines
        # where the edges overlap: one swath between the same two nodes, traced once
        traced = set()
        for arc, edge, on_source, by_probe, open_end in zip(
            candidates[related], edges[related], ends_on_source[related], probed[related], dangling[related],
            strict=True,
        ):
            if not arc_free[arc]:
                continue
            if by_probe:
                seen = probes.seen[probes.offsets[arc] : probes.offsets[arc + 1]] == group
                sides = np.where(seen[:, 0] == seen[:, 1], 0, np.where(seen[:, 0], 1, -1))
                pieces = zip(
                    *probes.s[probes.offsets[arc] : probes.offsets[arc + 1]].T,
                    *probes.node[probes.offsets[arc] : probes.offsets[arc + 1]].T, sides, strict=True,
                )
            else:
                side = _seen_side(
                    scene, topo, self._faces_along(int(edge), float(arcs.s[arc].mean())), int(edge), group, apex,
                    group if on_source else int(arcs.end[arc, 1]),
                )
                if side != 0 and open_end:
                    raise VisradError(
                        f"the view of polygon {source} from vertex {vertex} is not closed: an arc along edge "
                        f"{edge} lacks a node (build the skeleton completely or report the scene)"
                    )
                pieces = [(*arcs.s[arc], *arcs.node[arc], side)]
            a, b = scene.vertices[scene.edges[edge]]
            for s0, s1, n0, n1, side in pieces:
                n0, n1 = int(n0), int(n1)
                if side == 0 or (min(n0, n1), max(n0, n1)) in traced:
                    continue
                traced.add((min(n0, n1), max(n0, n1)))
                p0 = _onto_plane(apex, a + s0 * (b - a), normal, offset)
                p1 = _onto_plane(apex, a + s1 * (b - a), normal, offset)
                if _seen_on_left(apex, a, b, 0.5 * (s0 + s1), normal, offset, side):
                    segments.append((n0, n1, p0, p1))
                else:
                    segments.append((n1, n0, p1, p0))
        rests = self._rest_faces[self._rest_offsets[vertex] : self._rest_offsets[vertex + 1]]
        if len(rests):
            segments += _along_rest_planes(
                segments, scene.normals[rests], scene.plane_offsets[rests], 16.0 * scene.tol.length
            )
        return _chain(segments, vertex, source)

    def index_views(self) -> Skeleton:
        """Make now what vertex views (form_factor, visible_boundary) read, which the first view makes otherwise;
        returns self."""
        self._view_index()
        return self

    def _view_index(self) -> tuple[np.ndarray, Probes]:
        """(arc_free (A,) bool: whether each arc's lines leave its vertex into free space, Probes): what vertex
        views read (see _loops). Made by the first view after a build, not by the build: a bake reads
        discontinuities and blockers only, and each build a bake extends would make them again."""
        with self._views_lock:
            if self._views is None:
                scene, arcs, topo = self.scene, self.arcs, self.topology
                arc_free = _arcs_leave_freely(
                    arcs.kind, arcs.codes, arcs.s, arcs.dangling, scene.n_vertices, scene.vertices, scene.edges,
                    scene.polygon_points, scene.polygon_offsets, scene.normals, topo.vertex_face_offsets,
                    topo.vertex_faces, topo.vertex_face_corner, self._rest_offsets, self._rest_faces,
                    self._other_offsets, self._other_codes, scene.edge_face_offsets, scene.edge_faces,
                    topo.edge_face_local, scene.tol.cosine, WORKERS,
                )  # fmt: skip
                self._views = (arc_free, self._probe_arcs())
            return self._views

    def _probe_arcs(self) -> Probes:
        """The probes of the EV arcs whose sides the faces along them do not tell: lines lying in a face's
        plane (END_PLANAR), lines said to leave the scene (END_FREE: in a closed scene they end exactly on an
        edge), arcs with nodes inside them (_arc_cuts). Each such arc is cut at those nodes into pieces; the
        middle line of each piece, moved off the swath to either side by _PROBE_LENGTHS tolerance lengths at
        its edge, is cast from the vertex: the face group it meets first (-1: none, or it leaves the vertex into
        a solid, see _leaves_freely) is what that side of the piece sees."""
        scene, arcs, topo = self.scene, self.arcs, self.topology
        nv = scene.n_vertices
        cut_offsets, cut_s, cut_node = _arc_cuts(
            arcs.kind, arcs.codes, arcs.s, arcs.node, nv, scene.vertices, scene.edges, self.nodes.start,
            self.nodes.direction, self._vertex_offsets, self._vertex_arcs, scene.tol.snap, scene.tol.cosine, WORKERS,
        )  # fmt: skip
        _return_free_memory()
        offsets = _probed_pieces(arcs.kind, arcs.node, arcs.ends, cut_offsets)
        piece_s, piece_node = _piece_bounds(offsets, cut_offsets, cut_s, cut_node, arcs.s, arcs.node)
        del cut_offsets, cut_s, cut_node
        arc = _arc_of_pieces(offsets)
        seen = np.full((len(arc), 2), -1, dtype=np.int32)

        def probe_side(column: int, _) -> None:
            side = 1.0 if column == 0 else -1.0
            # the rays of all pieces at once would set the peak memory of a build
            for lo in range(0, len(arc), _PROBED_AT_ONCE):
                hi = min(lo + _PROBED_AT_ONCE, len(arc))
                vertex = arcs.codes[arc[lo:hi], 0].astype(np.int64)
                edge = (arcs.codes[arc[lo:hi], 1] - nv).astype(np.int64)
                directions = _probe_directions(
                    vertex, edge, piece_s[lo:hi], scene.vertices, scene.edges,
                    side * _PROBE_LENGTHS * scene.tol.length,
                )  # fmt: skip
                free = _lines_leave_freely(
                    vertex, directions, scene.polygon_points, scene.polygon_offsets, scene.normals,
                    topo.vertex_face_offsets, topo.vertex_faces, topo.vertex_face_corner, self._rest_offsets,
                    self._rest_faces, self._other_offsets, self._other_codes, scene.edge_face_offsets,
                    scene.edge_faces, topo.edge_face_local, scene.tol.cosine,
                )  # fmt: skip
                polygon, _, _ = first_hits(scene, self.bvh, scene.vertices[vertex], directions)
                hit = np.flatnonzero(free & (polygon >= 0))
                seen[lo + hit, column] = topo.face_group[polygon[hit]]

        # the two sides of the pieces (columns 0 and 1 of seen, as slices) are probed at once: the kernels release
        # the GIL
        _on_threads(probe_side, [(0, 1), (1, 2)], min(2, WORKERS) if len(arc) >= _PROBED_ON_ONE_THREAD else 1)
        return Probes(offsets, piece_s, piece_node, seen)

    @cached_property
    def _collinear(self) -> tuple[np.ndarray, np.ndarray]:
        """_collinear_edges of the scene, made by the first query that needs them: a build does not."""
        return _collinear_edges(self.scene)

    def _faces_along(self, edge: int, s: float) -> list[tuple[int, int]]:
        """(face, its edge) pairs around the point at parameter s of `edge`: the edge's own faces, and those of
        other edges on the same line that hold the point (two boxes side by side: the top edges at their
        contact overlap, and each box's faces there close around the other's edge as well)."""
        scene = self.scene
        faces = [(int(face), edge) for face in scene.edge_polygons(edge)]
        offsets, collinear = self._collinear
        others = collinear[offsets[edge] : offsets[edge + 1]]
        if len(others) == 0:
            return faces
        a, b = scene.vertices[scene.edges[edge]]
        point = a + s * (b - a)
        for other in others:
            p, q = scene.vertices[scene.edges[other]]
            along = q - p
            length = np.linalg.norm(along)
            t = (point - p) @ along / length
            if scene.tol.length < t < length - scene.tol.length:
                faces.extend((int(face), int(other)) for face in scene.edge_polygons(int(other)))
        return faces

    def _edge_touches_group(self, edges: np.ndarray, group: int) -> np.ndarray:
        """(K,) bool: which of the edges (K,) int64 bound a polygon of face group `group`."""
        scene = self.scene
        groups = self.topology.face_group[scene.edge_faces]
        hit = np.zeros(len(scene.edges), dtype=np.bool_)
        owner = np.repeat(np.arange(len(scene.edges)), np.diff(scene.edge_face_offsets))
        hit[owner[groups == group]] = True
        return hit[edges]

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


def _edge_tolerance(scene: Scene) -> np.ndarray:
    """(E,) the tolerance length as a parameter along each edge."""
    ends = scene.vertices[scene.edges]
    return scene.tol.length / np.linalg.norm(ends[:, 1] - ends[:, 0], axis=1)


_EMPTY = {
    NodeChunk: lambda: NodeChunk(
        np.empty(0, np.int8), np.zeros((0, 4), np.int8), np.full((0, 4), -1, np.int32), np.empty((0, 3)),
        np.empty((0, 3)), np.empty((0, 2), np.int32), np.empty((0, 2)),
    ),
    IncidenceChunk: lambda: IncidenceChunk(
        np.empty(0, np.int32), np.empty(0, np.int8), np.empty((0, 3), np.int32), np.empty((0, 2), np.int32),
        np.empty(0), np.empty(0, np.int8),
    ),
}  # fmt: skip


def _concatenated(chunk_type, parts: list):
    """One chunk_type (NodeChunk, IncidenceChunk or Arcs) holding the rows of `parts` in order. Empties `parts`
    and lets each piece go once copied: the joined columns are allocated first but their pages are taken only
    as the rows arrive, so the peak is the rows plus one piece, not all the pieces and all the joined rows."""
    if not parts:
        return _EMPTY[chunk_type]()
    if any(len(part) for part in parts):
        # the empty part of a skeleton built for no source yet would widen the joined columns
        parts[:] = [part for part in parts if len(part)]
    if len(parts) == 1:
        return parts.pop()
    names = [field.name for field in fields(chunk_type)]
    joined = {}
    for name in names:
        columns = [getattr(part, name) for part in parts]
        joined[name] = np.empty((sum(len(c) for c in columns), *columns[0].shape[1:]), np.result_type(*columns))
    del columns
    parts.reverse()
    row = 0
    while parts:
        part = parts.pop()
        for name in names:
            joined[name][row : row + len(part)] = getattr(part, name)
        row += len(part)
        del part
        _return_free_memory()
    return chunk_type(**joined)


#: probed pieces whose rays are cast at a time (see Skeleton._probe_arcs)
_PROBED_AT_ONCE = 1 << 16
#: fewer probed pieces than this are probed on one thread, both sides in turn (office-84's 2 767 pieces took
#: 13-15 ms on one thread, 16 ms with a thread per side)
_PROBED_ON_ONE_THREAD = 1 << 13

#: fewer arcs than this are indexed by surface pair on one thread (see _pair_index): office-168's 66 701 arcs took
#: 25 ms on one thread, 29 ms on two; office-312's 193 999 took 75 ms on two, 125 ms on one (2026-11-29)
_PAIRED_ON_ONE_THREAD = 1 << 17

#: incidences assembled into arcs at a time (see _arcs_by_key_range): each range's sort keys, order and widened
#: codes and arcs are held beside the incidences of the others, a range per thread. Office-1488's largest resident
#: memory while assembling, with malloc's mmap threshold fixed at 128 kB (so that it counts held arrays only):
#: 406 MB above the build's baseline at 1 << 20, 369 MB at 1 << 19 (2026-12-02)
_ASSEMBLED_AT_ONCE = 1 << 19
#: fewer incidences than this are assembled on one thread (a thread's start costs more than it saves)
_ASSEMBLED_ON_ONE_THREAD = 1 << 15


def _arcs_by_key_range(parts: list, node_id, edge_tol, n_vertices: int, n_edges: int, release: bool) -> Arcs:
    """The arcs (core.skeleton.graph.assemble_arcs) of the incidences of `parts` (IncidenceChunk, their node
    ids mapped through node_id (N,) int32), assembled for one range of keys (kind, first generator) at a time on
    each of WORKERS threads: arcs are sorted by their key first, so the pieces joined in order are the arcs of
    all incidences at once. When `release`, `parts` is emptied (see _pieces_by_key_range): all incidences, their
    sort and all arcs at once would set the peak memory of a build."""
    n_codes = n_vertices + n_edges
    counts = np.zeros(len(ARC_NAMES) * n_codes, dtype=np.int64)
    for part in parts:
        counts += np.bincount(_key_prefix(part, n_codes), minlength=len(counts))
    cumulative = np.concatenate([[0], np.cumsum(counts)])
    total = int(cumulative[-1])
    # a range per thread at least: the assembly's kernels release the GIL
    pieces = max(1, -(-total // _ASSEMBLED_AT_ONCE), min(WORKERS, total // _ASSEMBLED_ON_ONE_THREAD))
    bounds = np.unique(np.searchsorted(cumulative, np.linspace(0, cumulative[-1], pieces + 1)[1:-1]))
    bounds = np.array([0, *bounds.tolist(), len(counts)], dtype=np.int64)

    def assembled(piece):
        # the arcs' end groups stay as narrow as the incidences held them: int32 they took 56 of the 370 MB of
        # office-1488's skeleton
        return assemble_arcs(
            piece.kind, piece.codes.astype(np.int32, copy=False), piece.end, piece.s, piece.direction,
            node_id[piece.node], edge_tol, n_vertices,
        )  # fmt: skip

    if pieces == 1:
        return _concatenated(Arcs, [assembled(part) for part in _pieces_by_key_range(parts, bounds, n_codes, release)])
    arcs = []
    with ThreadPoolExecutor(WORKERS) as pool:
        running = []
        # at most one range per thread in hand: the incidences of the others wait unsorted
        for piece in _pieces_by_key_range(parts, bounds, n_codes, release):
            running.append(pool.submit(assembled, piece))
            del piece
            if len(running) == WORKERS:
                arcs.append(running.pop(0).result())
                _return_free_memory()
        arcs.extend(future.result() for future in running)
    return _concatenated(Arcs, arcs)


def _pieces_by_key_range(parts: list, bounds: np.ndarray, n_codes: int, release: bool):
    """Yield, for each range [bounds[k], bounds[k + 1]) of key prefixes (see _key_prefix), the incidences of
    `parts` (IncidenceChunk) in it as one IncidenceChunk, in the order of `parts` and of their rows. When
    `release`, each part is split among the ranges in one pass and let go (`parts` ends empty): its rows are
    then held once, in their range; otherwise each range's rows are copied out of the parts, which stay."""
    names = [field.name for field in fields(IncidenceChunk)]
    n_ranges = len(bounds) - 1
    if n_ranges == 1:
        # one range holds every row, in the parts' order: nothing to split or select (a copy of each column)
        yield _concatenated(IncidenceChunk, parts if release else list(parts))
        return
    if not release:
        for lo, hi in zip(bounds[:-1], bounds[1:], strict=True):
            taken = []
            for part in parts:
                prefix = _key_prefix(part, n_codes)
                inside = (prefix >= lo) & (prefix < hi)
                taken.append(IncidenceChunk(*(getattr(part, name)[inside] for name in names)))
            yield _concatenated(IncidenceChunk, taken)
        return

    def split(part) -> list:
        which = np.searchsorted(bounds, _key_prefix(part, n_codes), side="right") - 1
        order = np.argsort(which, kind="stable")
        cuts = np.searchsorted(which[order], np.arange(n_ranges + 1))
        return [IncidenceChunk(*(getattr(part, name)[order[lo:hi]] for name in names)) if hi > lo else None
                for lo, hi in zip(cuts[:-1], cuts[1:], strict=True)]  # fmt: skip

    ranges: list[list[IncidenceChunk]] = [[] for _ in range(n_ranges)]

    def keep(split_part: list) -> None:
        for k, piece in enumerate(split_part):
            if piece is not None:
                ranges[k].append(piece)
        _return_free_memory()

    # the empty part of a skeleton built for no source yet holds no row to split
    parts[:] = [part for part in reversed(parts) if len(part)]
    if len(parts) == 1:
        keep(split(parts.pop()))
    else:
        # a part per thread is split at once (numpy's sorts and takes release the GIL), kept in the parts' order
        with ThreadPoolExecutor(WORKERS) as pool:
            splitting: deque = deque()
            while parts or splitting:
                while parts and len(splitting) < WORKERS:
                    splitting.append(pool.submit(split, parts.pop()))
                keep(splitting.popleft().result())
    for pieces in ranges:
        yield _concatenated(IncidenceChunk, pieces)


def _narrowest_int(limit: int):
    """The smallest signed integer dtype, int16 or int32, holding every value in [-3, limit): the generator
    codes and face groups of the incidences held until the end of a build, widened to int32 again a piece at a
    time for the assembly. Held as int32 they would set the build's peak memory: office-1488's 7.0 million
    incidences took 228 MB of the 351 MB of node and incidence parts held when validation ended."""
    return np.int16 if limit <= np.iinfo(np.int16).max else np.int32


def _key_prefix(part, n_codes: int) -> np.ndarray:
    """(M,) int64 the leading part of each incidence's arc key: kind, then its first generator."""
    return part.kind.astype(np.int64) * n_codes + part.codes[:, 0]


def _one_node_per_line(columns: dict, node_line: np.ndarray) -> tuple[NodeChunk, np.ndarray]:
    """The nodes standing for their line (node_line (N,): see Skeleton) among all nodes (columns: the fields
    of their NodeChunk, emptied column by column: two copies of all at once would set the peak memory of a
    build), and (N,) int32 the id among them of each node's line."""
    kept = node_line == np.arange(len(node_line))
    line_id = np.cumsum(kept, dtype=np.int32) - 1
    selected = {}
    for name in list(columns):
        selected[name] = columns.pop(name)[kept]
        _return_free_memory()
    return NodeChunk(**selected), line_id[node_line]


def _merged_within(scene: Scene, nodes: NodeChunk, incidences: IncidenceChunk, edge_tol: np.ndarray):
    """(NodeChunk, IncidenceChunk): one validated chunk with one node per line among its nodes (see
    _one_node_per_line) and the incidences moved onto those, leaving out an incidence that repeats one of its
    node's (same arc, same direction, coordinates within edge_tol (E,) on the parameter edge, as
    core.skeleton.graph.assemble_arcs would). A quarter of an office's nodes repeat a line of their own chunk:
    held to the build's end, they and their incidences would set its peak memory."""
    node_line = coincident_nodes(nodes.start, nodes.direction, scene.diagonal, scene.tol.length)
    nodes, node_id = _one_node_per_line(dict(vars(nodes)), node_line)
    node = node_id[incidences.node]
    codes = incidences.codes
    kept = _not_repeated(node, len(nodes), incidences.kind, codes, incidences.direction, incidences.s, edge_tol,
                         scene.n_vertices)  # fmt: skip
    return nodes, IncidenceChunk(
        node[kept].astype(np.int32), incidences.kind[kept], codes[kept], incidences.end[kept], incidences.s[kept],
        incidences.direction[kept],
    )


@njit(cache=True)
def _not_repeated(node, n_nodes, kind, codes, direction, s, edge_tol, n_vertices):
    """(M,) bool: the incidences (node (M,) int32 ids below n_nodes, kind (M,) int8, codes (M, 3), direction (M,)
    int8, s (M,) float64) that do not repeat one of their node's. Sorted by node, kind, codes, direction, then
    s (ties in index order, NaN last: np.lexsort's order), an incidence repeats the one before it when all but
    s agree and s is within edge_tol (E,) of it on their parameter edge (the lowest edge code - n_vertices).
    The incidences of one node, a handful, are sorted by insertion; a node of many (a line met by many merged
    nodes) by stable sorts of its rows, one per key from the last."""
    m = len(node)
    first = np.zeros(n_nodes + 1, dtype=np.int64)
    for i in range(m):
        first[node[i] + 1] += 1
    for k in range(n_nodes):
        first[k + 1] += first[k]
    order = np.empty(m, dtype=np.int64)
    filled = first[:-1].copy()
    for i in range(m):
        order[filled[node[i]]] = i
        filled[node[i]] += 1
    kept = np.ones(m, dtype=np.bool_)
    for k in range(n_nodes):
        lo = first[k]
        hi = first[k + 1]
        if hi - lo > _INSERTION_RUN:
            rows = order[lo:hi]
            rows = rows[np.argsort(s[rows], kind="mergesort")]
            rows = rows[np.argsort(direction[rows], kind="mergesort")]
            for column in range(2, -1, -1):
                rows = rows[np.argsort(codes[rows, column], kind="mergesort")]
            order[lo:hi] = rows[np.argsort(kind[rows], kind="mergesort")]
        else:
            for p in range(lo + 1, hi):
                moving = order[p]
                q = p
                while q > lo and _incidence_before(moving, order[q - 1], kind, codes, direction, s):
                    order[q] = order[q - 1]
                    q -= 1
                order[q] = moving
        for p in range(lo + 1, hi):
            a = order[p - 1]
            b = order[p]
            if kind[a] != kind[b] or direction[a] != direction[b]:
                continue
            if codes[a, 0] != codes[b, 0] or codes[a, 1] != codes[b, 1] or codes[a, 2] != codes[b, 2]:
                continue
            edge = len(edge_tol)
            for c in range(3):
                if codes[b, c] >= n_vertices:
                    edge = min(edge, codes[b, c] - n_vertices)
            if edge < len(edge_tol) and s[b] - s[a] <= edge_tol[edge]:
                kept[b] = False
    return kept


@njit(cache=True)
def _incidence_before(a, b, kind, codes, direction, s):
    """Whether incidence a sorts strictly before b by kind, codes, direction, then s (NaN last)."""
    if kind[a] != kind[b]:
        return kind[a] < kind[b]
    for c in range(3):
        if codes[a, c] != codes[b, c]:
            return codes[a, c] < codes[b, c]
    if direction[a] != direction[b]:
        return direction[a] < direction[b]
    return _before(s[a], s[b])


@njit(cache=True)
def _probed_pieces(kind, node, ends, cut_offsets):
    """(A+1,) int32 offsets of the probed pieces of each arc (see Skeleton._probe_arcs): the EV arcs with both
    nodes whose lines end in a face's plane or leave the scene (ends (A, 2, 2), at either node), or with cuts
    (cut_offsets (A+1,) int32, see _arc_cuts), have one piece more than cuts; the others none."""
    offsets = np.zeros(kind.shape[0] + 1, dtype=np.int32)
    for arc in range(kind.shape[0]):
        cuts = cut_offsets[arc + 1] - cut_offsets[arc]
        probed = cuts > 0
        for at in range(2):
            if ends[arc, at, 1] == END_PLANAR or ends[arc, at, 1] == END_FREE:
                probed = True
        wanted = kind[arc] == ARC_EV and node[arc, 0] >= 0 and node[arc, 1] >= 0 and probed
        offsets[arc + 1] = offsets[arc] + (cuts + 1 if wanted else 0)
    return offsets


@njit(cache=True)
def _piece_bounds(offsets, cut_offsets, cut_s, cut_node, arc_s, arc_node):
    """(K, 2) float64 and (K, 2) int32: where each probed piece (offsets (A+1,) int32, see _probed_pieces)
    starts and ends on its arc's edge, and the nodes there: the arc's start or a cut, then the next cut or
    the arc's end (cuts: cut_offsets (A+1,) into cut_s, cut_node, see _arc_cuts; the arcs' s, node (A, 2))."""
    piece_s = np.empty((offsets[-1], 2))
    piece_node = np.empty((offsets[-1], 2), dtype=np.int32)
    for arc in range(offsets.shape[0] - 1):
        pieces = offsets[arc + 1] - offsets[arc]
        for within in range(pieces):
            piece = offsets[arc] + within
            cut = cut_offsets[arc] + within
            if within > 0:
                piece_s[piece, 0] = cut_s[cut - 1]
                piece_node[piece, 0] = cut_node[cut - 1]
            else:
                piece_s[piece, 0] = arc_s[arc, 0]
                piece_node[piece, 0] = arc_node[arc, 0]
            if within < pieces - 1:
                piece_s[piece, 1] = cut_s[cut]
                piece_node[piece, 1] = cut_node[cut]
            else:
                piece_s[piece, 1] = arc_s[arc, 1]
                piece_node[piece, 1] = arc_node[arc, 1]
    return piece_s, piece_node


@njit(cache=True, nogil=True)
def _probe_directions(vertex, edge, piece_s, vertices, edges, shift):
    """(K, 3) float64: from each piece's vertex (K,) int64 to the middle of its piece of edge (K,) int64
    (piece_s (K, 2)), moved off the swath by `shift` (a length, signed: + the side cross(b - a, apex - a))."""
    directions = np.empty((vertex.shape[0], 3))
    along = np.empty(3)
    to_apex = np.empty(3)
    swath = np.empty(3)
    for k in range(vertex.shape[0]):
        middle = 0.5 * (piece_s[k, 0] + piece_s[k, 1])
        a, b, apex = edges[edge[k], 0], edges[edge[k], 1], vertex[k]
        for j in range(3):
            along[j] = vertices[b, j] - vertices[a, j]
            to_apex[j] = vertices[apex, j] - vertices[a, j]
        for j in range(3):
            swath[j] = along[(j + 1) % 3] * to_apex[(j + 2) % 3] - along[(j + 2) % 3] * to_apex[(j + 1) % 3]
        scale = shift / np.sqrt(swath[0] ** 2 + swath[1] ** 2 + swath[2] ** 2)
        for j in range(3):
            directions[k, j] = vertices[a, j] + middle * along[j] + scale * swath[j] - vertices[apex, j]
    return directions


@njit(cache=True)
def _arc_of_pieces(offsets):
    """(K,) int32 the arc of each piece, from the offsets (A+1,) int32 of each arc's pieces."""
    arc = np.empty(offsets[-1], dtype=np.int32)
    for a in range(offsets.shape[0] - 1):
        arc[offsets[a] : offsets[a + 1]] = a
    return arc


def _slices(cumulative: np.ndarray, parts: int) -> list[tuple[int, int]]:
    """`parts` consecutive slices (lo, hi) of range(n) with about as much work each; cumulative (n + 1,): the
    work before each index."""
    n = len(cumulative) - 1
    cuts = np.searchsorted(cumulative, np.linspace(0, cumulative[-1], max(1, parts) + 1)[1:-1])
    bounds = [0, *np.minimum(cuts, n).tolist(), n]
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def _even_slices(n: int, parts: int) -> list[tuple[int, int]]:
    """`parts` consecutive slices (lo, hi) of range(n) of about one length."""
    bounds = np.linspace(0, n, max(1, parts) + 1).astype(np.int64).tolist()
    return list(zip(bounds[:-1], bounds[1:], strict=True))


def _on_threads(run: Callable, slices: list[tuple[int, int]], workers: int | None = None) -> list:
    """[run(lo, hi) for each slice], on `workers` threads at once (None: one per slice), each taking the next
    slice when done with one: `run` calls kernels that release the GIL."""
    workers = len(slices) if workers is None else min(max(1, workers), len(slices))
    # a thread's start costs more than an empty slice: a skeleton built for no source yet has only those
    if workers == 1 or sum(hi > lo for lo, hi in slices) <= 1:
        return [run(*bound) for bound in slices]
    with ThreadPoolExecutor(workers) as pool:
        return list(pool.map(lambda bound: run(*bound), slices))


def _element_faces(scene: Scene, topology, code: int) -> np.ndarray:
    nv = scene.n_vertices
    if code < nv:
        return topology.vertex_faces[topology.vertex_face_offsets[code] : topology.vertex_face_offsets[code + 1]]
    edge = code - nv
    return scene.edge_faces[scene.edge_face_offsets[edge] : scene.edge_face_offsets[edge + 1]]


@njit(cache=True)
def _arc_lines(kind, codes, arcs, s, vertices, edges, n_vertices):
    """(K, 3) points and (K, 3) directions of the lines of `arcs` (K,) int64 (kind, codes: of Arcs) at their
    parameters s (K,) float64 (see _arc_line_at)."""
    origin = np.empty((arcs.shape[0], 3))
    direction = np.empty((arcs.shape[0], 3))
    for k in range(arcs.shape[0]):
        point, along = _arc_line_at(kind[arcs[k]], codes[arcs[k]], s[k], vertices, edges, n_vertices)
        for i in range(3):
            origin[k, i] = point[i]
            direction[k, i] = along[i]
    return origin, direction


def _line_meets_polygon(scene: Scene, polygon: int, origin: np.ndarray, direction: np.ndarray) -> np.ndarray:
    """(K,) float64 the parameter t where each line origin + t direction ((K, 3) each) meets convex `polygon`
    (its sides included, within the tolerance length), NaN where it does not or runs along its plane."""
    normal, offset = scene.normals[polygon], scene.plane_offsets[polygon]
    rate = direction @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = -(origin @ normal + offset) / rate
        t[np.abs(rate) <= scene.tol.cosine * np.linalg.norm(direction, axis=1)] = np.nan
    point = origin + t[:, None] * direction
    corners = scene.polygon(polygon)
    for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
        side = np.cross(b - a, point - a) @ normal / np.linalg.norm(b - a)
        t[~(side >= -scene.tol.length)] = np.nan
    return t


def _pair_index(kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, n_groups, workers):
    """The arcs joining each pair of surfaces (face groups), CSR: first (P,) int32 < second (P,) int32 the
    distinct pairs sorted by first then second, offsets (P + 1,) int64 into arcs (R,) int32, each pair's arcs
    in increasing order. Filled by a counting sort on the first surface, then each first surface's rows by a
    counting sort on the second, found again from the arc: the second surface of every row at once, or a sort
    on (pair, arc) rows, would hold arrays as large as the index, the largest of a build. Consecutive slices
    of the arcs, then of the surfaces, are shared among `workers` threads; the result does not depend on how
    many."""
    geometry = (kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group)
    if kind.shape[0] < _PAIRED_ON_ONE_THREAD:
        workers = 1
    arc_slices = _even_slices(kind.shape[0], workers)
    counts = _on_threads(lambda lo, hi: _pair_counts(lo, hi, *geometry, n_groups), arc_slices)
    bucket = np.zeros(n_groups + 1, dtype=np.int64)
    np.cumsum(np.sum(counts, axis=0), out=bucket[1:])
    # each slice fills the rows of every surface after those of the slices before it: arcs in increasing order
    fill = {}
    before = bucket[:-1].copy()
    for (lo, _), count in zip(arc_slices, counts, strict=True):
        fill[lo] = before.copy()
        before += count
    arcs = np.empty(bucket[-1], dtype=np.int32)
    _on_threads(lambda lo, hi: _pair_fill(lo, hi, *geometry, fill[lo], arcs), arc_slices)
    pairs = _on_threads(lambda lo, hi: _sort_pairs(lo, hi, *geometry, bucket, arcs, n_groups),
                        _slices(bucket, workers))  # fmt: skip
    first = np.concatenate([found[0] for found in pairs])
    second = np.concatenate([found[1] for found in pairs])
    offsets = np.concatenate([*(found[2] for found in pairs), [len(arcs)]])
    return first, second, offsets, arcs


@njit(cache=True)
def _vertex_index(kind, codes, n_vertices):
    """The EV arcs of each vertex, CSR: arcs (E,) int32 in increasing order within each vertex, offsets (V + 1,)
    int64; an EV arc's vertex is its first code. A counting sort: an argsort of the EV arcs' vertices would hold
    int64 arrays of every EV arc beside the result (~70 MB at office-1488)."""
    offsets = np.zeros(n_vertices + 1, dtype=np.int64)
    for arc in range(kind.shape[0]):
        if kind[arc] == ARC_EV:
            offsets[codes[arc, 0] + 1] += 1
    for vertex in range(n_vertices):
        offsets[vertex + 1] += offsets[vertex]
    fill = offsets[:-1].copy()
    arcs = np.empty(offsets[n_vertices], dtype=np.int32)
    for arc in range(kind.shape[0]):
        if kind[arc] == ARC_EV:
            vertex = codes[arc, 0]
            arcs[fill[vertex]] = arc
            fill[vertex] += 1
    return arcs, offsets


@njit(cache=True, nogil=True)
def _pair_counts(lo, hi, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, n_groups):
    """(G,) int64: how many (pair, arc) rows the arcs lo..hi-1 give each first surface."""
    touched = np.empty((2, 64), dtype=np.int64)
    found = np.empty((2, 64 * 64), dtype=np.int64)
    count = np.zeros(n_groups, dtype=np.int64)
    for arc in range(lo, hi):
        for k in range(_arc_pairs(arc, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face,
                                  face_group, touched, found)):  # fmt: skip
            count[found[0, k]] += 1
    return count


@njit(cache=True, nogil=True)
def _pair_fill(lo, hi, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, fill, arcs):
    """Arcs lo..hi-1 into their rows, one per pair, each at its first surface's next row (fill (G,) int64): an
    arc's rows of one first surface are consecutive, in the order _arc_pairs finds its pairs."""
    touched = np.empty((2, 64), dtype=np.int64)
    found = np.empty((2, 64 * 64), dtype=np.int64)
    for arc in range(lo, hi):
        for k in range(_arc_pairs(arc, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face,
                                  face_group, touched, found)):  # fmt: skip
            arcs[fill[found[0, k]]] = arc
            fill[found[0, k]] += 1


@njit(cache=True, nogil=True)
def _sort_pairs(lo, hi, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, bucket, arcs,
                n_groups):  # fmt: skip
    """Sort the rows of first surfaces lo..hi-1 (bucket (G+1,) int64: their first rows) by second surface,
    stably (each pair's arcs stay in increasing order), by counting over the second surfaces each first one
    meets; returns the distinct pairs among them: first, second (K,) int32 and their first rows (K,) int64."""
    touched = np.empty((2, 64), dtype=np.int64)
    found = np.empty((2, 64 * 64), dtype=np.int64)
    row_of = np.zeros(n_groups, dtype=np.int64)
    seen = np.empty(n_groups, dtype=np.int32)
    longest = 0
    for group in range(lo, hi):
        longest = max(longest, bucket[group + 1] - bucket[group])
    row_second = np.empty(longest, dtype=np.int32)
    moved_arcs = np.empty(longest, dtype=np.int32)
    pair_first = np.empty(16, dtype=np.int32)
    pair_second = np.empty(16, dtype=np.int32)
    pair_row = np.empty(16, dtype=np.int64)
    n_pairs = 0
    for group in range(lo, hi):
        first_row, end_row = bucket[group], bucket[group + 1]
        n_seen = 0
        n_found = 0
        next_found = 0
        for row in range(first_row, end_row):
            if row == first_row or arcs[row] != arcs[row - 1]:
                n_found = _arc_pairs(arcs[row], kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face,
                                     face_group, touched, found)  # fmt: skip
                next_found = 0
            while next_found < n_found - 1 and found[0, next_found] != group:
                next_found += 1
            second = found[1, next_found]
            next_found += 1
            row_second[row - first_row] = second
            if row_of[second] == 0:
                seen[n_seen] = second
                n_seen += 1
            row_of[second] += 1
        seen[:n_seen].sort()
        if n_pairs + n_seen > pair_first.shape[0]:
            size = max(2 * pair_first.shape[0], n_pairs + n_seen)
            pair_first = _resized(pair_first, size)
            pair_second = _resized(pair_second, size)
            pair_row = _resized(pair_row, size)
        # each second surface's first row among the group's: one pair each
        start = 0
        for k in range(n_seen):
            rows = row_of[seen[k]]
            row_of[seen[k]] = start
            pair_first[n_pairs] = group
            pair_second[n_pairs] = seen[k]
            pair_row[n_pairs] = first_row + start
            n_pairs += 1
            start += rows
        for row in range(first_row, end_row):
            second = row_second[row - first_row]
            target = row_of[second]
            moved_arcs[target] = arcs[row]
            row_of[second] = target + 1
        arcs[first_row:end_row] = moved_arcs[: end_row - first_row]
        for k in range(n_seen):
            row_of[seen[k]] = 0
    return pair_first[:n_pairs].copy(), pair_second[:n_pairs].copy(), pair_row[:n_pairs].copy()


@njit(cache=True)
def _resized(values, size):
    """values (K,) copied into a new array of `size` >= K rows."""
    out = np.empty(size, dtype=values.dtype)
    out[: values.shape[0]] = values
    return out


@njit_leaf
def _arc_pairs(arc, kind, codes, ends, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, touched, found):
    """The (surface, surface) pairs arc `arc` joins, each once as (lower, higher), into found (2, K); returns
    K. The surfaces touched at each end are the ones its lines end on (as found at either node, ends (A, 2,
    2)) and those around its outer generator (the lines graze it or stop on it); a pair needs a surface the
    lines end on at one end at least: lines grazing both surfaces at their generators run on past both and
    join neither (a lamp's corner and the edge of the floor along a wall: the wall is no blocker between the
    lamp and the floor). touched (2, 64) scratch."""
    last = 1 if kind[arc] == ARC_EV else 2
    sizes = (
        _touched(codes[arc, 0], ends[arc, 0, 0], ends[arc, 1, 0], n_vertices, vf_off, vf_face, ef_off, ef_face,
                 face_group, touched[0]),
        _touched(codes[arc, last], ends[arc, 0, 1], ends[arc, 1, 1], n_vertices, vf_off, vf_face, ef_off, ef_face,
                 face_group, touched[1]),
    )  # fmt: skip
    n = 0
    for i in range(sizes[0][0]):
        for j in range(sizes[1][0]):
            if i >= sizes[0][1] and j >= sizes[1][1]:
                continue
            a = min(touched[0, i], touched[1, j])
            b = max(touched[0, i], touched[1, j])
            if a == b:
                continue
            seen = False
            for k in range(n):
                if found[0, k] == a and found[1, k] == b:
                    seen = True
                    break
            if not seen:
                found[0, n] = a
                found[1, n] = b
                n += 1
    return n


@njit_leaf
def _touched(code, end_at_start, end_at_end, n_vertices, vf_off, vf_face, ef_off, ef_face, face_group, out):
    """The surfaces an arc's lines touch beyond generator `code`, into out: first those they end on, then those
    around the generator; returns (how many, how many they end on)."""
    count = 0
    for end in (end_at_start, end_at_end):
        if end >= 0:
            count = _add_unique(out, count, end)
    ending = count
    if code < n_vertices:
        for i in range(vf_off[code], vf_off[code + 1]):
            count = _add_unique(out, count, face_group[vf_face[i]])
    else:
        for i in range(ef_off[code - n_vertices], ef_off[code - n_vertices + 1]):
            count = _add_unique(out, count, face_group[ef_face[i]])
    return count, ending


@njit_leaf
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


#: most points of an EEE trace
_TRACE_SAMPLES = 4096


@njit_leaf
def _arc_line_at(kind, codes, s, vertices, edges, n_vertices):
    """A point and a direction (3-tuples) of the line of an arc (kind, codes (3,) of Arcs) at parameter s on
    its lowest edge: from the vertex for EV, the meet of the planes through the point and each other edge
    for EEE."""
    param = -1
    for c in codes:
        if c >= n_vertices and (param < 0 or c - n_vertices < param):
            param = c - n_vertices
    a = edges[param, 0]
    b = edges[param, 1]
    point = (
        vertices[a, 0] + s * (vertices[b, 0] - vertices[a, 0]),
        vertices[a, 1] + s * (vertices[b, 1] - vertices[a, 1]),
        vertices[a, 2] + s * (vertices[b, 2] - vertices[a, 2]),
    )
    if kind == ARC_EV:
        v = codes[0] if codes[0] < n_vertices else codes[1]
        apex = (vertices[v, 0], vertices[v, 1], vertices[v, 2])
        return apex, (point[0] - apex[0], point[1] - apex[1], point[2] - apex[2])
    first = (0.0, 0.0, 0.0)
    second = (0.0, 0.0, 0.0)
    found = 0
    for c in codes:
        if c < 0 or c == param + n_vertices:
            continue
        p = edges[c - n_vertices, 0]
        q = edges[c - n_vertices, 1]
        to_p = (vertices[p, 0] - point[0], vertices[p, 1] - point[1], vertices[p, 2] - point[2])
        to_q = (vertices[q, 0] - point[0], vertices[q, 1] - point[1], vertices[q, 2] - point[2])
        plane = _cross3(to_p, to_q)
        if found == 0:
            first = plane
        else:
            second = plane
        found += 1
    return point, _cross3(first, second)


@njit_leaf
def _cross3(a, b):
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


@njit_leaf
def _plane_hit(kind, codes, s, vertices, edges, n_vertices, normal, offset, lo, hi, cosine):
    """(hit, point 3-tuple): where the arc's line at s meets the plane normal . x + offset = 0, hit False when
    the line is parallel to it (within cosine) or meets it outside the box lo, hi (3,)."""
    point, direction = _arc_line_at(kind, codes, s, vertices, edges, n_vertices)
    rate = normal[0] * direction[0] + normal[1] * direction[1] + normal[2] * direction[2]
    length = np.sqrt(direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2])
    if abs(rate) <= cosine * length:
        return False, point
    step = (normal[0] * point[0] + normal[1] * point[1] + normal[2] * point[2] + offset) / rate
    x = (point[0] - step * direction[0], point[1] - step * direction[1], point[2] - step * direction[2])
    for c in range(3):
        if not lo[c] <= x[c] <= hi[c]:
            return False, x
    return True, x


@njit_leaf
def _last_hit(kind, codes, inside, outside, vertices, edges, n_vertices, normal, offset, lo, hi, cosine):
    """The parameter nearest `outside` on the way from `inside` (whose line hits the plane) whose line still
    hits: `outside` itself when it does, else found by bisection (64 halvings reach float64 resolution)."""
    if _plane_hit(kind, codes, outside, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)[0]:
        return outside
    for _ in range(64):
        middle = 0.5 * (inside + outside)
        if middle == inside or middle == outside:
            break
        if _plane_hit(kind, codes, middle, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)[0]:
            inside = middle
        else:
            outside = middle
    return inside


@njit(cache=True)
def _traced(kind, codes, s0, s1, vertices, edges, n_vertices, normal, offset, lo, hi, cosine, curve):
    """Skeleton._trace of the arc (kind, codes (3,), parameter range s0, s1): (k, 2, 3) float64."""
    middle = 0.5 * (s0 + s1)
    if not _plane_hit(kind, codes, middle, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)[0]:
        return np.empty((0, 2, 3))
    s0 = _last_hit(kind, codes, middle, s0, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)
    s1 = _last_hit(kind, codes, middle, s1, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)
    capacity = 2 if kind == ARC_EV else _TRACE_SAMPLES
    params = np.empty(capacity)
    points = np.empty((capacity, 3))
    for k, s in enumerate((s0, s1)):
        params[k] = s
        x = _plane_hit(kind, codes, s, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)[1]
        for c in range(3):
            points[k, c] = x[c]
    count = 2
    i = 0
    # each piece is halved until its middle lies within `curve` of its chord, left pieces first
    while kind != ARC_EV and i < count - 1 and count < capacity:
        sm = 0.5 * (params[i] + params[i + 1])
        pm = _plane_hit(kind, codes, sm, vertices, edges, n_vertices, normal, offset, lo, hi, cosine)[1]
        chord = (points[i + 1, 0] - points[i, 0], points[i + 1, 1] - points[i, 1], points[i + 1, 2] - points[i, 2])
        length2 = chord[0] * chord[0] + chord[1] * chord[1] + chord[2] * chord[2]
        t = 0.0
        if length2 != 0.0:
            t = ((pm[0] - points[i, 0]) * chord[0] + (pm[1] - points[i, 1]) * chord[1]
                 + (pm[2] - points[i, 2]) * chord[2]) / length2  # fmt: skip
            t = min(max(t, 0.0), 1.0)
        gap = 0.0
        for c in range(3):
            gap += (points[i, c] + t * chord[c] - pm[c]) ** 2
        if np.sqrt(gap) > curve:
            params[i + 2 : count + 1] = params[i + 1 : count].copy()
            points[i + 2 : count + 1] = points[i + 1 : count].copy()
            params[i + 1] = sm
            for c in range(3):
                points[i + 1, c] = pm[c]
            count += 1
        else:
            i += 1
    segments = np.empty((count - 1, 2, 3))
    segments[:, 0] = points[: count - 1]
    segments[:, 1] = points[1:count]
    return segments


def _onto_plane(apex: np.ndarray, through: np.ndarray, normal: np.ndarray, offset: float) -> np.ndarray:
    """Where the line from apex through `through` meets the plane normal . x + offset = 0."""
    direction = through - apex
    return apex - (normal @ apex + offset) / (normal @ direction) * direction


def _inward(scene: Scene, face: int, edge: int) -> np.ndarray:
    """(3,) direction across `edge` into polygon `face` (in its plane, perpendicular to the edge)."""
    a, b = scene.vertices[scene.edges[edge]]
    along = b - a if _edge_runs_forward(scene, face, edge) else a - b
    return np.cross(scene.normals[face], along)


def _seen_side(scene: Scene, topology, faces: list[tuple[int, int]], edge: int, group: int, apex,
               end_after: int) -> int:
    """Which side of the swath (apex, edge) sees the source's face group: +1 the side its normal
    cross(b - a, apex - a) points to, -1 the other, 0 when the swath bounds nothing of the source's view.
    faces: the (face, its edge) pairs around the swath's points of the edge (Skeleton._faces_along).

    An edge of the source bounds its view where the lines just inside the source pass the edge's other faces:
    in the section across the edge, a face pointing between the apex and the source hides it, and so does a
    face running from the edge to the apex with the source behind it. A blocker edge
    whose lines end on the source hides it on the side of its faces; faces whose plane holds the apex (the
    face a horizon line slides over) are seen edge-on and tell nothing, and with only such faces (a lone
    panel seen from its own corner) both sides see the source."""
    a, b = scene.vertices[scene.edges[edge]]
    along = b - a
    to_apex = apex - a
    swath = np.cross(along, to_apex)
    own = [(face, at) for face, at in faces if topology.face_group[face] == group]
    tol = scene.tol.length
    if own:
        into_source = _inward(scene, *own[0])
        turn = np.sign(np.cross(to_apex, into_source) @ along)
        for face, at in faces:
            if topology.face_group[face] == group:
                continue
            into_face = _inward(scene, face, at)
            if abs(scene.normals[face] @ to_apex) <= tol:
                # the apex lies on this face's plane: the lines just inside the source leave it across the
                # face, into the solid when the source is behind the face (a convex edge of a solid)
                if into_face @ to_apex > 0.0 and scene.normals[face] @ into_source < 0.0:
                    return 0
                continue
            if (np.sign(np.cross(to_apex, into_face) @ along) == turn
                    and np.sign(np.cross(into_face, into_source) @ along) == turn):
                return 0
        return int(np.sign(swath @ into_source))
    if end_after != group:
        return 0
    best = 0.0
    side = 0
    for face, at in faces:
        if abs(scene.normals[face] @ to_apex) <= tol:
            continue
        lean = swath @ _inward(scene, face, at)
        if abs(lean) > best:
            best = abs(lean)
            side = -int(np.sign(lean))
    return side


def _seen_on_left(apex, a, b, s: float, normal, offset: float, side: int) -> bool:
    """Whether the trace of the swath (apex, edge a-b) on the plane normal . x + offset = 0, walked towards
    larger s, has the seen side (`side`, see _seen_side) on its left, looking from the apex. The walking
    direction is the derivative of the central projection at s, so an arc of zero length is oriented too."""
    x = a + s * (b - a)
    rise = normal @ (x - apex)
    height = normal @ apex + offset
    velocity = -height / rise * (b - a) + height * (normal @ (b - a)) / (rise * rise) * (x - apex)
    facing = normal if height > 0.0 else -normal
    swath = np.cross(b - a, apex - a)
    return bool(np.sign(swath @ np.cross(facing, velocity)) == side)


def _edge_runs_forward(scene: Scene, face: int, edge: int) -> bool:
    """Whether polygon `face` runs along `edge` from its first vertex to its second (counter-clockwise)."""
    ids = scene.polygon_vertices(face)
    first, second = scene.edges[edge]
    k = int(np.flatnonzero(ids == first)[0])
    return ids[(k + 1) % len(ids)] == second


@njit(cache=True)
def _resting_on(vertices, points, offsets, normals, plane_offsets, object_ids, vf_off, vf_face, tol):
    """CSR (offsets (V+1,) int64, faces int64): for each vertex, the polygons of other objects it lies inside
    (strictly, by more than tol from their sides): a box corner resting on a table top, a leg's top corner
    under it. Lines from the vertex into such a polygon's back side enter that object's solid at once."""
    n_vertices = vertices.shape[0]
    n_polygons = normals.shape[0]
    lo = np.empty((n_polygons, 3))
    hi = np.empty((n_polygons, 3))
    for p in range(n_polygons):
        for k in range(3):
            lo[p, k] = points[offsets[p] : offsets[p + 1], k].min() - tol
            hi[p, k] = points[offsets[p] : offsets[p + 1], k].max() + tol
    counts = np.zeros(n_vertices + 1, dtype=np.int64)
    pairs = []
    for v in range(n_vertices):
        x = vertices[v]
        own = -1 if vf_off[v] == vf_off[v + 1] else object_ids[vf_face[vf_off[v]]]
        for p in range(n_polygons):
            if object_ids[p] == own:
                continue
            if (x[0] < lo[p, 0] or x[1] < lo[p, 1] or x[2] < lo[p, 2] or x[0] > hi[p, 0] or x[1] > hi[p, 1]
                    or x[2] > hi[p, 2]):
                continue
            n = normals[p]
            if abs(n[0] * x[0] + n[1] * x[1] + n[2] * x[2] + plane_offsets[p]) > tol:
                continue
            first = offsets[p]
            count = offsets[p + 1] - first
            inside = True
            for k in range(count):
                a = points[first + k]
                side = np.cross(n, points[first + (k + 1) % count] - a)
                if (x - a) @ side <= tol * np.sqrt(side @ side):
                    inside = False
                    break
            if inside:
                pairs.append((v, p))
                counts[v + 1] += 1
    found = np.empty(len(pairs), dtype=np.int64)
    for i in range(len(pairs)):
        found[i] = pairs[i][1]
    return np.cumsum(counts), found


@njit(cache=True)
def _elements_at(vertices, edges, ef_off, ef_face, object_ids, vf_off, vf_face, tol):
    """CSR (offsets (V+1,) int64, element codes int64: vertex w as w, edge e as V + e): for each vertex, the
    vertices of other objects at its point (within tol: a box in the room's corner) and the edges of other
    objects passing through it (within tol of the edge's line, more than tol from its ends: a box's corner on
    the edge of the box beside it or under it). Lines from the vertex into the solid around such an element
    enter the other object."""
    n_vertices = vertices.shape[0]
    # each element looks at the vertices within its extent along x only
    by_x = np.argsort(vertices[:, 0])
    xs = vertices[by_x, 0]
    counts = np.zeros(n_vertices + 1, dtype=np.int64)
    at_vertex = []
    element = []
    for w in range(n_vertices):
        if vf_off[w] == vf_off[w + 1]:
            continue
        owner = object_ids[vf_face[vf_off[w]]]
        lo = np.searchsorted(xs, vertices[w, 0] - tol, side="left")
        hi = np.searchsorted(xs, vertices[w, 0] + tol, side="right")
        for k in range(lo, hi):
            v = by_x[k]
            if vf_off[v] == vf_off[v + 1] or object_ids[vf_face[vf_off[v]]] == owner:
                continue
            offset = vertices[v] - vertices[w]
            if offset @ offset <= tol * tol:
                at_vertex.append(v)
                element.append(w)
                counts[v + 1] += 1
    for e in range(edges.shape[0]):
        a = vertices[edges[e, 0]]
        b = vertices[edges[e, 1]]
        along = b - a
        length = np.sqrt(along @ along)
        along = along / length
        owner = object_ids[ef_face[ef_off[e]]]
        lo = np.searchsorted(xs, min(a[0], b[0]) - tol, side="left")
        hi = np.searchsorted(xs, max(a[0], b[0]) + tol, side="right")
        for k in range(lo, hi):
            v = by_x[k]
            if vf_off[v] == vf_off[v + 1] or object_ids[vf_face[vf_off[v]]] == owner:
                continue
            offset = vertices[v] - a
            t = offset @ along
            if t <= tol or t >= length - tol:
                continue
            aside = offset - t * along
            if aside @ aside <= tol * tol:
                at_vertex.append(v)
                element.append(n_vertices + e)
                counts[v + 1] += 1
    order = np.argsort(np.array(at_vertex, dtype=np.int64), kind="mergesort")
    return np.cumsum(counts), np.array(element, dtype=np.int64)[order]


def _arcs_leave_freely(kind, codes, s, dangling, n_vertices, vertices, edges, points, offsets, normals,
                       vf_off, vf_face, vf_corner, rest_off, rest_face, other_off, other_code, ef_off, ef_face,
                       ef_local, cosine, workers):
    """(A,) bool: whether the lines of each EV arc leave its vertex towards its edge into free space, not into
    the solid the vertex bounds (interior swaths, seed 003 section 3.1; see _leaves_freely). Constant along an
    arc: the winding changes only where the line slides over a face of the vertex, which ends the arc at a
    node. The arcs are shared among `workers` threads; the result does not depend on how many."""
    result = np.ones(kind.shape[0], dtype=np.bool_)

    def run(lo, hi):
        _arcs_leave_freely_slice(
            lo, hi, kind, codes, s, dangling, n_vertices, vertices, edges, points, offsets, normals, vf_off,
            vf_face, vf_corner, rest_off, rest_face, other_off, other_code, ef_off, ef_face, ef_local, cosine,
            result,
        )  # fmt: skip

    # the EV arcs, the costly ones, come first (arcs are sorted by kind): small slices even the threads out
    _on_threads(run, _even_slices(kind.shape[0], _SLICES_PER_WORKER * workers), workers)
    return result


#: slices per thread where the work per slice is not known in advance
_SLICES_PER_WORKER = 8


@njit(cache=True, nogil=True)
def _arcs_leave_freely_slice(lo, hi, kind, codes, s, dangling, n_vertices, vertices, edges, points, offsets,
                             normals, vf_off, vf_face, vf_corner, rest_off, rest_face, other_off, other_code, ef_off,
                             ef_face, ef_local, cosine, result):
    """_arcs_leave_freely of arcs lo..hi-1, into result (A,) bool (left as it is for the other arcs)."""
    elements, angles = _free_scratch()
    direction = np.empty(3)
    for arc in range(lo, hi):
        if kind[arc] != ARC_EV or dangling[arc]:
            continue
        v = codes[arc, 0]
        e = codes[arc, 1] - n_vertices
        t = 0.5 * (s[arc, 0] + s[arc, 1])
        a = edges[e, 0]
        b = edges[e, 1]
        for c in range(3):
            direction[c] = vertices[a, c] + t * (vertices[b, c] - vertices[a, c]) - vertices[v, c]
        result[arc] = _leaves_freely(
            v, direction, points, offsets, normals, vf_off, vf_face, vf_corner, rest_off, rest_face, other_off,
            other_code, ef_off, ef_face, ef_local, cosine, elements, angles,
        )  # fmt: skip


@njit(cache=True, nogil=True)
def _lines_leave_freely(vertex, directions, points, offsets, normals, vf_off, vf_face, vf_corner, rest_off,
                        rest_face, other_off, other_code, ef_off, ef_face, ef_local, cosine):
    """(N,) bool: _leaves_freely for each line leaving vertex[i] (N,) int64 along directions[i] (N, 3)."""
    result = np.empty(vertex.shape[0], dtype=np.bool_)
    elements, angles = _free_scratch()
    for i in range(vertex.shape[0]):
        result[i] = _leaves_freely(
            vertex[i], directions[i], points, offsets, normals, vf_off, vf_face, vf_corner, rest_off, rest_face,
            other_off, other_code, ef_off, ef_face, ef_local, cosine, elements, angles,
        )  # fmt: skip
    return result


def _arc_cuts(kind, codes, s, node, n_vertices, vertices, edges, node_start, node_direction, vertex_offsets,
              vertex_arcs, tol, cosine, workers, index_from=None):
    """The nodes lying inside each EV arc, CSR: offsets (A+1,) int32, then s (C,) float64 increasing within an
    arc and node (C,) int32: the nodes at the ends of the vertex's arcs whose line (node_start, unit
    node_direction (N, 3)) passes through the vertex (within tol) and meets the arc's edge strictly inside
    its range (by more than tol). None in a generic scene: there every node through the vertex on the swath
    bounds the arc. In a degenerate one a corner of another object lying in the plane the lines slide in (a
    box overhanging the one the vertex is on) changes what the lines meet there without ending the arc.

    The vertices are shared among `workers` threads in slices of about as many arcs each; the result does
    not depend on how many. A vertex with index_from nodes or more (None: _CUT_INDEX_MIN_NODES) indexes
    them (see _vertex_cuts); the result does not depend on it either."""
    if index_from is None:
        index_from = _CUT_INDEX_MIN_NODES
    counts = np.zeros(kind.shape[0] + 1, dtype=np.int32)

    def cuts_of(lo, hi):
        return _vertex_cuts(
            lo, hi, codes, s, node, n_vertices, vertices, edges, node_start, node_direction, vertex_offsets,
            vertex_arcs, tol, cosine, index_from, counts,
        )  # fmt: skip

    found = _on_threads(cuts_of, _slices(vertex_offsets, workers))
    offsets = np.cumsum(counts, dtype=np.int32)
    cut_s = np.empty(offsets[-1])
    cut_node = np.empty(offsets[-1], dtype=np.int32)
    # found vertex by vertex: put in arc order
    fill = offsets[:-1].copy()
    for found_arc, found_s, found_node in found:
        _place_cuts(found_arc, found_s, found_node, fill, cut_s, cut_node)
    return offsets, cut_s, cut_node


#: nodes of a vertex below which its arcs test every one of them: an index of their lines costs more
_CUT_INDEX_MIN_NODES = 32


@njit(cache=True, nogil=True)
def _vertex_cuts(lo, hi, codes, s, node, n_vertices, vertices, edges, node_start, node_direction, vertex_offsets,
                 vertex_arcs, tol, cosine, index_from, counts):
    """The cuts (see _arc_cuts) of the arcs of vertices lo..hi-1: (C,) int64 arc, (C,) float64 s, (C,) int32
    node, vertex by vertex, each arc's by increasing s; each arc's count into counts[arc + 1] (A+1,) int32.

    A node inside an arc has its line within tol of a point of the arc's edge between the arc's ends, seen
    from the vertex: its direction (or the opposite one) lies in the cone from the vertex around that
    piece of edge, widened by the angle tol subtends at the edge line's distance. The node directions of a
    vertex are put in a grid of cells over [-1, 1]^3, both ways round; each arc tests the nodes in the cells
    its cone's bounding box overlaps, and orders those it keeps by node id as testing every node would: the
    cuts found are the same."""
    found_arc = []
    found_s = []
    found_node = []
    for v in range(lo, hi):
        mine = vertex_arcs[vertex_offsets[v] : vertex_offsets[v + 1]]
        if mine.shape[0] == 0:
            continue
        px, py, pz = vertices[v, 0], vertices[v, 1], vertices[v, 2]
        ends = np.unique(node[mine].ravel())
        # the nodes whose line passes through the vertex (those at the ends of its arcs, unless merged); numbers,
        # not rows: a row view costs two atomic reference counts, a difference or cross product an allocation
        keep = np.zeros(ends.shape[0], dtype=np.bool_)
        for k in range(ends.shape[0]):
            n = ends[k]
            if n >= 0:
                ox, oy, oz = _cross3(
                    (px - node_start[n, 0], py - node_start[n, 1], pz - node_start[n, 2]),
                    (node_direction[n, 0], node_direction[n, 1], node_direction[n, 2]),
                )  # fmt: skip
                keep[k] = ox * ox + oy * oy + oz * oz <= tol * tol
        ends = ends[keep]
        n_ends = ends.shape[0]
        values = np.empty(n_ends)
        ids = np.empty(n_ends, dtype=np.int32)
        tested = np.empty(n_ends, dtype=np.int64)
        last_arc = np.full(n_ends, -1, dtype=np.int64)
        indexed = n_ends >= index_from
        # about one direction per cell of the sphere's surface (some 8 G^2 cells)
        grid = max(2, min(32, int(np.sqrt(n_ends / 4.0)))) if indexed else 1
        # the directions read by every arc of the vertex, side by side
        directions = node_direction[ends]
        cell_offsets, cell_ends = _direction_grid(directions, grid)
        apex = np.array((px, py, pz))
        a = np.empty(3)
        along = np.empty(3)
        for arc in mine:
            if node[arc, 0] < 0 or node[arc, 1] < 0:
                continue
            e = codes[arc, 1] - n_vertices
            for c in range(3):
                a[c] = vertices[edges[e, 0], c]
                along[c] = vertices[edges[e, 1], c] - a[c]
            ax, ay, az = a[0], a[1], a[2]
            lx, ly, lz = along[0], along[1], along[2]
            length = np.sqrt(lx * lx + ly * ly + lz * lz)
            nx, ny, nz = _cross3((lx, ly, lz), (ax - px, ay - py, az - pz))
            norm = np.sqrt(nx * nx + ny * ny + nz * nz)
            height = norm / length
            nx, ny, nz = nx / norm, ny / norm, nz / norm
            n_tested = n_ends
            if indexed:
                n_tested = _nodes_near_piece(
                    apex, a, along, s[arc, 0], s[arc, 1], height, tol, directions, cell_offsets, cell_ends, grid, arc,
                    last_arc, tested,
                )  # fmt: skip
            count = 0
            for t in range(n_tested):
                k = tested[t] if n_tested < n_ends else t
                n = ends[k]
                if n == node[arc, 0] or n == node[arc, 1]:
                    continue
                dx, dy, dz = directions[k, 0], directions[k, 1], directions[k, 2]
                # a line through the vertex within tol of a point of the edge leans off the swath's plane by at
                # most 2 tol over the vertex's distance to the edge
                if abs(nx * dx + ny * dy + nz * dz) * height > 2.0 * tol:
                    continue
                cx, cy, cz = _cross3((lx, ly, lz), (dx, dy, dz))
                scale = cx * cx + cy * cy + cz * cz
                if scale <= cosine * length * length:
                    continue
                wx, wy, wz = _cross3((ax - px, ay - py, az - pz), (dx, dy, dz))
                at = -(wx * cx + wy * cy + wz * cz) / scale
                if (at - s[arc, 0]) * length <= tol or (s[arc, 1] - at) * length <= tol:
                    continue
                mx, my, mz = _cross3((ax + at * lx - px, ay + at * ly - py, az + at * lz - pz), (dx, dy, dz))
                if mx * mx + my * my + mz * mz <= tol * tol:
                    values[count] = at
                    ids[count] = n
                    count += 1
            if count == 0:
                continue
            if count > 1 and n_tested < n_ends:
                # in increasing node id, the order testing every node finds them in (argsort breaks ties by it)
                by_id = np.argsort(ids[:count])
                values[:count] = values[:count][by_id]
                ids[:count] = ids[:count][by_id]
            order = np.argsort(values[:count])
            for k in order:
                found_arc.append(arc)
                found_s.append(values[k])
                found_node.append(ids[k])
            counts[arc + 1] = count
    return (np.array(found_arc, dtype=np.int64), np.array(found_s, dtype=np.float64),
            np.array(found_node, dtype=np.int32))  # fmt: skip


@njit_leaf
def _grid_cell(x, grid):
    """The cell of coordinate x in [-1, 1] among `grid` cells; monotone in x, so a range maps to a range."""
    return min(grid - 1, max(0, int(np.floor((x + 1.0) * 0.5 * grid))))


@njit(cache=True, nogil=True)
def _direction_grid(directions, grid):
    """CSR over grid^3 cells of [-1, 1]^3 (offsets (grid^3 + 1,) int64, then (2K,) int64 rows of directions):
    the cells of the unit directions (K, 3) and of their opposites."""
    n_cells = grid * grid * grid
    cell = np.empty(2 * directions.shape[0], dtype=np.int64)
    offsets = np.zeros(n_cells + 1, dtype=np.int64)
    for k in range(directions.shape[0]):
        d = directions[k]
        for way in range(2):
            sign = 1.0 if way == 0 else -1.0
            c = (_grid_cell(sign * d[0], grid) * grid + _grid_cell(sign * d[1], grid)) * grid + _grid_cell(
                sign * d[2], grid
            )
            cell[2 * k + way] = c
            offsets[c + 1] += 1
    for c in range(n_cells):
        offsets[c + 1] += offsets[c]
    fill = offsets[:-1].copy()
    members = np.empty(2 * directions.shape[0], dtype=np.int64)
    for i in range(cell.shape[0]):
        members[fill[cell[i]]] = i // 2
        fill[cell[i]] += 1
    return offsets, members


@njit_leaf
def _nodes_near_piece(apex, a, along, s0, s1, height, tol, directions, cell_offsets, cell_ends, grid, stamp,
                      last_stamp, out):
    """Positions in the vertex's ends (into out (K,) int64, in no order; returns how many, or K for all of
    them) of the nodes whose line through apex may pass within tol of a point of the edge a + s along,
    s0 <= s <= s1, at distance >= height from apex: those of the grid cells (see _direction_grid) of the box
    around the cone of such lines whose direction (K, 3) lies in the cone. stamp marks the positions looked
    at in last_stamp (K,) int64."""
    n_ends = out.shape[0]
    u0x, u0y, u0z = a[0] + s0 * along[0] - apex[0], a[1] + s0 * along[1] - apex[1], a[2] + s0 * along[2] - apex[2]
    u1x, u1y, u1z = a[0] + s1 * along[0] - apex[0], a[1] + s1 * along[1] - apex[1], a[2] + s1 * along[2] - apex[2]
    n0 = np.sqrt(u0x * u0x + u0y * u0y + u0z * u0z)
    n1 = np.sqrt(u1x * u1x + u1y * u1y + u1z * u1z)
    if n0 == 0.0 or n1 == 0.0 or height <= 2.0 * tol:
        return n_ends
    u0x, u0y, u0z = u0x / n0, u0y / n0, u0z / n0
    u1x, u1y, u1z = u1x / n1, u1y / n1, u1z / n1
    mx, my, mz = u0x + u1x, u0y + u1y, u0z + u1z
    m = np.sqrt(mx * mx + my * my + mz * mz)
    if m < 1e-3:
        return n_ends
    # the lines through apex and the piece: within half the piece's angle of its middle; one within tol of a
    # point of the piece, within asin(tol / height) of the line through that point. The margins cover rounding
    cx, cy, cz = u0y * u1z - u0z * u1y, u0z * u1x - u0x * u1z, u0x * u1y - u0y * u1x
    half = 0.5 * np.arctan2(np.sqrt(cx * cx + cy * cy + cz * cz), u0x * u1x + u0y * u1y + u0z * u1z)
    spread = (half + np.arcsin(min(1.0, tol / height))) * (1.0 + 1e-6) + 1e-9
    if spread >= 1.0:
        return n_ends
    radius = 2.0 * np.sin(0.5 * spread) + 1e-9
    mx, my, mz = mx / m, my / m, mz / m
    x0, x1 = _grid_cell(mx - radius, grid), _grid_cell(mx + radius, grid)
    y0, y1 = _grid_cell(my - radius, grid), _grid_cell(my + radius, grid)
    z0, z1 = _grid_cell(mz - radius, grid), _grid_cell(mz + radius, grid)
    if (x1 - x0 + 1) * (y1 - y0 + 1) * (z1 - z0 + 1) >= n_ends:
        return n_ends
    # a direction within the chord radius of the middle, either way round (the lines lying in the swath's plane
    # beyond the piece are most of those in the cells)
    reach = radius * radius
    count = 0
    for x in range(x0, x1 + 1):
        for y in range(y0, y1 + 1):
            row = (x * grid + y) * grid
            for i in range(cell_offsets[row + z0], cell_offsets[row + z1 + 1]):
                k = cell_ends[i]
                if last_stamp[k] == stamp:
                    continue
                last_stamp[k] = stamp
                dx, dy, dz = directions[k, 0], directions[k, 1], directions[k, 2]
                ahead = (dx - mx) * (dx - mx) + (dy - my) * (dy - my) + (dz - mz) * (dz - mz)
                behind = (dx + mx) * (dx + mx) + (dy + my) * (dy + my) + (dz + mz) * (dz + mz)
                if min(ahead, behind) <= reach:
                    out[count] = k
                    count += 1
    return count


@njit(cache=True, nogil=True)
def _place_cuts(found_arc, found_s, found_node, fill, cut_s, cut_node):
    """Write the cuts found (arc, s, node) (C,) each at its arc's next free row (fill (A,) int64)."""
    for k in range(found_arc.shape[0]):
        cut_s[fill[found_arc[k]]] = found_s[k]
        cut_node[fill[found_arc[k]]] = found_node[k]
        fill[found_arc[k]] += 1


@njit(cache=True, nogil=True)
def _free_scratch():
    """Scratch arrays for _leaves_freely, allocated once per loop over lines: elements (3, 64) int64 (faces,
    contact kinds, corners of one element) and angles (6, 128) float64 (see _enters, and the unit direction)."""
    return np.empty((3, 64), dtype=np.int64), np.empty((6, 128))


@njit_leaf
def _leaves_freely(v, direction, points, offsets, normals, vf_off, vf_face, vf_corner, rest_off, rest_face,
                   other_off, other_code, ef_off, ef_face, ef_local, cosine, elements, angles):
    """Whether the line leaving vertex v along `direction` (3,) goes into free space, not into a solid. Its
    own faces decide first (see _enters); a vertex resting inside another object's face (rest_off, rest_face:
    see _resting_on) sends the lines behind that face into its object, and one at another object's vertex or
    on its edge (other_off, other_code: see _elements_at) the lines into the solid around that element, the
    faces of each element winding on their own. elements, angles: scratch (see _free_scratch)."""
    n_vertices = vf_off.shape[0] - 1
    length = np.sqrt(direction[0] * direction[0] + direction[1] * direction[1] + direction[2] * direction[2])
    unit = angles[5, :3]
    for k in range(3):
        unit[k] = direction[k] / length
    direction = unit
    for i in range(rest_off[v], rest_off[v + 1]):
        face = rest_face[i]
        if normals[face, 0] * unit[0] + normals[face, 1] * unit[1] + normals[face, 2] * unit[2] < -cosine:
            return False
    faces = elements[0]
    kinds = elements[1]
    corners = elements[2]
    e1, e2 = _perpendicular_frame(direction)
    for j in range(other_off[v] - 1, other_off[v + 1]):
        # first the vertex's own faces (j = other_off[v] - 1), then each other element's
        code = v if j < other_off[v] else other_code[j]
        count = 0
        if code < n_vertices:
            for i in range(vf_off[code], min(vf_off[code + 1], vf_off[code] + 64)):
                faces[count] = vf_face[i]
                kinds[count] = CONTACT_VERTEX
                corners[count] = vf_corner[i]
                count += 1
        else:
            e = code - n_vertices
            for i in range(ef_off[e], min(ef_off[e + 1], ef_off[e] + 64)):
                faces[count] = ef_face[i]
                kinds[count] = CONTACT_EDGE
                corners[count] = ef_local[i]
                count += 1
        if _enters(points, offsets, normals, faces, kinds, corners, count, direction, e1, e2, cosine, angles):
            return False
    return True


def _collinear_edges(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    """CSR (offsets (E+1,) int64, edges int64): for each edge, the other edges on its line (within the
    tolerance length) overlapping it by more than that length: the top edges of two boxes of one height side
    by side, a box's edge on the edge of the one it stands on."""
    n_edges = len(scene.edges)
    ends = scene.vertices[scene.edges]
    direction = ends[:, 1] - ends[:, 0]
    length = np.linalg.norm(direction, axis=1)
    direction /= length[:, None]
    line = coincident_nodes(ends[:, 0], direction, scene.diagonal, scene.tol.length)
    tol = scene.tol.length
    pairs = []
    for root in np.flatnonzero(np.bincount(line, minlength=n_edges) > 1):
        members = np.flatnonzero(line == root)
        base, axis = ends[root, 0], direction[root]
        lo = np.minimum(ends[members, 0] @ axis, ends[members, 1] @ axis) - base @ axis
        hi = np.maximum(ends[members, 0] @ axis, ends[members, 1] @ axis) - base @ axis
        overlap = np.minimum(hi[:, None], hi[None]) - np.maximum(lo[:, None], lo[None]) > tol
        np.fill_diagonal(overlap, False)
        pairs.extend(zip(members[np.nonzero(overlap)[0]], members[np.nonzero(overlap)[1]], strict=True))
    pairs = np.array(sorted(pairs), dtype=np.int64).reshape(-1, 2)
    offsets = np.zeros(n_edges + 1, dtype=np.int64)
    offsets[1:] = np.cumsum(np.bincount(pairs[:, 0], minlength=n_edges))
    return offsets, pairs[:, 1]


def _along_rest_planes(segments, normals: np.ndarray, offsets: np.ndarray, tol: float) -> list:
    """The segments closing a view (oriented segments: from node, to node, from point, to point) along the
    planes of the faces its vertex rests on (normals (R, 3), offsets (R,)): each chain ending at a point of such
    a plane goes on to the nearest chain starting on it. The lines from the vertex sliding along the face it
    rests on and past its edges (a rug's corner on the floor, towards the foot of a wall) bound the view where
    that plane cuts the source, and no arc holds them: their far generator is the concave edge between the
    face and the source (or what stands on the face before it)."""
    arriving: dict[int, np.ndarray] = {}
    leaving: dict[int, np.ndarray] = {}
    for n0, n1, p0, p1 in segments:
        leaving[n0] = p0
        arriving[n1] = p1
    ends = [(node, point) for node, point in arriving.items() if node not in leaving]
    starts = [(node, point) for node, point in leaving.items() if node not in arriving]
    closing = []
    for node, point in ends:
        on = np.abs(normals @ point + offsets) <= tol
        if not on.any():
            continue
        candidates = [
            (float(np.linalg.norm(other - point)), other_node, other)
            for other_node, other in starts
            if (np.abs(normals[on] @ other + offsets[on]) <= tol).any()
        ]
        if candidates:
            _, other_node, other = min(candidates, key=lambda c: c[0])
            starts = [(n, p) for n, p in starts if n != other_node]
            closing.append((node, other_node, point, other))
    return closing


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
