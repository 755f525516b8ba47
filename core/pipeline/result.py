"""The solver's result (DESIGN.md section 3): the leaf triangulation, radiosity at its vertices, the inserted
discontinuities and the statistics, with the linear reconstruction at arbitrary surface points."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import VisradError

# point-triangle pairs per batch of the point location (bounds its memory to a few tens of MB)
_BATCH_ENTRIES = 1 << 20


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
        out = np.zeros((len(pts), 3))
        keys = polys * 2 + side
        for key in np.unique(keys):
            idx = np.nonzero(keys == key)[0]
            tri = self.triangles[(self.triangle_polygon * 2 + self.triangle_side) == key]
            if not len(tri):
                raise VisradError(f"radiosity_at: polygon {key // 2} side {key % 2} has no result triangles")
            a, b, c = (self.vertices[tri[:, k]] for k in range(3))
            batch = max(1, _BATCH_ENTRIES // len(tri))
            for start in range(0, len(idx), batch):
                part = idx[start : start + batch]
                coords = _barycentric(a, b, c, pts[part])
                best = np.argmax(coords.min(axis=2), axis=1)
                w = np.clip(coords[np.arange(len(part)), best], 0.0, None)
                w /= w.sum(axis=1, keepdims=True)
                out[part] = np.einsum("qk,qkc->qc", w, self.radiosity[tri[best]])
        return out


def _barycentric(a, b, c, points) -> np.ndarray:
    """(Q, T, 3) barycentric coordinates of points (Q, 3) in triangles a, b, c (T, 3), in each plane."""
    e1 = b - a
    e2 = c - a
    d = points[:, None, :] - a[None]
    d11 = np.einsum("ij,ij->i", e1, e1)
    d12 = np.einsum("ij,ij->i", e1, e2)
    d22 = np.einsum("ij,ij->i", e2, e2)
    p1 = np.einsum("qtj,tj->qt", d, e1)
    p2 = np.einsum("qtj,tj->qt", d, e2)
    den = d11 * d22 - d12 * d12
    v = (d22 * p1 - d12 * p2) / den
    w = (d11 * p2 - d12 * p1) / den
    return np.stack([1.0 - v - w, v, w], axis=2)
