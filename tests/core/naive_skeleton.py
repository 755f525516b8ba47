"""Independent oracles for the Visibility Skeleton's queries (seed 003, sections 4.3 and 4.4).

* `analytic_events` / `analytic_event_segments`: the EV and VE discontinuity lines that one convex box casts
  on a floor lit by a convex light, from the geometry alone, optionally hidden by extra occluders;
  `face_plane_traces`: where a box face's plane cuts the light (face swaths, not EV / VE, yet the form
  factor's derivative jumps there); `uncovered` / `same_segment_sets` compare segment sets as point sets (the
  skeleton may split a trace at nodes where the oracle does not).
* `blockers_by_removal`: whether taking a candidate (or its whole object) out of the blocker set changes a form
  factor source -> receiver (evidence from core.visibility.exact_form_factors, verified on its own).
* `reaches`: whether some unoccluded segment from the source to the receiver touches a polygon, settled either
  way where possible: a witness segment, or an occluder that every such segment crosses.
* `seen_pairs`: which polygons see each other, from exact form factors at sample points of every polygon.

Plain numpy, every polygon tested, no BVH. The only core function used is exact_form_factors (by
`blockers_by_removal` and `seen_pairs`); nothing here imports core.skeleton or core.raycast.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.visibility import exact_form_factors

#: relative tolerance of the oracles, as core's (a multiple of the bounding-box diagonal)
RELATIVE_TOLERANCE = 1e-9


# ---------------------------------------------------------------------------------------------------------
# Small geometry, written here rather than borrowed from core so the oracles share no code with it.


def _as_polygon(polygon) -> np.ndarray:
    array = np.array(polygon, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3 or len(array) < 3:
        raise ValueError(f"a polygon must be a (K >= 3, 3) array, got shape {array.shape}")
    return array


def _tolerance(*polygons) -> float:
    points = np.concatenate([np.asarray(p, dtype=np.float64).reshape(-1, 3) for p in polygons])
    return RELATIVE_TOLERANCE * max(float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))), 1.0e-300)


def _plane(polygon: np.ndarray) -> tuple[np.ndarray, float]:
    """Unit normal (3,) by Newell's rule (right-hand rule of the corner order) and offset d: n . x + d = 0."""
    newell = np.cross(polygon, np.roll(polygon, -1, axis=0)).sum(axis=0)
    normal = newell / np.linalg.norm(newell)
    return normal, -float(normal @ polygon.mean(axis=0))


