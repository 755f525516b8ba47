"""The solver's result (DESIGN.md section 3): the leaf triangulation, radiosity at its vertices, the inserted
discontinuities and the statistics, with the linear reconstruction at arbitrary surface points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import VisradError
from .interpolation import locate


@dataclass(frozen=True, eq=False)
class Result:
    """A radiosity solution.

    vertices (N, 3) float64 world space; triangles (T, 3) int64, counter-clockwise seen from the side whose
    radiosity they carry (a two-sided polygon has a second set of triangles, wound the other way, on vertices
    of its own); triangle_polygon (T,) int64 scene polygon; triangle_side (T,) int8 0 front / 1 back;
    radiosity (N, 3) float64 B in W/m^2; discontinuities: polygon -> (M, 2, 3) segments inserted on it;
    stats: seconds per stage, links, triangles, vertices, iterations, peak bytes, ...
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_polygon: np.ndarray
    triangle_side: np.ndarray
    radiosity: np.ndarray
    discontinuities: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)
    normals: np.ndarray | None = None

    def radiosity_at(self, points, polygons, sides=None) -> np.ndarray:
        """The linear reconstruction of B at surface points (Q, 3) on polygons (Q,) int (sides (Q,) 0/1,
        default front): barycentric interpolation in the leaf triangle containing each point (the nearest one
        for points a rounding error outside). Returns (Q, 3) float64."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        polys = np.asarray(polygons, dtype=np.int64).reshape(-1)
        if len(polys) != len(pts):
            raise VisradError(f"radiosity_at: {len(pts)} points but {len(polys)} polygons")
        side = np.zeros(len(pts), np.int64) if sides is None else np.asarray(sides, dtype=np.int64).reshape(-1)
        if len(side) != len(pts):
            raise VisradError(f"radiosity_at: {len(pts)} points but {len(side)} sides")
        keys = polys * 2 + side
        triangle_keys = self.triangle_polygon * 2 + self.triangle_side
        missing = np.setdiff1d(keys, triangle_keys)
        if len(missing):
            key = int(missing[0])
            raise VisradError(f"radiosity_at: polygon {key // 2} side {key % 2} has no result triangles")
        best, _, weights = locate(self.vertices, self.triangles, triangle_keys, pts, keys)
        return np.einsum("qk,qkc->qc", weights, self.radiosity[self.triangles[best]])
