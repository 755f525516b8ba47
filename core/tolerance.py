"""The one tolerance object: every epsilon of core, relative to the scene's bounding-box diagonal.

DESIGN.md section 4: no literal epsilons elsewhere. A scene scaled by 1e-3 or 1e4 gets the same relative
tolerances, hence the same classifications (coplanarity, grazing, zero area) and the same results.
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tolerance:
    """Epsilons for one scene.

    scale: the scene's bounding-box diagonal (metres or any unit); every length epsilon is a multiple of it.
    """

    scale: float
    relative: float = 1e-9
    planarity_relative: float = 1e-7
    cosine: float = 1e-12
    snap_lengths: float = 16.0
    curve_relative: float = 1e-6

    @property
    def length(self) -> float:
        """Two points closer than this are the same point; a point this close to a plane lies on it."""
        return self.relative * self.scale

    @property
    def planarity(self) -> float:
        """A polygon whose vertices stray further than this from its best plane is split into triangles."""
        return self.planarity_relative * self.scale

    @property
    def area(self) -> float:
        """Areas below this are zero (a square of side `length`)."""
        return self.length * self.length

    @property
    def snap(self) -> float:
        """Mesh features (points, segment ends) closer than this to a mesh vertex or side are moved onto it,
        and shorter segment pieces are dropped: slivers thinner than a few `length` leave "is this point on
        that side" without a consistent answer between neighbouring elements."""
        return self.snap_lengths * self.length

    @property
    def curve(self) -> float:
        """Largest distance between a sampled curve (the trace of an EEE swath, a quadric) and its polyline."""
        return self.curve_relative * self.scale

    @staticmethod
    def for_points(points: np.ndarray) -> "Tolerance":
        """The tolerance of a set of points (N, 3): scale = their bounding-box diagonal (1 if degenerate)."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if len(pts) == 0:
            return Tolerance(scale=1.0)
        diagonal = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        return Tolerance(scale=diagonal if diagonal > 0.0 else 1.0)