def _inside_distances(points: np.ndarray, polygon: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """(N, K) distances of points (N, 3) lying in or near the plane of a convex polygon (K, 3) to its K edge
    lines, positive on the polygon's side (the corners turn counter-clockwise around `normal`)."""
    edges = np.roll(polygon, -1, axis=0) - polygon
    inward = np.cross(normal, edges)
    inward /= np.linalg.norm(inward, axis=1)[:, None]
    return np.einsum("nkj,kj->nk", points[:, None, :] - polygon[None, :, :], inward)


def _clip(polygon: np.ndarray, normal: np.ndarray, offset: float, tol: float) -> np.ndarray:
    """The part (M, 3) of a convex polygon where normal . x + offset >= -tol (M may be < 3)."""
    values = polygon @ normal + offset
    kept = []
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if values[i] >= -tol:
            kept.append(polygon[i])
        if (values[i] > tol and values[j] < -tol) or (values[i] < -tol and values[j] > tol):
            kept.append(polygon[i] + values[i] / (values[i] - values[j]) * (polygon[j] - polygon[i]))
    return np.array(kept).reshape(-1, 3)


def _plane_section(polygon: np.ndarray, normal: np.ndarray, offset: float, tol: float) -> np.ndarray:
    """Points (M, 3) whose convex hull is the polygon's intersection with the plane (all corners when the
    polygon lies in the plane, M = 0 when it misses it)."""
    values = polygon @ normal + offset
    on = np.abs(values) <= tol
    points = [polygon[i] for i in np.flatnonzero(on)]
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if (values[i] > tol and values[j] < -tol) or (values[i] < -tol and values[j] > tol):
            points.append(polygon[i] + values[i] / (values[i] - values[j]) * (polygon[j] - polygon[i]))
    return np.array(points).reshape(-1, 3)


# ---------------------------------------------------------------------------------------------------------
# Analytic EV / VE event lines of one convex box between a convex light and a floor.


@dataclass(frozen=True)
class Event:
    """One EV or VE event of `analytic_events` and the visible pieces of its trace on the floor.

    kind: "EV" (a light vertex and a box edge) or "VE" (a box vertex and a light edge); centre: (3,) float64
    the vertex (the light's for EV, the box's for VE); generator: (2, 3) float64 the edge (the box's for EV,
    the light's for VE); segments: (n, 2, 3) float64 the pieces on the floor, possibly none.
    """

    kind: str
    centre: np.ndarray
    generator: np.ndarray
    segments: np.ndarray


def analytic_event_segments(light, box_polygons, floor, occluders=()) -> np.ndarray:
    """The EV and VE visual-event lines that a convex box casts on a floor lit by a convex light: the segments
    (M, 2, 3) float64 of every event of `analytic_events`, unmerged (collinear pieces may overlap)."""
    events = analytic_events(light, box_polygons, floor, occluders)
    return np.concatenate([e.segments for e in events] + [np.empty((0, 2, 3))])


def analytic_events(light, box_polygons, floor, occluders=()) -> list[Event]:
    """The EV and VE events of a convex box between a convex light and a floor, with their traces.

    light: (K, 3) convex polygon whose corner order gives its emitting side; box_polygons: the faces (k, 3) of
    one closed convex box, outward by the right-hand rule; floor: (F, 3) convex polygon, its normal facing the
    light; occluders: optional extra convex polygons (k, 3) that may hide parts of the box's events.
    Returns one Event per (light vertex, box edge) and (box vertex, light edge) pair whose trace is not empty.

    Which floor points q count (seed 003, sections 2.3 and 4.3; the EV events of aspect graphs):
    * EV (light vertex v, box edge e): the line through q and v meets e at a point y strictly between q and v
      (q in front of the light, y above the floor), and the plane through v and e supports the box -- e is a
      silhouette edge seen from v: its two faces lie on the same side of that plane, one front- and one
      back-facing. Seen from q, the image of v crosses the image of e there.
    * VE (box vertex w, light edge f): the line through q and w meets f at a point x, with w strictly between
      q and x, w in front of the light, and that line touches the box only at w -- w is a silhouette vertex seen
      from q: the line's direction points neither into nor out of the cone of the faces at w (some face at w
      faces along it, another against it). This depends on x, so a VE trace may stop part-way. (A plane through
      f and w supporting the box is sufficient, not necessary: seen from q, the silhouette may pass through w
      with w's neighbours on both sides of f's image.)
    * In both cases the open segments (light point, generator) and (generator, q) must cross no occluder. They
      never cross the box itself: the event line is tangent to the convex box at the generator (this is why
      the box's own faces are not occluder-tested).
    The traces are exact: along an event the floor point is a projective function of the parameter on the
    generating edge, so every constraint (in front, above the floor, inside the floor polygon, crossing an
    occluder) changes sign at roots of polynomials of degree <= 2, found in closed form, with the geometric
    sign tested in between. EEE events cannot occur: a line tangent to a convex box along two of its edges lies
    in a face plane, and two edges of the (planar) light meet only at a vertex.
    Raises ValueError for a non-convex or open box, a floor not facing the light, or a light vertex lying in
    the plane of a box face (a degenerate event: pick another configuration).
    """
    light = _as_polygon(light)
    floor = _as_polygon(floor)
    faces = [_as_polygon(face) for face in box_polygons]
    blockers = [_as_polygon(o) for o in occluders]
    tol = _tolerance(light, floor, *faces, *blockers)
    light_normal, light_offset = _plane(light)
    floor_normal, floor_offset = _plane(floor)
    if np.any(light @ floor_normal + floor_offset <= tol):
        raise ValueError("the light must lie strictly above the floor (on the side its normal points to)")
    if np.any(floor @ light_normal + light_offset <= tol):
        raise ValueError("the floor must lie strictly in front of the light")
    corners, edges, incident = _convex_box(faces, tol)
    face_normals = np.array([_plane(face)[0] for face in faces])

    context = _TraceContext(
        light_normal, light_offset, floor_normal, floor_offset, floor,
        [_slab_clip(o, light_normal, light_offset, floor_normal, floor_offset, tol) for o in blockers], tol,
    )
    events = []
    for v in light:
        for a, b, first, second in edges:
            normal = np.cross(corners[a] - v, corners[b] - v)
            if np.linalg.norm(normal) <= tol * np.linalg.norm(corners[b] - corners[a]):
                continue  # v on the edge's line: the wedge is a line, not an event plane
            normal /= np.linalg.norm(normal)
            if _face_side(faces[first], normal, v, tol) != _face_side(faces[second], normal, v, tol):
                continue
            pieces = context.trace(centre=v, start=corners[a], end=corners[b], centre_on_light=True)
            if pieces:
                events.append(Event("EV", v.copy(), corners[[a, b]].copy(), _segments(pieces)))
    for w, around in zip(corners, incident, strict=True):
        if w @ light_normal + light_offset <= tol:
            continue
        for i in range(len(light)):
            la, lb = light[i], light[(i + 1) % len(light)]
            pieces = context.trace(
                centre=w, start=la, end=lb, centre_on_light=False, tangent_to=face_normals[sorted(around)]
            )
            if pieces:
                events.append(Event("VE", w.copy(), np.stack([la, lb]), _segments(pieces)))
    return events


def _segments(pieces) -> np.ndarray:
    return np.array(pieces, dtype=np.float64).reshape(-1, 2, 3)


def face_plane_traces(light, box_polygons, floor) -> np.ndarray:
    """Where a box face is seen edge-on in front of the light: (M, 2, 3) float64 segments on the floor.

    For each box face F whose plane cuts the light (light corners strictly on both sides), the floor points q
    of F's plane from which F's (degenerate, segment) image overlaps the light's: some line in F's plane
    through q meets F and, beyond it, the light. These are the floor traces of the face swaths (seed 003,
    Fig. 4(c)-(d): Fv / FE); not EV or VE events, but the form factor's derivative jumps across them (the box's
    image gains or loses the sliver of F linearly on one side only), so they bound the validity of view
    comparisons around the events. Same arguments as `analytic_events`; F must lie strictly between the
    light's plane and the floor.
    """
    light = _as_polygon(light)
    floor = _as_polygon(floor)
    faces = [_as_polygon(face) for face in box_polygons]
    tol = _tolerance(light, floor, *faces)
    floor_normal, floor_offset = _plane(floor)
    light_normal, light_offset = _plane(light)
    traces = []
    for face in faces:
        normal, offset = _plane(face)
        if not (np.min(light @ normal + offset) < -tol < tol < np.max(light @ normal + offset)):
            continue
        section = _plane_section(light, normal, offset, tol)
        h_face = face @ floor_normal + floor_offset
        if np.any(h_face <= tol) or np.any(face @ light_normal + light_offset <= tol):
            raise ValueError("a box face must lie strictly between the light's plane and the floor")
        # projections of F's corners from the section's ends onto the floor: the covered range of F's floor line
        ends = []
        for x in section:
            h_x = x @ floor_normal + floor_offset
            ends += [(h_x * y - h_y * x) / (h_x - h_y) for y, h_y in zip(face, h_face, strict=True)]
        ends = np.array(ends)
        direction = np.cross(normal, floor_normal)
        direction /= np.linalg.norm(direction)
        along = ends @ direction
        start, end = ends[np.argmin(along)], ends[np.argmax(along)]
        clipped = _clip_segment(start, end, floor, floor_normal, tol)
        if clipped is not None:
            traces.append(clipped)
    return np.array(traces, dtype=np.float64).reshape(-1, 2, 3)


def _clip_segment(start, end, polygon, normal, tol):
    """The part (2, 3) of a segment lying in a convex polygon's plane that is inside it, or None."""
    d0 = _inside_distances(start[None, :], polygon, normal)[0]
    d1 = _inside_distances(end[None, :], polygon, normal)[0]
    lo, hi = 0.0, 1.0
    for a, b in zip(d0, d1, strict=True):
        if a == b:
            if a < 0.0:
                return None
            continue
        s = -a / (b - a)
        lo, hi = (max(lo, s), hi) if b > a else (lo, min(hi, s))
    if (hi - lo) * np.linalg.norm(end - start) <= tol:
        return None
    return np.stack([start + lo * (end - start), start + hi * (end - start)])


def _convex_box(faces: list[np.ndarray], tol: float):
    """Distinct corners (V, 3), edges [(a, b, face, face)] and the faces around each corner [set] of a closed
    convex polyhedron given by its faces."""
    corners: list[np.ndarray] = []

    def index(point):
        for i, c in enumerate(corners):
            if np.linalg.norm(c - point) <= tol:
                return i
        corners.append(point)
        return len(corners) - 1

    adjacency: dict[tuple[int, int], list[int]] = {}
    around: dict[int, set[int]] = {}
    for f, face in enumerate(faces):
        ids = [index(p) for p in face]
        for i in ids:
            around.setdefault(i, set()).add(f)
        for k in range(len(ids)):
            key = (min(ids[k], ids[(k + 1) % len(ids)]), max(ids[k], ids[(k + 1) % len(ids)]))
            adjacency.setdefault(key, []).append(f)
    points = np.array(corners)
    for face in faces:
        normal, offset = _plane(face)
        if np.any(points @ normal + offset > tol):
            raise ValueError("the box must be convex with outward faces (a corner lies in front of a face)")
    edges = []
    for (a, b), owners in adjacency.items():
        if len(owners) != 2:
            raise ValueError(f"the box must be closed: edge {a}-{b} has {len(owners)} faces")
        edges.append((a, b, owners[0], owners[1]))
    return points, edges, [around[i] for i in range(len(points))]


def _face_side(face: np.ndarray, normal: np.ndarray, origin: np.ndarray, tol: float) -> int:
    """Side (+1 / -1) of an event plane (through `origin`, unit `normal`) on which a face hinged on it lies."""
    values = (face - origin) @ normal
    far = values[np.argmax(np.abs(values))]
    if abs(far) <= tol:
        raise ValueError("degenerate configuration: a light vertex lies in the plane of a box face")
    return 1 if far > 0.0 else -1


def _slab_clip(polygon, light_normal, light_offset, floor_normal, floor_offset, tol) -> np.ndarray:
    """The part of an occluder strictly between the light's plane (in front) and the floor (above)."""
    kept = _clip(polygon, light_normal, light_offset - tol, 0.0)
    if len(kept) >= 3:
        kept = _clip(kept, floor_normal, floor_offset - tol, 0.0)
    return kept if len(kept) >= 3 else np.empty((0, 3))


def _affine_product(p: tuple[float, float], q: tuple[float, float]) -> np.ndarray:
    """Coefficients (c0, c1, c2) of (p0 + p1 u)(q0 + q1 u)."""
    return np.array([p[0] * q[0], p[0] * q[1] + p[1] * q[0], p[1] * q[1]])


def _roots_inside(coefficients: np.ndarray, lo: float, hi: float) -> list[float]:
    """Real roots in (lo, hi) of c0 + c1 u + c2 u^2 (none when the polynomial vanishes identically)."""
    c0, c1, c2 = (float(c) for c in coefficients)
    scale = max(abs(c0), abs(c1), abs(c2))
    if scale == 0.0:
        return []
    if abs(c2) <= 1e-14 * scale:
        roots = [] if abs(c1) <= 1e-14 * scale else [-c0 / c1]
    else:
        discriminant = c1 * c1 - 4.0 * c2 * c0
        if discriminant < 0.0:
            return []
        root = np.sqrt(discriminant)
        # the numerically stable pair of roots
        q = -0.5 * (c1 + np.copysign(root, c1))
        roots = [q / c2] + ([c0 / q] if q != 0.0 else [])
    return [r for r in roots if lo < r < hi]


@dataclass
class _TraceContext:
    """What every event trace needs: the two planes, the floor polygon, clipped occluders, the tolerance."""

    light_normal: np.ndarray
    light_offset: float
    floor_normal: np.ndarray
    floor_offset: float
    floor: np.ndarray
    occluders: list
    tol: float

    def _height(self, point):
        return float(point @ self.floor_normal + self.floor_offset)

    def trace(self, centre, start, end, centre_on_light: bool, tangent_to=None) -> list[tuple]:
        """Floor segments (a, b) of one event: lines through the fixed `centre` and M(u) = start + u (end - start).

        EV (centre_on_light): the light vertex is the centre, M runs along the box edge. VE: the box vertex is
        the centre, M runs along the light edge. On each line, `upper` is the point on the light and `lower`
        the generator on the box; the floor point is q = (h_upper lower - h_lower upper) / (h_upper - h_lower)
        with h the height above the floor. tangent_to: (n, 3) normals of the faces around a box vertex the
        line must only touch (some facing along the line, some against it), or None.
        """
        direction = end - start

        def ends(u):
            moving = start + u * direction
            return (centre, moving) if centre_on_light else (moving, centre)

        def floor_point(u):
            upper, lower = ends(u)
            hu, hl = self._height(upper), self._height(lower)
            return (hu * lower - hl * upper) / (hu - hl)

        # affine (value at u = 0, slope) of a scalar affine function of the upper and lower points
        def affine(function):
            u0, l0 = ends(0.0)
            u1, l1 = ends(1.0)
            return (function(u0), function(u1) - function(u0)), (function(l0), function(l1) - function(l0))

        hu, hl = affine(self._height)
        in_front = affine(lambda p: float(p @ self.light_normal + self.light_offset))[1]
        breaks = [0.0, 1.0]
        # above the floor, below the light point, in front of the light
        for line in (hl, (hu[0] - hl[0], hu[1] - hl[1]), in_front):
            breaks += _roots_inside(np.array([line[0], line[1], 0.0]), 0.0, 1.0)
        # inside the floor polygon: inward . (q - corner) >= 0, times (h_upper - h_lower) > 0
        edges = np.roll(self.floor, -1, axis=0) - self.floor
        inward = np.cross(self.floor_normal, edges)
        for corner, normal in zip(self.floor, inward, strict=True):
            a_upper, a_lower = affine(lambda p, c=corner, n=normal: float(n @ (p - c)))
            breaks += _roots_inside(_affine_product(hu, a_lower) - _affine_product(hl, a_upper), 0.0, 1.0)
        # touching the box at its vertex only: the faces around it change facing where n . (lower - upper) = 0
        normals = np.empty((0, 3)) if tangent_to is None else np.asarray(tangent_to)
        for n in normals:
            along = affine(lambda p, n=n: float(n @ p))
            breaks += _roots_inside(np.array([along[1][0] - along[0][0], along[1][1] - along[0][1], 0.0]), 0.0, 1.0)
        # crossing an occluder: signed side of its section points with respect to the line, in the event plane
        plane_normal = np.cross(ends(0.0)[1] - ends(0.0)[0], ends(1.0)[1] - ends(1.0)[0])
        if np.linalg.norm(plane_normal) == 0.0:
            return []
        plane_normal /= np.linalg.norm(plane_normal)
        plane_offset = -float(plane_normal @ centre)
        sections = []
        for occluder in self.occluders:
            if len(occluder) == 0:
                continue
            section = _plane_section(occluder, plane_normal, plane_offset, self.tol)
            if len(section):
                sections.append(section)
                for point in section:
                    at0 = np.cross(start - centre, point - centre) @ plane_normal
                    slope = np.cross(direction, point - centre) @ plane_normal
                    breaks += _roots_inside(np.array([at0, slope, 0.0]), 0.0, 1.0)

        def usable(u):
            upper, lower = ends(u)
            h_upper, h_lower = self._height(upper), self._height(lower)
            if not (h_lower > self.tol and h_upper - h_lower > self.tol):
                return False
            if lower @ self.light_normal + self.light_offset <= self.tol:
                return False
            q = floor_point(u)
            if _inside_distances(q[None, :], self.floor, self.floor_normal).min() < -self.tol:
                return False
            line = lower - upper
            line /= np.linalg.norm(line)
            facing = normals @ line
            if len(facing) and (np.all(facing < -self.tol) or np.all(facing > self.tol)):
                return False
            for section in sections:
                side = np.cross(line, section - upper) @ plane_normal
                if side.min() < -self.tol and side.max() > self.tol:
                    return False
            return True

        breaks = np.unique(np.clip(breaks, 0.0, 1.0))
        pieces: list[list[float]] = []
        for lo, hi in zip(breaks[:-1], breaks[1:], strict=True):
            if hi - lo <= 0.0 or not usable(0.5 * (lo + hi)):
                continue
            if pieces and pieces[-1][1] == lo:
                pieces[-1][1] = hi
            else:
                pieces.append([lo, hi])
        out = []
        for lo, hi in pieces:
            a, b = floor_point(lo), floor_point(hi)
            if np.linalg.norm(b - a) > self.tol:
                out.append((a, b))
        return out


# ---------------------------------------------------------------------------------------------------------
# Comparing segment sets as point sets.


def uncovered(a, b, tol: float) -> np.ndarray:
    """The parts (K, 2, 3) of segments a (M, 2, 3) not covered by the union of segments b (N, 2, 3).

    A segment of b covers part of a segment s of a when both its ends lie within tol of the line of s; the
    covered parameters on s are merged, grown by tol, and what is left longer than tol is returned. So any
    splitting of collinear pieces (at nodes, at crossings) is irrelevant.
    """
    a = np.asarray(a, dtype=np.float64).reshape(-1, 2, 3)
    b = np.asarray(b, dtype=np.float64).reshape(-1, 2, 3)
    left = []
    for p, q in a:
        length = float(np.linalg.norm(q - p))
        if length <= tol:
            continue
        d = (q - p) / length
        covered = []
        for r, s in b:
            gap_r = np.linalg.norm(np.cross(r - p, d))
            gap_s = np.linalg.norm(np.cross(s - p, d))
            if gap_r <= tol and gap_s <= tol:
                t0, t1 = sorted((float((r - p) @ d), float((s - p) @ d)))
                covered.append((t0 - tol, t1 + tol))
        covered.sort()
        position = 0.0
        for t0, t1 in covered:
            if t0 > position and min(t0, length) - position > tol:
                left.append((p + position * d, p + min(t0, length) * d))
            position = max(position, t1)
            if position >= length:
                break
        if length - position > tol:
            left.append((p + position * d, q))
    return np.array(left, dtype=np.float64).reshape(-1, 2, 3)


def same_segment_sets(a, b, tol: float) -> bool:
    """Whether two sets of segments (M, 2, 3) and (N, 2, 3) cover the same points, within tol."""
    return len(uncovered(a, b, tol)) == 0 and len(uncovered(b, a, tol)) == 0


# ---------------------------------------------------------------------------------------------------------
# Blockers by removal.


@dataclass(frozen=True)
class RemovalEvidence:
    """What taking a candidate out of the blocker set did to the form factors source -> receiver samples.

    removed: (R,) int64 the polygons taken out (the candidate, or every polygon of its object);
    changed: whether some form factor moved by more than the threshold; largest_change: the largest |change|;
    point: (3,) float64 the sample point where the form factor moved most.
    """

    removed: np.ndarray
    changed: bool
    largest_change: float
    point: np.ndarray


def receiver_samples(scene, polygon: int, count: int, rng) -> np.ndarray:
    """`count` uniform random points (count, 3) float64 inside a convex scene polygon (area-weighted fan)."""
    corners = scene.polygon(polygon)
    first, second, third = corners[0], corners[1:-1], corners[2:]
    areas = np.linalg.norm(np.cross(second - first, third - first), axis=1)
    triangle = rng.choice(len(areas), size=count, p=areas / areas.sum())
    r1, r2 = rng.random(count), rng.random(count)
    flip = r1 + r2 > 1.0
    r1[flip], r2[flip] = 1.0 - r1[flip], 1.0 - r2[flip]
    return first + r1[:, None] * (second[triangle] - first) + r2[:, None] * (third[triangle] - first)


def blockers_by_removal(
    scene, source: int, receiver: int, candidates, samples: int, rng, remove: str = "polygon",
    threshold: float = 1e-12,
) -> dict[int, RemovalEvidence]:
    """For each candidate polygon b: does removing it change a form factor from the receiver to the source?

    Form factors from `samples` random points of the receiver (its normal) to the source, exact
    (core.visibility.exact_form_factors), with every polygon as a blocker, then with the blocker set minus b
    (remove="polygon") or minus every polygon of b's object (remove="object"). Returns {b: RemovalEvidence}.

    A change is proof that b (its object) blocks some light of the pair; no change is evidence at the samples
    only. Note that removing one face of a closed box never changes anything: every line through that face
    also crosses another face of the box. Removal by object is the meaningful test for closed objects.
    """
    if remove not in ("polygon", "object"):
        raise ValueError(f"remove must be 'polygon' or 'object', not {remove!r}")
    points = receiver_samples(scene, receiver, samples, rng)
    normals = np.tile(scene.normals[receiver], (len(points), 1))
    everything = np.arange(scene.n_polygons)
    reference = exact_form_factors(scene, points, normals, source)
    evidence = {}
    for candidate in (int(c) for c in candidates):
        if remove == "polygon":
            removed = np.array([candidate], dtype=np.int64)
        else:
            removed = np.flatnonzero(scene.object_ids == scene.object_ids[candidate]).astype(np.int64)
        kept = np.setdiff1d(everything, removed)
        change = np.abs(exact_form_factors(scene, points, normals, source, blockers=kept) - reference)
        worst = int(np.argmax(change))
        evidence[candidate] = RemovalEvidence(
            removed=removed, changed=bool(change[worst] > threshold), largest_change=float(change[worst]),
            point=points[worst].copy(),
        )
    return evidence


# ---------------------------------------------------------------------------------------------------------
# Does an unoccluded source -> receiver segment touch a polygon?


@dataclass(frozen=True)
class Reach:
    """Whether some unoccluded segment from the source to the receiver touches a polygon.

    status: True (a witness was found), False (proved impossible: every segment from the source to the receiver
    that meets the polygon crosses the interior of `occluder`), None (neither could be shown).
    witness: (3, 3) float64 the segment's start on the source, the point where it touches the polygon's
    boundary, its end on the receiver; None unless status is True. occluder: polygon id when status is False.
    """

    status: bool | None
    witness: np.ndarray | None = None
    occluder: int | None = None


def reaches(scene, source: int, receiver: int, polygon: int, density: int = 12) -> Reach:
    """Settle whether an unoccluded segment from `source` to `receiver` touches `polygon` (a blocker of the
    pair in the sense of seed 003, section 4.4: a polygon whose edge or vertex generates a line swath of the
    pair).

    Proof of False (exact): a polygon o such that the source is strictly on one side of o's plane, the receiver
    strictly on the other and the polygon strictly lower than every source point (distances to o's plane), with
    every line through a source corner and a polygon corner crossing o's plane strictly inside o. The crossing
    point of the line through x (source) and y (polygon) is a projective function of x for fixed y and of y
    for fixed x, with a positive denominator, so the crossings of all such lines lie in the convex hull of the
    corner-pair crossings: every segment from the source to the receiver meeting the polygon crosses o.
    Witness of True: a segment from a source point (a grid of interior points) through a point of one of the
    polygon's edges (`density` per edge) to a receiver point strictly inside it, leaving the source's front
    side and reaching the receiver's front side (either side when two-sided), which touches the polygon there
    and meets no polygon anywhere else: no crossing of a polygon's closed region, no end covered by a polygon
    lying in its plane (contact, as a box resting on the floor), no overlap with a polygon it lies in.
    """
    for occluder in range(scene.n_polygons):
        if occluder in (source, receiver, polygon):
            continue
        if _crossed_by_all(scene, source, receiver, polygon, occluder):
            return Reach(status=False, occluder=occluder)
    witness = _witness(scene, source, receiver, polygon, density)
    return Reach(status=True, witness=witness) if witness is not None else Reach(status=None)


def _crossed_by_all(scene, source: int, receiver: int, polygon: int, occluder: int) -> bool:
    tol = scene.tol.length
    normal, offset = scene.normals[occluder], scene.plane_offsets[occluder]
    x, r, y = scene.polygon(source), scene.polygon(receiver), scene.polygon(polygon)
    hx, hr, hy = x @ normal + offset, r @ normal + offset, y @ normal + offset
    if hx.min() < -tol:
        # measure heights on the source's side of the plane: the crossings do not depend on the orientation
        hx, hr, hy = -hx, -hr, -hy
    if not (hx.min() > tol and hr.max() < -tol and hy.max() < hx.min() - tol):
        return False
    # crossing of the line through x_i and y_j with the plane: (h(x) y - h(y) x) / (h(x) - h(y))
    crossings = (hx[:, None, None] * y[None, :, :] - hy[None, :, None] * x[:, None, :]) / (
        hx[:, None, None] - hy[None, :, None]
    )
    distances = _inside_distances(crossings.reshape(-1, 3), scene.polygon(occluder), scene.normals[occluder])
    return bool(distances.min() > tol)


def _source_points(corners: np.ndarray) -> np.ndarray:
    """Interior points (N, 3) of a convex polygon: its centroid and points towards each corner and edge
    midpoint at 50, 90 and 99 % of the way."""
    centre = corners.mean(axis=0)
    targets = np.concatenate([corners, 0.5 * (corners + np.roll(corners, -1, axis=0))])
    fractions = np.array([0.5, 0.9, 0.99])
    points = centre + fractions[:, None, None] * (targets[None, :, :] - centre)
    return np.concatenate([centre[None, :], points.reshape(-1, 3)])


def _witness(scene, source: int, receiver: int, polygon: int, density: int) -> np.ndarray | None:
    tol = scene.tol.length
    origins = _source_points(scene.polygon(source))
    corners = scene.polygon(polygon)
    sides = np.roll(corners, -1, axis=0) - corners
    fractions = (np.arange(density) + 0.5) / density
    on_edges = (corners[:, None, :] + fractions[None, :, None] * sides[:, None, :]).reshape(-1, 3)
    # every (source point, edge point) pair
    starts = np.repeat(origins, len(on_edges), axis=0)
    touches = np.tile(on_edges, (len(origins), 1))
    r_normal, r_offset = scene.normals[receiver], scene.plane_offsets[receiver]
    h_start, h_touch = starts @ r_normal + r_offset, touches @ r_normal + r_offset
    # the receiver's plane beyond the touching point: h(start) and h(touch) on the same side, |h(touch)| smaller
    with np.errstate(divide="ignore", invalid="ignore"):
        t = h_start / (h_start - h_touch)
    ends = starts + t[:, None] * (touches - starts)
    good = np.isfinite(t) & (t > 1.0 + tol) & (np.abs(h_touch) > tol)
    good &= _inside_distances(ends, scene.polygon(receiver), r_normal).min(axis=1) > tol
    s_normal, s_offset = scene.normals[source], scene.plane_offsets[source]
    leaving = ends @ s_normal + s_offset
    good &= (leaving > tol) | (scene.two_sided[source] & (leaving < -tol))
    good &= (h_start > tol) | (scene.two_sided[receiver] & (h_start < -tol))
    if not good.any():
        return None
    starts, touches, ends = starts[good], touches[good], ends[good]
    free = _unoccluded(scene, starts, touches, ends, (source, receiver), tol)
    if not free.any():
        return None
    first = int(np.argmax(free))
    return np.stack([starts[first], touches[first], ends[first]])


def _unoccluded(scene, starts, touches, ends, skip, tol) -> np.ndarray:
    """(N,) bool: segments starts -> ends (N, 3) meeting no polygon except at `touches`, on the polygon's
    boundary (a graze); polygons in `skip` (the source and the receiver) are ignored."""
    free = np.ones(len(starts), dtype=bool)
    for other in range(scene.n_polygons):
        if other in skip:
            continue
        corners = scene.polygon(other)
        normal, offset = scene.normals[other], scene.plane_offsets[other]
        h0, h1 = starts @ normal + offset, ends @ normal + offset
        crossing = ((h0 > tol) & (h1 < -tol)) | ((h0 < -tol) & (h1 > tol))
        if crossing.any():
            with np.errstate(divide="ignore", invalid="ignore"):
                t = np.where(crossing, h0 / (h0 - h1), 0.0)
            points = starts + t[:, None] * (ends - starts)
            nearest = _inside_distances(points, corners, normal).min(axis=1)
            graze = (np.linalg.norm(points - touches, axis=1) <= tol) & (nearest <= tol)
            free &= ~(crossing & (nearest >= -tol) & ~graze)
        for h, end in ((h0, starts), (h1, ends)):
            on = np.abs(h) <= tol
            if on.any():
                covered = _inside_distances(end[on], corners, normal).min(axis=1) >= -tol
                free[np.flatnonzero(on)[covered]] = False
        flat = (np.abs(h0) <= tol) & (np.abs(h1) <= tol)
        for i in np.flatnonzero(flat & free):
            free[i] = not _overlaps_in_plane(starts[i], ends[i], corners, normal, tol)
    return free


def _overlaps_in_plane(start, end, corners, normal, tol) -> bool:
    """Whether a segment lying in a convex polygon's plane overlaps it over more than tol."""
    d0 = _inside_distances(start[None, :], corners, normal)[0]
    d1 = _inside_distances(end[None, :], corners, normal)[0]
    lo, hi = 0.0, 1.0
    for a, b in zip(d0, d1, strict=True):
        # a + s (b - a) >= -tol on the kept part
        if b == a:
            if a < -tol:
                return False
            continue
        s = (-tol - a) / (b - a)
        lo, hi = (max(lo, s), hi) if b > a else (lo, min(hi, s))
    return (hi - lo) * float(np.linalg.norm(end - start)) > tol


def swath_line(vertices: np.ndarray, edges: np.ndarray, codes, s: float) -> tuple[np.ndarray, np.ndarray]:
    """The line of a skeleton arc with generator codes `codes` (vertex v -> v, edge e -> len(vertices) + e,
    -1 padded) at coordinate s of its parameter edge (its lowest edge, 0..1 from that edge's first vertex):
    (point (3,) on the parameter edge, unit direction (3,)). An EV arc's line joins that point to its vertex;
    an EEE arc's line is where the planes through that point and each other edge meet."""
    n_vertices = len(vertices)
    codes = [int(c) for c in codes if c >= 0]
    edge_ids = sorted(c - n_vertices for c in codes if c >= n_vertices)
    a, b = vertices[edges[edge_ids[0]]]
    point = a + s * (b - a)
    vertex_ids = [c for c in codes if c < n_vertices]
    if vertex_ids:
        direction = vertices[vertex_ids[0]] - point
    else:
        planes = [np.cross(vertices[edges[e, 0]] - point, vertices[edges[e, 1]] - point) for e in edge_ids[1:]]
        direction = np.cross(planes[0], planes[1])
    return point, direction / np.linalg.norm(direction)


# ---------------------------------------------------------------------------------------------------------
# Which polygons see each other?


def seen_pairs(scene, samples: int, rng, threshold: float = 1e-12) -> np.ndarray:
    """(P, P) bool, symmetric: polygons p and q see each other when, from some sample point of either (its
    corners and `samples` uniform points of it, all moved off it by 1e-5 of the scene's diagonal, the corners
    towards its centre as well), the exact form factor to the other exceeds `threshold`, counting only points
    strictly in front of the other's plane. Points covered by a polygon pressed against theirs (in its plane,
    facing the other way: a box resting on a table) are left out: a point of contact sees through the contact
    plane in the exact form factors. Evidence at the samples only: visibility through a sliver can be missed."""
    shift = 1e-5 * scene.diagonal
    seen = np.zeros((scene.n_polygons, scene.n_polygons), dtype=bool)
    for p in range(scene.n_polygons):
        corners = scene.polygon(p)
        inward = corners.mean(axis=0) - corners
        corners = corners + shift * inward / np.linalg.norm(inward, axis=1)[:, None]
        points = np.concatenate([corners, receiver_samples(scene, p, samples, rng)])
        points = points[~_pressed(scene, p, points)] + shift * scene.normals[p]
        normals = np.tile(scene.normals[p], (len(points), 1))
        for q in range(scene.n_polygons):
            front = points @ scene.normals[q] + scene.plane_offsets[q] > 0.0
            if q != p and front.any():
                seen[p, q] = exact_form_factors(scene, points[front], normals[front], q).max() > threshold
    return seen | seen.T


def _pressed(scene, polygon: int, points: np.ndarray) -> np.ndarray:
    """(K,) bool: the points of `polygon` inside (edges included) another polygon lying in its plane and
    facing the other way."""
    tol = RELATIVE_TOLERANCE * scene.diagonal
    pressed = np.zeros(len(points), dtype=bool)
    for other in range(scene.n_polygons):
        if other == polygon or scene.normals[other] @ scene.normals[polygon] > -1.0 + 1e-9:
            continue
        inside = np.abs(points @ scene.normals[other] + scene.plane_offsets[other]) <= 100.0 * tol
        corners = scene.polygon(other)
        for a, b in zip(corners, np.roll(corners, -1, axis=0), strict=True):
            inside &= np.cross(b - a, points - a) @ scene.normals[other] >= -tol
        pressed |= inside
    return pressed
