"""Naive, obviously-correct references for core.raycast: every polygon tested, plain numpy, no BVH.

The contact rules are the contract of core.raycast, re-derived in a 2-D frame of each polygon's plane. The
occlusion reference counts interior crossings only, so it is meant for segments in general position (the
random tests); grazing configurations are tested against hand-derived answers.
"""

import numpy as np

from core.raycast import CONTACT_EDGE, CONTACT_INTERIOR, CONTACT_NONE, CONTACT_SLIDING, CONTACT_VERTEX


def _frame(normal):
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = np.cross(normal, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(normal, u)


def naive_contacts(scene, polygon, starts, ends):
    """(kind (N,) int8, t (N,)) of N open segments starts-ends (N, 3) with one polygon, by the rules of
    core.raycast, computed in a 2-D frame of the polygon's plane."""
    tol = scene.tol.length
    normal = scene.normals[polygon]
    corners = scene.polygon(polygon)
    u, v = _frame(normal)
    flat = np.stack([corners @ u, corners @ v], axis=1)
    edges = np.roll(flat, -1, axis=0) - flat
    outward = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]
    starts = np.asarray(starts, dtype=np.float64)
    ends = np.asarray(ends, dtype=np.float64)
    h0 = starts @ normal + scene.plane_offsets[polygon]
    h1 = ends @ normal + scene.plane_offsets[polygon]
    kind = np.full(len(starts), CONTACT_NONE, dtype=np.int8)
    t = np.zeros(len(starts))

    crossing = ((h0 > tol) & (h1 < -tol)) | ((h0 < -tol) & (h1 > tol))
    with np.errstate(divide="ignore", invalid="ignore"):
        tc = np.where(crossing, h0 / (h0 - h1), 0.0)
    points = starts + tc[:, None] * (ends - starts)
    q = np.stack([points @ u, points @ v], axis=1)
    # signed distances (N, K) of the crossing points to the edge lines, positive outside (CCW in u, v)
    distance = np.einsum("nkj,kj->nk", q[:, None, :] - flat[None, :, :], outward)
    corner_gap = np.linalg.norm(points[:, None, :] - corners[None, :, :], axis=2).min(axis=1)
    near = (distance >= -tol).sum(axis=1)
    inside = ~np.any(distance > tol, axis=1)
    vertex = crossing & ((corner_gap <= tol) | (inside & (near >= 2)))
    edge = crossing & ~vertex & inside & (near == 1)
    interior = crossing & ~vertex & inside & (near == 0)
    kind[interior] = CONTACT_INTERIOR
    kind[edge] = CONTACT_EDGE
    kind[vertex] = CONTACT_VERTEX
    t[crossing] = tc[crossing]

    # in the plane: clip the open parameter range by every edge line grown by tol
    in_plane = (np.abs(h0) <= tol) & (np.abs(h1) <= tol)
    for i in np.flatnonzero(in_plane):
        length = np.linalg.norm(ends[i] - starts[i])
        if length <= 2 * tol:
            continue
        lo, hi = tol / length, 1.0 - tol / length
        entry = lo  # where it enters the polygon itself (not grown)
        a = np.array([starts[i] @ u, starts[i] @ v])
        b = np.array([ends[i] @ u, ends[i] @ v])
        for k in range(len(flat)):
            f0 = (a - flat[k]) @ outward[k]
            rate = (b - a) @ outward[k]
            if rate == 0.0:
                if f0 > tol:
                    lo, hi = 1.0, 0.0
            elif rate > 0:
                hi = min(hi, (tol - f0) / rate)
            else:
                lo = max(lo, (tol - f0) / rate)
                entry = max(entry, -f0 / rate)
        if lo <= hi:
            kind[i], t[i] = CONTACT_SLIDING, min(max(entry, lo), hi)
    return kind, t


def naive_segments_occluded(scene, starts, ends, exclude=None):
    """(N,) bool: the open segment crosses the interior of a polygon not excluded (general position)."""
    result = np.zeros(len(starts), dtype=bool)
    for polygon in range(scene.n_polygons):
        kind, _ = naive_contacts(scene, polygon, starts, ends)
        hit = kind == CONTACT_INTERIOR
        if exclude is not None:
            hit &= np.all(np.asarray(exclude) != polygon, axis=1)
        result |= hit
    return result


def naive_first_hits(scene, origins, directions, t_max):
    """Nearest contact of each ray origin + t direction, t in (0, t_max[i]]: polygon, t, kind
    (ties within tol.length go to the lower kind, then the lower polygon id)."""
    ends = origins + t_max[:, None] * directions
    kinds, ts = [], []
    for polygon in range(scene.n_polygons):
        kind, t = naive_contacts(scene, polygon, origins, ends)
        kinds.append(kind)
        ts.append(np.where(kind == CONTACT_NONE, np.inf, t))
    kinds, ts = np.array(kinds).T, np.array(ts).T
    n = len(origins)
    polygon = np.full(n, -1, dtype=np.int64)
    t_hit = np.full(n, np.inf)
    kind = np.zeros(n, dtype=np.int8)
    same = scene.tol.length / np.linalg.norm(ends - origins, axis=1)
    for i in range(n):
        if not np.isfinite(ts[i]).any():
            continue
        close = np.flatnonzero(ts[i] <= ts[i].min() + same[i])
        best = min(close, key=lambda p: (kinds[i, p], p))
        polygon[i], t_hit[i], kind[i] = best, ts[i, best] * t_max[i], kinds[i, best]
    return polygon, t_hit, kind


def corner_rectangle_ff(a, b, c):
    """Form factor from a differential area to a parallel a x b rectangle facing it, at height c above a
    corner (the textbook closed form, e.g. Howell's catalogue B-3): with X = a/c, Y = b/c,
    F = 1/(2 pi) [X/sqrt(1+X^2) atan(Y/sqrt(1+X^2)) + Y/sqrt(1+Y^2) atan(X/sqrt(1+Y^2))]."""
    x, y = a / c, b / c
    return (
        x / np.sqrt(1 + x * x) * np.arctan(y / np.sqrt(1 + x * x))
        + y / np.sqrt(1 + y * y) * np.arctan(x / np.sqrt(1 + y * y))
    ) / (2 * np.pi)


def parallel_rectangle_ff(point, height, x0, x1, y0, y1):
    """Form factor from a differential area at `point` (x, y) with normal +z to the rectangle
    [x0, x1] x [y0, y1] at height `height` above it, by adding and subtracting corner rectangles."""
    px, py = point

    def signed(dx, dy):
        # a rectangle from the foot of the normal to (dx, dy), signed by the quadrant it lies in
        return np.sign(dx) * np.sign(dy) * corner_rectangle_ff(abs(dx), abs(dy), height)

    return signed(x1 - px, y1 - py) - signed(x0 - px, y1 - py) - signed(x1 - px, y0 - py) + signed(x0 - px, y0 - py)
