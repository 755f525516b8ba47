"""Grid-like subdivision of an element (seed 000 section 6.2, first two subdivisions).

The grid is a triangular lattice aligned with the element's longest side, so that its constrained Delaunay
triangulation is made of nearly equilateral triangles; its step is a function of the element's size.
Grid points too close to externally supplied points (light maxima, section 6.3), to constrained segments or
to points already on the element's sides are skipped, so the mesh stays nearly regular around them.

Every element of a grid step calls these functions once, so they are numba kernels: numpy's per-call
overhead on arrays of three corners used to be most of a grid step.
"""

import math
from dataclasses import dataclass

import numpy as np
from numba import njit


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
    keep_away = np.ascontiguousarray(keep_away, dtype=np.float64).reshape(-1, 2)
    return _side_grid(float(a[0]), float(a[1]), float(b[0]), float(b[1]), float(step), keep_away, float(radius),
                      float(slack))  # fmt: skip


@njit(cache=True)
def _side_grid(ax, ay, bx, by, step, keep_away, radius, slack):
    length = math.hypot(bx - ax, by - ay)
    count = int(math.floor((length + slack) / step + 0.5))
    if count <= 1:
        return np.zeros(0)
    t = np.empty(count - 1)
    kept = 0
    for i in range(1, count):
        ti = i / count
        x = ax + ti * (bx - ax)
        y = ay + ti * (by - ay)
        far = True
        for m in range(len(keep_away)):
            if math.sqrt((x - keep_away[m, 0]) ** 2 + (y - keep_away[m, 1]) ** 2) <= radius - slack:
                far = False
                break
        if far:
            t[kept] = ti
            kept += 1
    return t[:kept]


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
    return _interior_grid(
        np.ascontiguousarray(corners, dtype=np.float64).reshape(-1, 2),
        float(step),
        np.ascontiguousarray(keep_away_points, dtype=np.float64).reshape(-1, 2),
        np.ascontiguousarray(keep_away_segments, dtype=np.float64).reshape(-1, 2, 2),
        float(radius),
        float(slack),
    )


@njit(cache=True)
def _segment_distance(x, y, ax, ay, bx, by):
    """Distance from (x, y) to the closed segment a b (a point when a = b)."""
    ux, uy = bx - ax, by - ay
    length2 = ux * ux + uy * uy
    t = 0.0
    if length2 > 0.0:
        t = min(1.0, max(0.0, ((x - ax) * ux + (y - ay) * uy) / length2))
    return math.sqrt((x - (ax + t * ux)) ** 2 + (y - (ay + t * uy)) ** 2)


@njit(cache=True)
def _interior_grid(corners, step, keep_points, keep_segments, radius, slack):
    k = len(corners)
    sides = np.empty((k, 2))
    lengths = np.empty(k)
    for i in range(k):
        j = (i + 1) % k
        sides[i, 0] = corners[j, 0] - corners[i, 0]
        sides[i, 1] = corners[j, 1] - corners[i, 1]
        lengths[i] = math.sqrt(sides[i, 0] ** 2 + sides[i, 1] ** 2)
    top = lengths.max()
    longest = 0
    while lengths[longest] < top - slack:
        longest += 1
    count = max(1, int(math.floor((lengths[longest] + slack) / step + 0.5)))
    dx = lengths[longest] / count
    # No point of a convex polygon is further than 2 area / perimeter from its boundary.
    twice_area = 0.0
    for i in range(k):
        twice_area += corners[i, 0] * (corners[i, 1] + sides[i, 1]) - corners[i, 1] * (corners[i, 0] + sides[i, 0])
    if twice_area / lengths.sum() <= 0.5 * dx - slack:
        return np.zeros((0, 2))
    ox, oy = corners[longest, 0], corners[longest, 1]
    axis_x, axis_y = sides[longest, 0] / lengths[longest], sides[longest, 1] / lengths[longest]
    normal_x, normal_y = -axis_y, axis_x
    x_min, x_max, y_max = np.inf, -np.inf, -np.inf
    for i in range(k):
        lx = (corners[i, 0] - ox) * axis_x + (corners[i, 1] - oy) * axis_y
        ly = (corners[i, 0] - ox) * normal_x + (corners[i, 1] - oy) * normal_y
        x_min, x_max, y_max = min(x_min, lx), max(x_max, lx), max(y_max, ly)
    dy = dx * np.sqrt(3.0) / 2.0
    n_rows = int(np.floor((y_max + slack) / dy))
    first_column = int(np.floor(x_min / dx)) - 1
    last_column = int(np.ceil(x_max / dx)) + 1
    out = np.empty((max(0, n_rows) * max(0, last_column - first_column + 1), 2))
    kept = 0
    for row in range(1, n_rows + 1):
        y = row * dy
        for column in range(first_column, last_column + 1):
            x = column * dx + (row % 2) * (0.5 * dx)
            px = ox + x * axis_x + y * normal_x
            py = oy + x * axis_y + y * normal_y
            inside = np.inf
            for i in range(k):
                distance = (sides[i, 0] * (py - corners[i, 1]) - sides[i, 1] * (px - corners[i, 0])) / lengths[i]
                inside = min(inside, distance)
            if inside <= 0.5 * dx - slack:
                continue
            near = np.inf
            for m in range(len(keep_points)):
                near = min(near, math.sqrt((px - keep_points[m, 0]) ** 2 + (py - keep_points[m, 1]) ** 2))
            for s in range(len(keep_segments)):
                near = min(near, _segment_distance(px, py, keep_segments[s, 0, 0], keep_segments[s, 0, 1],
                                                   keep_segments[s, 1, 0], keep_segments[s, 1, 1]))  # fmt: skip
            if near <= radius - slack:
                continue
            out[kept, 0] = px
            out[kept, 1] = py
            kept += 1
    return out[:kept]
