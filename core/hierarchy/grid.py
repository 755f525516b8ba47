"""Grid-like subdivision of an element (seed 000 section 6.2, first two subdivisions).

The grid is a triangular lattice aligned with the element's longest side, so that its constrained Delaunay
triangulation is made of nearly equilateral triangles; its step is a function of the element's size.
Grid points too close to externally supplied points (light maxima, section 6.3), to constrained segments or
to points already on the element's sides are skipped, so the mesh stays nearly regular around them.
"""

import math
from dataclasses import dataclass

import numpy as np

from .geometry import cross2, segment_distances

_NO_PARAMETERS = np.zeros(0)
_NO_POINTS = np.zeros((0, 2))


@dataclass(frozen=True)
class GridSettings:
    """How fine the regular subdivision of an element is.

    The step along the element's longest side L is target_spacing_relative x (scene scale), clamped to
    [L / max_divisions, L / min_divisions]: large polygons get more grid cells than small ones, tiny
    elements still get min_divisions. Grid points closer than skip_radius x step to a supplied point or
    segment, or to a vertex already on a side, are not inserted.
    """

    target_spacing_relative: float = 0.05
    min_divisions: int = 2
    max_divisions: int = 16
    skip_radius: float = 0.5

    def step(self, longest_side: float, scene_scale: float) -> float:
        target = self.target_spacing_relative * scene_scale
        return float(np.clip(target, longest_side / self.max_divisions, longest_side / self.min_divisions))


def side_grid_parameters(
    a: np.ndarray, b: np.ndarray, step: float, keep_away: np.ndarray, radius: float, slack: float
) -> np.ndarray:
    """Parameters t in (0, 1) of grid points on side a -> b (2,), evenly spaced about `step` apart,
    without those within `radius` of any point of keep_away (M, 2). Returns (n,) float64, increasing.
    slack (the length tolerance) breaks ties the same way whatever the scene's scale."""
    length = math.hypot(b[0] - a[0], b[1] - a[1])
    count = int(math.floor((length + slack) / step + 0.5))
    if count <= 1:
        return _NO_PARAMETERS
    t = np.arange(1, count) / count
    if len(keep_away) == 0:
        return t
    points = a[None, :] + t[:, None] * (b - a)[None, :]
    far = np.min(np.linalg.norm(points[:, None, :] - keep_away[None, :, :], axis=2), axis=1) > radius - slack
    return t[far]


def interior_grid_points(
    corners: np.ndarray,
    step: float,
    keep_away_points: np.ndarray,
    keep_away_segments: np.ndarray,
    radius: float,
    slack: float,
) -> np.ndarray:
    """Triangular-lattice points strictly inside a convex counter-clockwise polygon corners (K, 2).

    Points closer than half a step to the boundary (they would make slivers against the side points),
    or closer than `radius` to keep_away_points (M, 2) or to keep_away_segments (S, 2, 2), are dropped;
    slack (the length tolerance) resolves the exact ties of regular shapes identically at every scale.
    Returns (N, 2) float64.
    """
    sides = np.concatenate([corners[1:], corners[:1]]) - corners
    lengths = np.sqrt(np.einsum("ij,ij->i", sides, sides))
    longest = int(np.argmax(lengths >= lengths.max() - slack))
    count = max(1, int(math.floor((lengths[longest] + slack) / step + 0.5)))
    dx = lengths[longest] / count
    # No point of a convex polygon is further than 2 area / perimeter from its boundary.
    area = 0.5 * float(cross2(corners, corners + sides).sum())
    if 2.0 * area / lengths.sum() <= 0.5 * dx - slack:
        return _NO_POINTS
    axis = sides[longest] / lengths[longest]
    normal = np.array([-axis[1], axis[0]])
    local = np.stack([(corners - corners[longest]) @ axis, (corners - corners[longest]) @ normal], axis=1)
    dy = dx * np.sqrt(3.0) / 2.0
    rows = np.arange(1, int(np.floor((local[:, 1].max() + slack) / dy)) + 1)
    if len(rows) == 0:
        return _NO_POINTS
    x_min, x_max = local[:, 0].min(), local[:, 0].max()
    columns = np.arange(int(np.floor(x_min / dx)) - 1, int(np.ceil(x_max / dx)) + 2)
    xs = columns[None, :] * dx + (rows[:, None] % 2) * (0.5 * dx)
    ys = np.broadcast_to(rows[:, None] * dy, xs.shape)
    candidates = corners[longest] + xs.reshape(-1, 1) * axis + ys.reshape(-1, 1) * normal
    inside = cross2(sides[None, :, :], candidates[:, None, :] - corners[None, :, :]) / lengths[None, :]
    keep = inside.min(axis=1) > 0.5 * dx - slack
    candidates = candidates[keep]
    if len(candidates) and len(keep_away_points):
        near = np.linalg.norm(candidates[:, None, :] - keep_away_points[None, :, :], axis=2).min(axis=1)
        candidates = candidates[near > radius - slack]
    if len(candidates) and len(keep_away_segments):
        near = segment_distances(candidates, keep_away_segments[:, 0], keep_away_segments[:, 1]).min(axis=1)
        candidates = candidates[near > radius - slack]
    return candidates
