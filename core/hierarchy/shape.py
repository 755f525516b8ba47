"""Where a free point goes so that the triangles around it stay well shaped (seed 000 section 3.1).

A free point is a sample whose exact position does not matter (a point inserted without a grid); segment ends,
segment crossings and light maxima inserted with a grid are never moved. In an element's constrained Delaunay
triangulation a free point is joined to the element's ring (its corners and the points already on its sides),
whose pieces are constraints: near a piece it makes a triangle with a tiny angle whatever the triangulation
does. The hierarchy therefore scores each place a free point could go by the smallest angle of the fan it
would make with the rings it joins (the element's, and the neighbour's when it lands on a side, which
matching then splits), and keeps the point, moves it onto a nearby side, or merges it with a vertex.
"""

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ShapeSettings:
    """How free points are placed to keep triangles well shaped; both are ratios, hence scale-free.

    snap_angle_degrees: a free point stays where it is if its fan keeps every angle at least this large, else
        it moves onto the nearby side piece whose fans (in the element and across) do; 0 keeps every point.
    merge_fraction: when no place reaches the snap angle, a point this close to a vertex of its element,
        relative to the element's longest side, merges with it; further away it takes its best place (the
        element's shape forces a thin triangle there). Two free points of one element closer than this
        fraction of their distance to the element's ring are one point.
    """

    snap_angle_degrees: float = 10.0
    merge_fraction: float = 0.2

    @property
    def enabled(self) -> bool:
        return self.snap_angle_degrees > 0.0


def piece_feet(point: np.ndarray, ring_xy: np.ndarray) -> tuple:
    """Closest points of the pieces ring_xy[i] -> ring_xy[i + 1] of a closed ring (n, 2) to point (2,).

    Returns (s, distance, length): the parameter in [0, 1] of the closest point along each piece, the distance
    to it and the piece's length, each (n,) float64.
    """
    e = np.roll(ring_xy, -1, axis=0) - ring_xy
    length = np.sqrt(np.einsum("ij,ij->i", e, e))
    s = np.clip(np.einsum("ij,ij->i", point - ring_xy, e) / (length * length), 0.0, 1.0)
    foot = ring_xy + s[:, None] * e
    return s, np.hypot(*(point - foot).T), length


def fan_min_angle(apex: np.ndarray, ring_xy: np.ndarray, flat: float) -> float:
    """Smallest angle, in degrees, of the triangles apex, ring[i], ring[i + 1] over a closed ring (n, 2).

    Pieces the apex lies on, or lies within `flat` of the line of, make no triangle (the apex is on that side)
    and are left out. Returns 180 when no triangle is left.
    """
    u = ring_xy - apex
    w = np.roll(ring_xy, -1, axis=0) - apex
    e = w - u
    cross = np.abs(u[:, 0] * w[:, 1] - u[:, 1] * w[:, 0])
    length = np.sqrt(np.einsum("ij,ij->i", e, e))
    real = cross > flat * length
    if not real.any():
        return 180.0
    u, w, e, cross = u[real], w[real], e[real], cross[real]
    at_apex = np.arctan2(cross, np.einsum("ij,ij->i", u, w))
    at_u = np.arctan2(cross, -np.einsum("ij,ij->i", u, e))
    at_w = np.arctan2(cross, np.einsum("ij,ij->i", w, e))
    return math.degrees(float(min(at_apex.min(), at_u.min(), at_w.min())))
