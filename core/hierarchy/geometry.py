"""Small 2-D predicates of the hierarchy: barycentric coordinates, clipping (a numba kernel), distances, angles."""

import numpy as np
from numba import njit


def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """z of the cross product of 2-D vectors (..., 2) x (..., 2) -> (...)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def barycentric(triangles: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points (M, 2) in triangles (C, 3, 2): (M, C, 3) float64.

    Triangles must be non-degenerate; the coordinates sum to one and reproduce linear functions exactly
    up to rounding.
    """
    a = triangles[None, :, 0, :]
    e1 = triangles[None, :, 1, :] - a
    e2 = triangles[None, :, 2, :] - a
    d = points[:, None, :] - a
    det = cross2(e1, e2)
    l1 = cross2(d, e2) / det
    l2 = cross2(e1, d) / det
    return np.stack([1.0 - l1 - l2, l1, l2], axis=-1)


def clip_segment_to_polygon(polygons: np.ndarray, p: np.ndarray, q: np.ndarray) -> tuple:
    """Cyrus-Beck clipping of p + t (q - p), t in [0, 1], to convex counter-clockwise polygons (C, K, 2).

    Returns (t_in, t_out), each (C,) float64; a polygon misses the segment where t_out <= t_in.
    """
    corners = np.ascontiguousarray(polygons, dtype=np.float64)
    return _clip_segment(corners, float(p[0]), float(p[1]), float(q[0]), float(q[1]))


@njit(cache=True)
def _clip_segment(corners, px, py, qx, qy):
    count, k = corners.shape[0], corners.shape[1]
    t_in = np.zeros(count)
    t_out = np.ones(count)
    dx, dy = qx - px, qy - py
    for c in range(count):
        for i in range(k):
            j = (i + 1) % k
            ex = corners[c, j, 0] - corners[c, i, 0]
            ey = corners[c, j, 1] - corners[c, i, 1]
            num = ex * (py - corners[c, i, 1]) - ey * (px - corners[c, i, 0])
            den = ex * dy - ey * dx
            if den > 0.0:
                t_in[c] = max(t_in[c], -num / den)
            elif den < 0.0:
                t_out[c] = min(t_out[c], -num / den)
            elif num < 0.0:
                t_out[c] = -np.inf
                break
    return t_in, t_out


def side_parameters(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple:
    """For points (M, 2) and lines a[j] b[j] (S, 2): the parameter t (M, S) of the orthogonal projection
    along a -> b and the distance (M, S) to the closed segment."""
    ab = b - a
    length2 = np.einsum("ij,ij->i", ab, ab)
    ap = points[:, None, :] - a[None, :, :]
    t = np.einsum("msk,sk->ms", ap, ab) / length2
    closest = a[None, :, :] + np.clip(t, 0.0, 1.0)[..., None] * ab[None, :, :]
    return t, np.linalg.norm(points[:, None, :] - closest, axis=2)


def triangle_min_angles(corners: np.ndarray) -> np.ndarray:
    """Smallest interior angle, in degrees, of triangles (T, 3, D) with D = 2 or 3: (T,) float64."""
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]

    def angle(at, x, y):
        u = x - at
        w = y - at
        cosine = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
        return np.degrees(np.arccos(np.clip(cosine, -1.0, 1.0)))

    return np.minimum(np.minimum(angle(a, b, c), angle(b, c, a)), angle(c, a, b))


def triangle_areas_2d(corners: np.ndarray) -> np.ndarray:
    """Signed areas of triangles (T, 3, 2): (T,) float64, positive when counter-clockwise."""
    return 0.5 * cross2(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
