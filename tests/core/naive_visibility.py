"""Independent exact views for the tests: central projection + shapely polygon booleans + Lambert.

Written separately from core.visibility (different frame, numpy clipping, GEOS booleans, its own Lambert sum);
DESIGN.md section 5, oracle 3.
"""

import numpy as np
import shapely
from shapely.geometry import Polygon
from shapely.geometry.polygon import orient


def lambert_form_factor(point, normal, rings):
    """Projected solid angle / pi of a planar region given as consistently oriented 3-D rings."""
    total = 0.0
    for ring in rings:
        r = np.asarray(ring, dtype=float) - point
        r_next = np.roll(r, -1, axis=0)
        cross = np.cross(r, r_next)
        norm = np.linalg.norm(cross, axis=1)
        ok = norm > 0.0
        angle = np.arctan2(norm[ok], np.einsum("ij,ij->i", r[ok], r_next[ok]))
        total += float(np.sum(angle * (cross[ok] @ normal) / norm[ok]))
    return abs(total) / (2.0 * np.pi)


def _clip_by_plane(polygon, plane_normal, plane_offset):
    """Part of a convex 3-D polygon with plane_normal . x + plane_offset >= 0."""
    if len(polygon) == 0:
        return polygon
    kept = []
    values = polygon @ plane_normal + plane_offset
    for i in range(len(polygon)):
        j = (i + 1) % len(polygon)
        if values[i] >= 0:
            kept.append(polygon[i])
        if values[i] * values[j] < 0:
            kept.append(polygon[i] + values[i] / (values[i] - values[j]) * (polygon[j] - polygon[i]))
    return np.array(kept).reshape(-1, 3)


def oracle_form_factor(point, normal, source, blockers, within=None):
    """Exact form factor from (point, normal) to the convex polygon `source` (K, 3) behind `blockers`; with
    `within` (a (M, 3) polygon in the source's plane), to the part of the source inside it only."""
    point = np.asarray(point, dtype=float)
    normal = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    source = np.asarray(source, dtype=float)
    plane_normal = np.cross(source[1] - source[0], source[2] - source[0])
    plane_normal /= np.linalg.norm(plane_normal)
    plane_offset = -plane_normal @ source[0]
    height = plane_normal @ point + plane_offset
    if abs(height) < 1e-12:
        return 0.0
    if height < 0:
        plane_normal, plane_offset, height = -plane_normal, -plane_offset, -height

    visible_source = _clip_by_plane(source, normal, -normal @ point)
    if len(visible_source) < 3:
        return 0.0
    e1 = visible_source[1] - visible_source[0]
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(plane_normal, e1)
    origin = visible_source[0]

    def to_2d(points3):
        return np.stack([(points3 - origin) @ e1, (points3 - origin) @ e2], axis=1)

    region = Polygon(to_2d(visible_source)).buffer(0)
    centre = visible_source.mean(axis=0)
    shadows = []
    for blocker in blockers:
        piece = np.asarray(blocker, dtype=float)
        for i in range(len(visible_source)):
            a = visible_source[i] - point
            b = visible_source[(i + 1) % len(visible_source)] - point
            side = np.cross(a, b)
            if side @ (centre - point) < 0:
                side = -side
            piece = _clip_by_plane(piece, side, -side @ point)
        piece = _clip_by_plane(piece, plane_normal, plane_offset)
        if len(piece) < 3:
            continue
        depth = height - (piece @ plane_normal + plane_offset)
        if np.any(depth <= 0):
            continue
        projected = point + (piece - point) * (height / depth)[:, None]
        shadow = Polygon(to_2d(projected)).buffer(0)
        if not shadow.is_empty:
            shadows.append(shadow)
    if shadows:
        region = region.difference(shapely.union_all(shadows))
    if within is not None:
        region = region.intersection(Polygon(to_2d(np.asarray(within, dtype=float))).buffer(0))
    rings = []
    parts = getattr(region, "geoms", [region])
    for part in parts:
        if part.is_empty or part.geom_type != "Polygon":
            continue
        part = orient(part, 1.0)
        for ring in [part.exterior, *part.interiors]:
            xy = np.asarray(ring.coords)[:-1]
            rings.append(origin + xy[:, :1] * e1 + xy[:, 1:] * e2)
    return lambert_form_factor(point, normal, rings)


def naive_shaft_blockers(scene, receiver: int, source: int) -> set:
    """The polygons reaching more than tol.length inside the convex hull of a receiver and a source polygon
    (scipy's Qhull for the hull, each polygon clipped by every face plane moved inward), and those lying in
    the source's plane over part of it: what core.visibility.shaft_blockers must list at least."""
    from scipy.spatial import ConvexHull

    eps = scene.tol.length
    corners = np.concatenate([scene.polygon(receiver), scene.polygon(source)])
    faces = ConvexHull(corners).equations  # rows (n, d), n . x + d <= 0 inside
    found = set()
    for candidate in range(scene.n_polygons):
        if candidate in (receiver, source):
            continue
        polygon = scene.polygon(candidate)
        if np.all(np.abs(polygon @ scene.normals[source] + scene.plane_offsets[source]) <= eps):
            # in the source's plane: listed when it overlaps the source (it may cover part of it)
            keep = np.argsort(np.abs(scene.normals[source]))[:2]
            if Polygon(polygon[:, keep]).intersection(Polygon(scene.polygon(source)[:, keep])).area > 0.0:
                found.add(candidate)
            continue
        for face in faces:
            polygon = _clip_by_plane(polygon, -face[:3], -face[3] - eps)
        if len(polygon) >= 3:
            found.add(candidate)
    return found
