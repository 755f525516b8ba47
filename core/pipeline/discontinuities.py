"""Discontinuity meshing (seed 000 sections 5, 6.2 and 6.4): the visual events of the emitters' light on a
receiver, from the Visibility Skeleton built lazily for the emitters, ranked by the visibility oracle.

The skeleton gives, for an (emitter, receiver) pair, the traces of its EV and EEE swaths on the receiver with
the generators of each swath (`Skeleton.discontinuity_events`). The generators that are not on the emitter
belong to the blocker of the event. Section 6.4 estimates the variation of radiosity an event causes:

* the unoccluded transfer B_unoc = rho_r B_s F, F the disk estimate of the emitter seen from the trace's end;
* the shadow amount: the blocker (diameter D(b), at distance l1 from the receiver point, the emitter at l2)
  projects onto the emitter with diameter D_proj = D(b) l2 / l1 and hides occlu = min(1, pi D_proj^2 / 4 A_s)
  of it: shadow = B_unoc occlu;
* the sharpness: the penumbra is D(pen) = D(s) l1 / l2 wide; on a receiver of diameter D(r) smaller than the
  penumbra the radiosity varies by shadow D(r) / D(pen) only.

Delta B = shadow min(1, D(r) / D(pen)), the larger of its values at the trace's two ends, luminance weighted.
Events with a perceptible Delta B are inserted into the receiver as constrained segments, highest first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..formfactor import disk_ff_estimate
from ..unionfind import find_root
from .perception import LUMINANCE_WEIGHTS


@dataclass(frozen=True)
class ReceiverEvents:
    """The candidate discontinuities of one receiver polygon (M events).

    segments (M, 2, 3) float64 traces on the receiver; emitter (M,) int64 the source of each event;
    blocker_size (M,) float64 D(b); emitter_size (M,) float64 D(s); blocker_point (M, 2, 3) float64 the point
    of the blocker's generators nearest the line joining each end of the trace to the emitter's centre;
    pieces (G, 2, 3) float64 the segments to insert: the traces with collinear overlapping ones merged
    (several swaths can trace the same line, and a triangulation cannot take overlapping constraints);
    group (M,) int64 the piece of each trace.
    """

    segments: np.ndarray
    emitter: np.ndarray
    blocker_size: np.ndarray
    emitter_size: np.ndarray
    blocker_point: np.ndarray
    pieces: np.ndarray
    group: np.ndarray

    def __len__(self) -> int:
        return len(self.segments)


def receiver_events(skeleton, scene, receiver: int, emitters) -> ReceiverEvents:
    """The visual events of every emitter of `emitters` (int ids) on polygon `receiver`."""
    segments, emitter, sizes, codes = [], [], [], []
    diameters = _polygon_diameters(scene)
    largest_face: dict[int, float] = {}  # generator code -> diameter of the largest polygon around it
    for source in emitters:
        if source == receiver:
            continue
        traces, generators = skeleton.discontinuity_events(int(source), receiver)
        if not len(traces):
            continue
        blocking = np.where(_on_polygon(scene, skeleton, generators, int(source)), -1, generators)
        kept = (blocking >= 0).any(axis=1)
        for code in np.unique(blocking[kept]):
            if code >= 0 and int(code) not in largest_face:
                largest_face[int(code)] = float(diameters[skeleton.element_faces(int(code))].max())
        for codes_of_trace in blocking[kept]:
            sizes.append(max(largest_face[int(c)] for c in codes_of_trace if c >= 0))
        segments.append(traces[kept])
        codes.append(blocking[kept])
        emitter.append(np.full(int(kept.sum()), int(source), dtype=np.int64))
    if not sizes:
        empty = np.empty((0, 2, 3))
        return ReceiverEvents(
            empty, np.empty(0, np.int64), np.empty(0), np.empty(0), empty, empty, np.empty(0, np.int64)
        )
    segments = np.concatenate(segments)
    emitter = np.concatenate(emitter)
    points = _nearest_on_elements(
        np.concatenate(codes), segments, scene.centroids[emitter], scene.vertices, scene.edges, scene.n_vertices
    )
    pieces, group = merge_collinear(segments, scene.tol.snap)
    return ReceiverEvents(segments, emitter, np.array(sizes), diameters[emitter], points, pieces, group)


def merge_collinear(segments: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge segments (M, 2, 3) lying on one line and overlapping or touching (within tol) into single pieces.

    Returns (pieces (G, 2, 3) float64, group (M,) int64 the piece holding each segment)."""
    segments = np.ascontiguousarray(segments, dtype=np.float64).reshape(-1, 2, 3)
    starts = segments[:, 0]
    directions = segments[:, 1] - starts
    lengths = np.linalg.norm(directions, axis=1)
    units = directions / np.where(lengths > 0.0, lengths, 1.0)[:, None]
    roots = _collinear_roots(segments, units, lengths, float(tol))
    _, group = np.unique(roots, return_inverse=True)
    pieces = np.empty((group.max() + 1, 2, 3))
    for g in range(len(pieces)):
        members = np.flatnonzero(group == g)
        first = members[np.argmax(lengths[members])]
        points = segments[members].reshape(-1, 3)
        along = (points - starts[first]) @ units[first]
        pieces[g] = points[[np.argmin(along), np.argmax(along)]]
    return pieces, group.astype(np.int64)


