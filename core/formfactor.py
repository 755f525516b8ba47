"""Unoccluded point-to-polygon form factors (Durand et al. 1999, section 4.2.1 and Fig. 9).

Lambert's closed form as written by Baum et al. 1989: the form factor from a differential area at point P
with unit normal N to a polygon with corners x_i is

    F = 1/(2 pi) * N . sum_i gamma_i (R_i x R_i+1) / |R_i x R_i+1|,   R_i = x_i - P,

gamma_i being the angle between R_i and R_i+1. The polygon is first clipped to the hemisphere above the
receiver (the formula needs it), so the result is the projected solid angle over pi, in [0, 1].

Also the disk-to-disk estimate of Hanrahan et al. 1991, used by the refinement oracles of section 6.4.
"""

import numpy as np
from numba import njit

from .errors import SceneError
from .jit import njit_leaf


def point_polygon_ff(points, normals, polygon) -> np.ndarray:
    """Unoccluded form factors from differential areas to one planar convex polygon.

    points: (N, 3) float64 receiver positions; normals: (N, 3) receiver unit normals (normalised here);
    polygon: (K, 3) float64 corners in order (either orientation). Returns (N,) float64 in [0, 1].
    """
    pts = _as_array(points, "points")
    nrm = _as_array(normals, "normals")
    if pts.shape != nrm.shape:
        raise SceneError(f"points {pts.shape} and normals {nrm.shape} must have the same shape")
    poly = _as_array(polygon, "polygon")
    if len(poly) < 3:
        raise SceneError(f"polygon needs at least 3 corners, got {len(poly)}")
    lengths = np.linalg.norm(nrm, axis=1)
    if np.any(lengths == 0.0):
        raise SceneError(f"normal {int(np.flatnonzero(lengths == 0.0)[0])} is zero")
    return _form_factors(pts, nrm / lengths[:, None], poly)


def disk_ff_estimate(points, normals, source_centre, source_normal, source_area: float) -> np.ndarray:
    """Disk-disk estimate of Hanrahan et al. 1991: cos_r cos_s A / (pi r^2 + A), cosines clamped at 0.

    points, normals: (N, 3) float64 receivers; source_centre, source_normal: (3,); source_area > 0.
    The source is taken as two-sided (|cos_s|), like Blender emitters. Returns (N,) float64.
    """
    pts = _as_array(points, "points")
    nrm = _as_array(normals, "normals")
    centre = np.asarray(source_centre, dtype=np.float64).reshape(3)
    axis = np.asarray(source_normal, dtype=np.float64).reshape(3)
    if not source_area > 0.0:
        raise SceneError(f"source_area must be positive, got {source_area}")
    offset = centre[None, :] - pts
    distance2 = np.einsum("ij,ij->i", offset, offset)
    distance = np.sqrt(distance2)
    safe = np.where(distance > 0.0, distance, 1.0)
    cos_r = np.clip(np.einsum("ij,ij->i", nrm, offset) / safe, 0.0, None)
    cos_s = np.abs(offset @ axis) / safe
    return np.where(distance > 0.0, cos_r * cos_s * source_area / (np.pi * distance2 + source_area), 0.0)


def _as_array(values, name: str) -> np.ndarray:
    array = np.ascontiguousarray(values, dtype=np.float64)
    if array.ndim != 2 or array.shape[1] != 3:
        raise SceneError(f"{name} must have shape (N, 3), got {array.shape}")
    if not np.isfinite(array).all():
        raise SceneError(f"{name} contains NaN or infinite values")
    return array


@njit(cache=True)
def _form_factors(points, normals, polygon):
    result = np.empty(len(points))
    buffer = np.empty((len(polygon) + 1, 3))
    for i in range(len(points)):
        count = clip_to_hemisphere(polygon, points[i], normals[i], buffer)
        result[i] = abs(lambert_sum(points[i], normals[i], buffer, count)) / (2.0 * np.pi)
    return result


@njit(cache=True)
def clip_to_hemisphere(polygon, point, normal, out):
    """Clip a convex (K, 3) polygon to normal . (x - point) >= 0; write corners to `out`; return their count.

    `out` needs K + 1 rows. Exact zero is the threshold: corners on the tangent plane add nothing to Lambert.
    """
    k = len(polygon)
    count = 0
    for i in range(k):
        a = polygon[i]
        b = polygon[(i + 1) % k]
        da = normal[0] * (a[0] - point[0]) + normal[1] * (a[1] - point[1]) + normal[2] * (a[2] - point[2])
        db = normal[0] * (b[0] - point[0]) + normal[1] * (b[1] - point[1]) + normal[2] * (b[2] - point[2])
        if da >= 0.0:
            out[count] = a
            count += 1
        if (da > 0.0 and db < 0.0) or (da < 0.0 and db > 0.0):
            t = da / (da - db)
            for c in range(3):
                out[count, c] = a[c] + t * (b[c] - a[c])
            count += 1
    return count


@njit_leaf
def lambert_sum(point, normal, corners, count):
    """Signed sum_i gamma_i N . (R_i x R_i+1)/|R_i x R_i+1| over the first `count` rows of corners (K, 3).

    Divide the absolute value by 2 pi for the form factor. Edges through the point add nothing.
    """
    total = 0.0
    for i in range(count):
        a = corners[i]
        b = corners[(i + 1) % count]
        ax = a[0] - point[0]
        ay = a[1] - point[1]
        az = a[2] - point[2]
        bx = b[0] - point[0]
        by = b[1] - point[1]
        bz = b[2] - point[2]
        cx = ay * bz - az * by
        cy = az * bx - ax * bz
        cz = ax * by - ay * bx
        cross_length = np.sqrt(cx * cx + cy * cy + cz * cz)
        if cross_length == 0.0:
            continue
        gamma = np.arctan2(cross_length, ax * bx + ay * by + az * bz)
        total += gamma * (normal[0] * cx + normal[1] * cy + normal[2] * cz) / cross_length
    return total
