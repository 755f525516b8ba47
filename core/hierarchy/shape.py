"""Where a free point goes so that the triangles around it stay well shaped (seed 000 section 3.1).

A free point is a sample whose exact position does not matter (a refinement point inserted without a grid);
segment ends, segment crossings and light maxima inserted with a grid are never moved. Inside an element's
constrained Delaunay triangulation a free point is joined to the element's ring (its corners and the points
already on its sides), whose pieces are constraints: a point in the thin wedge along a piece makes a
triangle with a tiny angle there whatever the triangulation does. Such a point is moved onto the piece
(where matching shares it with the neighbour) or onto the piece's nearer end.
"""

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ShapeSettings:
    """How far free points move to keep triangles well shaped; both are ratios, hence scale-free.

    snap_angle_degrees: a free point that would make, with a ring piece, a triangle whose angle at the piece's
        end is below this lies in that piece's thin wedge and is moved onto the piece. 0 keeps every point.
    merge_fraction: a point moved onto a piece lands on the piece's nearer end when it would be within this
        fraction of the piece's length from it (a side point there would make slivers on both sides); two
        free points closer than this fraction of their distance to the ring are one point.
    """

    snap_angle_degrees: float = 10.0
    merge_fraction: float = 0.2

    @property
    def enabled(self) -> bool:
        return self.snap_angle_degrees > 0.0

    @property
    def wedge_slope(self) -> float:
        """tan(snap angle): the width of a piece's thin wedge per unit of distance along the piece."""
        return math.tan(math.radians(self.snap_angle_degrees))


def wedge_target(point: np.ndarray, ring_xy: np.ndarray, settings: ShapeSettings, snap: float) -> tuple:
    """Where free `point` (2,) goes among the pieces ring_xy[i] -> ring_xy[i + 1] of a convex ring (n, 2).

    A point within `snap` (the length tolerance's snapping distance) of a piece is always on it. Returns
    ("vertex", i): ring vertex i; ("piece", i, s): the point at parameter s in (0, 1) of piece i; ("free",):
    the point stays where it is.
    """
    u = ring_xy
    w = np.roll(ring_xy, -1, axis=0)
    e = w - u
    length = np.sqrt(np.einsum("ij,ij->i", e, e))
    s = np.clip(np.einsum("ij,ij->i", point - u, e) / (length * length), 0.0, 1.0)
    foot = u + s[:, None] * e
    d = np.hypot(*(point - foot).T)
    along_u = s * length
    along_w = length - along_u
    # The smaller of the triangle's angles at the two ends is at the end further from the foot.
    thin = (d < settings.wedge_slope * np.maximum(along_u, along_w)) | (d <= snap)
    if not thin.any():
        return ("free",)
    i = int(np.argmin(np.where(thin, d, np.inf)))
    reach = max(settings.merge_fraction * length[i], snap)
    if along_u[i] <= reach and along_u[i] <= along_w[i]:
        return ("vertex", i)
    if along_w[i] <= reach:
        return ("vertex", (i + 1) % len(ring_xy))
    return ("piece", i, float(s[i]))
