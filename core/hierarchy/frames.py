"""Each input polygon's own 2-D frame, and the edges shared between input polygons.

The hierarchy works in the plane of each polygon: a point X (3,) of polygon p has 2-D coordinates
((X - origin[p]) . u[p], (X - origin[p]) . v[p]); u, v are orthonormal and u x v is the polygon's normal,
chosen so that the polygon's corners run counter-clockwise in 2-D.
"""

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree


@dataclass(frozen=True)
class PolygonFrames:
    """Orthonormal planar frames, one per polygon.

    origin, u, v, normal: (P, 3) float64. corners_2d: list of P arrays (K_p, 2) float64, counter-clockwise.
    """

    origin: np.ndarray
    u: np.ndarray
    v: np.ndarray
    normal: np.ndarray
    corners_2d: list

    def to_2d(self, polygon: int, points: np.ndarray) -> np.ndarray:
        """Project points (M, 3) onto polygon's plane: (M, 2) float64 coordinates in its frame."""
        d = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.origin[polygon]
        return np.stack([d @ self.u[polygon], d @ self.v[polygon]], axis=1)

    def to_3d(self, polygons: np.ndarray, points_2d: np.ndarray) -> np.ndarray:
        """Points (M, 2) of polygons (M,) int back to 3-D: (M, 3) float64."""
        polygons = np.asarray(polygons, dtype=np.int64)
        p2 = np.asarray(points_2d, dtype=np.float64).reshape(-1, 2)
        return (
            self.origin[polygons]
            + p2[:, :1] * self.u[polygons]
            + p2[:, 1:2] * self.v[polygons]
        )


def newell_normal(points: np.ndarray) -> np.ndarray:
    """Area vector of a closed polygon (K, 3) (twice the area times the unit normal), Newell's formula."""
    nxt = np.roll(points, -1, axis=0)
    return np.cross(points, nxt).sum(axis=0)


def build_frames(polygons: list, length_tolerance: float) -> PolygonFrames:
    """Frames for polygons given as a list of (K, 3) float64 arrays (planar, convex, K >= 3).

    u follows the first of the longest sides (lengths within length_tolerance tie), so that a scaled scene
    gets the same frames."""
    count = len(polygons)
    origin = np.zeros((count, 3))
    u = np.zeros((count, 3))
    v = np.zeros((count, 3))
    normal = np.zeros((count, 3))
    corners = []
    for i, pts in enumerate(polygons):
        area_vector = newell_normal(pts)
        n = area_vector / np.linalg.norm(area_vector)
        # The longest edge as u keeps the frame well conditioned even for slivers.
        edges = np.roll(pts, -1, axis=0) - pts
        lengths = np.linalg.norm(edges, axis=1)
        longest = int(np.argmax(lengths >= lengths.max() - length_tolerance))
        axis = edges[longest] - n * (edges[longest] @ n)
        axis /= np.linalg.norm(axis)
        origin[i] = pts[0]
        u[i] = axis
        v[i] = np.cross(n, axis)
        normal[i] = n
        d = pts - pts[0]
        corners.append(np.stack([d @ u[i], d @ v[i]], axis=1))
    return PolygonFrames(origin=origin, u=u, v=v, normal=normal, corners_2d=corners)


def shared_edges(polygons: list, length_tolerance: float) -> list:
    """Pairs of polygon sides with the same two endpoints (within length_tolerance).

    Returns a list of (polygon_a, side_a, polygon_b, side_b, reversed) where side k of a polygon runs from
    corner k to corner k+1 and reversed says that side_b runs from side_a's end to its start.
    """
    starts, ends, owners, sides = [], [], [], []
    for p, pts in enumerate(polygons):
        k = len(pts)
        starts.append(pts)
        ends.append(np.roll(pts, -1, axis=0))
        owners.append(np.full(k, p))
        sides.append(np.arange(k))
    if not starts:
        return []
    a = np.concatenate(starts)
    b = np.concatenate(ends)
    owner = np.concatenate(owners)
    side = np.concatenate(sides)
    tree = cKDTree(0.5 * (a + b))
    pairs = []
    for i, j in sorted(tree.query_pairs(length_tolerance)):
        if owner[i] == owner[j]:
            continue
        same = np.linalg.norm(a[i] - a[j]) <= length_tolerance and np.linalg.norm(b[i] - b[j]) <= length_tolerance
        flipped = (
            np.linalg.norm(a[i] - b[j]) <= length_tolerance and np.linalg.norm(b[i] - a[j]) <= length_tolerance
        )
        if same or flipped:
            pairs.append((int(owner[i]), int(side[i]), int(owner[j]), int(side[j]), bool(flipped and not same)))
    return pairs