@njit(cache=True)
def _collinear_roots(segments, units, lengths, tol):
    """(M,) int64 the union-find root of each segment, segments j > i joined to i when both ends of j lie within
    tol of i's line and j's extent along it meets [-tol, length_i + tol] (every pair of a receiver's traces is
    compared: thousands of them, hence a kernel)."""
    count = len(segments)
    parent = np.arange(count)
    for i in range(count):
        sx, sy, sz = segments[i, 0, 0], segments[i, 0, 1], segments[i, 0, 2]
        ux, uy, uz = units[i, 0], units[i, 1], units[i, 2]
        for j in range(i + 1, count):
            low = np.inf
            high = -np.inf
            on_line = True
            for end in range(2):
                ox = segments[j, end, 0] - sx
                oy = segments[j, end, 1] - sy
                oz = segments[j, end, 2] - sz
                along = ox * ux + oy * uy + oz * uz
                cx, cy, cz = ox - along * ux, oy - along * uy, oz - along * uz
                if np.sqrt(cx * cx + cy * cy + cz * cz) > tol:
                    on_line = False
                    break
                low = min(low, along)
                high = max(high, along)
            if on_line and high >= -tol and low <= lengths[i] + tol:
                parent[find_root(parent, j)] = find_root(parent, i)
    roots = np.empty(count, dtype=np.int64)
    for i in range(count):
        roots[i] = find_root(parent, i)
    return roots


def event_variation(events: ReceiverEvents, which, scene, receiver: int, radiated, receiver_size) -> np.ndarray:
    """(K,) float64 the luminance-weighted Delta B (section 6.4) of events `which` (K,) int on receiver regions
    of diameters `receiver_size` (K,); radiated (2 P, 3): what each polygon side radiates."""
    which = np.asarray(which, dtype=np.int64)
    if not len(which):
        return np.empty(0)
    rho = float(scene.reflectance[receiver] @ LUMINANCE_WEIGHTS)
    source_luminance = (np.asarray(radiated) @ LUMINANCE_WEIGHTS).reshape(-1, 2).max(axis=1)
    emitter = events.emitter[which]
    normals = np.tile(scene.normals[receiver], (len(which), 1))
    centres = scene.centroids[emitter]
    areas = scene.areas[emitter]
    variation = np.zeros(len(which))
    for end in range(2):
        points = events.segments[which, end]
        unoccluded = np.zeros(len(which))
        for source in np.unique(emitter):
            rows = emitter == source
            unoccluded[rows] = disk_ff_estimate(points[rows], normals[rows], centres[rows][0], scene.normals[source],
                                                scene.areas[source])  # fmt: skip
        unoccluded *= rho * source_luminance[emitter]
        to_blocker = np.linalg.norm(events.blocker_point[which, end] - points, axis=1)
        to_source = np.linalg.norm(centres - points, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            projected = events.blocker_size[which] * to_source / to_blocker
            penumbra = events.emitter_size[which] * to_blocker / to_source
            occlusion = np.where(to_blocker > 0.0, np.minimum(1.0, 0.25 * np.pi * projected**2 / areas), 1.0)
            sharpness = np.where(penumbra > 0.0, np.minimum(1.0, receiver_size / penumbra), 1.0)
        variation = np.maximum(variation, unoccluded * occlusion * sharpness)
    return variation


def clip_to_convex(segment: np.ndarray, polygon: np.ndarray, normal: np.ndarray) -> np.ndarray | None:
    """The part (2, 3) of a segment (2, 3) lying in the plane of the convex polygon (K, 3) that is inside it,
    or None when nothing of it is."""
    start, end = segment
    lo, hi = 0.0, 1.0
    centre = polygon.mean(axis=0)
    for k in range(len(polygon)):
        a = polygon[k]
        inward = np.cross(normal, polygon[(k + 1) % len(polygon)] - a)
        if inward @ (centre - a) < 0.0:
            inward = -inward
        at_start = (start - a) @ inward
        at_end = (end - a) @ inward
        if at_start < 0.0 and at_end < 0.0:
            return None
        if at_start < 0.0:
            lo = max(lo, at_start / (at_start - at_end))
        elif at_end < 0.0:
            hi = min(hi, at_start / (at_start - at_end))
    if hi <= lo:
        return None
    direction = end - start
    return np.stack([start + lo * direction, start + hi * direction])


def crossing(segments_2d: np.ndarray, triangles_2d: np.ndarray, tol: float) -> np.ndarray:
    """(M, T) bool: which segments (M, 2, 2) meet which triangles (T, 3, 2), within tol (separating axes: the
    triangle's three side normals and the segment's normal)."""
    segments_2d = np.ascontiguousarray(segments_2d, dtype=np.float64).reshape(-1, 2, 2)
    triangles_2d = np.ascontiguousarray(triangles_2d, dtype=np.float64).reshape(-1, 3, 2)
    return _crossing(segments_2d, triangles_2d, float(tol))


@njit(cache=True)
def _crossing(segments, triangles, tol):
    meets = np.zeros((len(segments), len(triangles)), dtype=np.bool_)
    seg = np.empty(2)
    tri = np.empty(3)
    for m in range(len(segments)):
        for t in range(len(triangles)):
            separated = False
            for k in range(4):
                if k < 3:
                    a = triangles[t, k]
                    b = triangles[t, (k + 1) % 3]
                else:
                    a = segments[m, 0]
                    b = segments[m, 1]
                # the axis normal to a -> b
                ax = a[1] - b[1]
                ay = b[0] - a[0]
                for j in range(2):
                    seg[j] = segments[m, j, 0] * ax + segments[m, j, 1] * ay
                for j in range(3):
                    tri[j] = triangles[t, j, 0] * ax + triangles[t, j, 1] * ay
                margin = tol * np.sqrt(ax * ax + ay * ay)
                if seg.max() < tri.min() - margin or tri.max() < seg.min() - margin:
                    separated = True
                    break
            meets[m, t] = not separated
    return meets


def _polygon_diameters(scene) -> np.ndarray:
    corners = [scene.polygon(p) for p in range(scene.n_polygons)]
    return np.array([np.linalg.norm(c[:, None] - c[None], axis=2).max() for c in corners])


def _on_polygon(scene, skeleton, generators: np.ndarray, polygon: int) -> np.ndarray:
    """(M, 3) bool: which generator codes are elements of the surface (face group) of `polygon`."""
    group = skeleton.topology.face_group[polygon]
    out = np.zeros(generators.shape, dtype=bool)
    for index, code in np.ndenumerate(generators):
        if code >= 0:
            out[index] = bool((skeleton.topology.face_group[skeleton.element_faces(code)] == group).any())
    return out


@njit(cache=True)
def _nearest_on_elements(codes, segments, centres, vertices, edges, n_vertices):
    """(M, 2, 3) for each trace and each of its ends, the point of its generator elements (codes (M, 3): vertex
    v as v, edge e as n_vertices + e, -1 none) nearest the segment from that end to the emitter's centre."""
    out = np.empty((len(codes), 2, 3))
    for m in range(len(codes)):
        for end in range(2):
            point = segments[m, end]
            best = np.inf
            for k in range(codes.shape[1]):
                code = codes[m, k]
                if code < 0:
                    continue
                if code < n_vertices:
                    candidate = vertices[code].copy()
                else:
                    edge = edges[code - n_vertices]
                    candidate = _segment_point_nearest_segment(vertices[edge[0]], vertices[edge[1]], point, centres[m])
                distance = _distance_to_segment(candidate, point, centres[m])
                if distance < best:
                    best = distance
                    out[m, end] = candidate
    return out


@njit(cache=True)
def _segment_point_nearest_segment(a, b, p, q):
    """The point of segment ab nearest segment pq (closest points of two segments, clamped to both)."""
    d1 = b - a
    d2 = q - p
    r = a - p
    aa = (d1 * d1).sum()
    ee = (d2 * d2).sum()
    if aa == 0.0:
        return a.copy()
    c = (d1 * r).sum()
    if ee == 0.0:
        return a + min(max(-c / aa, 0.0), 1.0) * d1
    f = (d2 * r).sum()
    bb = (d1 * d2).sum()
    denominator = aa * ee - bb * bb
    s = min(max((bb * f - c * ee) / denominator, 0.0), 1.0) if denominator > 0.0 else 0.0
    t = (bb * s + f) / ee
    if t < 0.0:
        s = min(max(-c / aa, 0.0), 1.0)
    elif t > 1.0:
        s = min(max((bb - c) / aa, 0.0), 1.0)
    return a + s * d1


@njit(cache=True)
def _distance_to_segment(x, p, q):
    d = q - p
    length2 = (d * d).sum()
    t = 0.0 if length2 == 0.0 else min(max(((x - p) * d).sum() / length2, 0.0), 1.0)
    gap = p + t * d - x
    return np.sqrt((gap * gap).sum())
