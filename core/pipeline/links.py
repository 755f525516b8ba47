"""Point-polygon links (seed 000 section 4.2.1): which polygon side each receiver point gathers from, and the
form factor of every link, exact (occluded, from exact views) or by jittered rays.

Sides. Every polygon has a front side (its normal); two-sided polygons (open surfaces, DESIGN.md section 2)
also have a back side. A *column* is a polygon side, 2 p + side; a receiver point on side s of polygon p has
normal (+/-) n_p and gathers from a polygon q through q's side that faces it: the front when the point is in
front of q's plane, the back (two-sided q only) when behind; points in q's plane exchange nothing with q.
The back of a one-sided polygon faces the inside of a closed object and neither emits nor reflects.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import VisradError
from ..raycast import jittered_form_factors
from ..visibility import ShaftBlockers, exact_pair_form_factors, shaft_blockers

FRONT = 0
BACK = 1
# corner-to-plane heights computed at once by facing_sources (128 MiB of float64)
_HEIGHTS_PER_CHUNK = 1 << 24
# the share of the available memory one array of a stage may take
_MEMORY_SHARE = 0.8


@dataclass(frozen=True)
class LinkSet:
    """L point-polygon links: point (L,) int64 index into the caller's points; column (L,) int64 source
    polygon side 2 q + side; form_factor (L,) float64 >= 0."""

    point: np.ndarray
    column: np.ndarray
    form_factor: np.ndarray

    def __len__(self) -> int:
        return len(self.point)

    @staticmethod
    def empty() -> LinkSet:
        return LinkSet(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))

    @staticmethod
    def concatenate(parts: list[LinkSet]) -> LinkSet:
        if not parts:
            return LinkSet.empty()
        return LinkSet(
            np.concatenate([p.point for p in parts]),
            np.concatenate([p.column for p in parts]),
            np.concatenate([p.form_factor for p in parts]),
        )


def facing_sources(scene) -> np.ndarray:
    """(P, 2, P) bool: [p, s, q] when some of polygon q lies strictly in front of side s of polygon p and some
    of p strictly on a radiating side of q (its front, or its back when q is two-sided): the polygon pairs
    that can exchange light at all. Raises VisradError, before allocating, when the P^2 pairs cannot fit in
    the memory available."""
    count = scene.n_polygons
    check_memory(4 * count * count, f"the pairs of the scene's {count:,} polygons")
    eps = scene.tol.length
    offsets = scene.polygon_offsets
    corners = scene.polygon_points
    owner = np.repeat(np.arange(count), np.diff(offsets))
    above = np.zeros((count, count), dtype=bool)  # above[q, p]: q reaches in front of p
    below = np.zeros_like(above)
    step = max(1, _HEIGHTS_PER_CHUNK // max(count, 1))
    for start in range(0, len(corners), step):
        stop = min(start + step, len(corners))
        # signed distances of these corners to the plane of every polygon
        heights = corners[start:stop] @ scene.normals.T + scene.plane_offsets[None, :]
        np.logical_or.at(above, owner[start:stop], heights > eps)
        np.logical_or.at(below, owner[start:stop], heights < -eps)
    # p reaches in front of q: above[p, q] = above.T[q, p]
    radiates = above | (below & scene.two_sided[None, :])
    result = np.zeros((count, 2, count), dtype=bool)
    result[:, FRONT, :] = above.T & radiates
    result[:, BACK, :] = below.T & radiates & scene.two_sided[:, None]
    np.fill_diagonal(result[:, FRONT, :], False)
    np.fill_diagonal(result[:, BACK, :], False)
    return result


def check_memory(needed: int, what: str) -> None:
    """Raise VisradError when `needed` bytes for `what` exceed what the machine has available (Linux's
    MemAvailable; elsewhere the check is skipped)."""
    available = _available_memory()
    if available is not None and needed > _MEMORY_SHARE * available:
        raise VisradError(
            f"{what} need about {_size(needed)} and {_size(available)} of memory are available: exclude objects "
            "from VisRad or lower their subdivision"
        )


def _size(count: int) -> str:
    return f"{count / 2**30:.1f} GiB" if count >= 2**30 else f"{count / 2**20:.0f} MiB"


def _available_memory() -> int | None:
    try:
        with open("/proc/meminfo") as meminfo:
            for line in meminfo:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        return None
    return None


# the polygon ids the blocker lists of PairShafts may hold (256 MiB of int64); pairs beyond use the BVH
_SHAFT_BUDGET = 1 << 25


class PairShafts:
    """The blocker lists of receiver-source polygon pairs (seed 000 section 5.3: the polygon-polygon links carry
    the blocker lists from which views at new vertices are computed, and detect full visibility), each pair's
    computed on first use (core.visibility.shaft_blockers) and kept: refinement asks for the same pairs at every
    iteration."""

    def __init__(self, scene, bvh, budget: int = _SHAFT_BUDGET):
        self.scene = scene
        self.bvh = bvh
        self.budget = budget
        self._keys = np.empty(0, dtype=np.int64)  # receiver * P + source, in the order the pairs were computed
        self._order = np.empty(0, dtype=np.int64)  # argsort of _keys
        self.lists = ShaftBlockers(np.zeros(1, dtype=np.int64), np.empty(0, dtype=np.int64))

    def __len__(self) -> int:
        return len(self._keys)

    def lookup(self, receivers, sources) -> np.ndarray:
        """(N,) int64: the index in self.lists of each (receiver, source) polygon pair, computing new pairs; -1
        for pairs left to the BVH once the lists hold `budget` polygon ids (huge scenes)."""
        count = self.scene.n_polygons
        keys = np.asarray(receivers, dtype=np.int64) * count + np.asarray(sources, dtype=np.int64)
        wanted = np.unique(keys)
        known = self._find(wanted) >= 0
        new = wanted[~known]
        if len(new) and len(self.lists.ids) < self.budget:
            found = shaft_blockers(self.scene, new // count, new % count, self.bvh)
            total = self.lists.offsets[-1]
            self.lists = ShaftBlockers(
                np.concatenate([self.lists.offsets, total + found.offsets[1:]]),
                np.concatenate([self.lists.ids, found.ids]),
            )
            self._keys = np.concatenate([self._keys, new])
            self._order = np.argsort(self._keys, kind="stable")
        return self._find(keys)

    def _find(self, keys: np.ndarray) -> np.ndarray:
        if not len(self._keys):
            return np.full(len(keys), -1, dtype=np.int64)
        sorted_keys = self._keys[self._order]
        at = np.minimum(np.searchsorted(sorted_keys, keys), len(sorted_keys) - 1)
        return np.where(sorted_keys[at] == keys, self._order[at], -1)


def compute_links(
    scene, bvh, points, polygons, sides, facing, settings, interior=None, wanted=None, evaluated=False, shafts=None
) -> LinkSet:
    """The links of receiver points: every source column the point can see, with its form factor.

    points (N, 3) float64 on their polygons; polygons (N,) int64; sides (N,) int8 FRONT/BACK; facing from
    facing_sources; interior (N, 3): a point inside the visible part of each point's polygon near it (the
    centroid of a leaf triangle around it; default the polygon's centroid), the direction of the limit taken
    at points on a touching boundary; wanted (N, P) bool: the only sources to link each point with (default
    all); evaluated: the points are already where their form factors are evaluated (by _inside_limit), and
    interior is not used; shafts: a PairShafts whose blocker lists the exact views are computed from (default
    the BVH's polygons in each point's pyramid; the form factors are the same). Links with a zero form factor
    (the source entirely hidden) are dropped.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    polygons = np.asarray(polygons, dtype=np.int64)
    sides = np.asarray(sides, dtype=np.int64)
    normals = scene.normals[polygons] * np.where(sides == BACK, -1.0, 1.0)[:, None]
    eps = scene.tol.length
    at = points
    if not evaluated:
        inside = scene.centroids[polygons] if interior is None else interior
        at = _inside_limit(scene, points, polygons, sides, facing, inside)
    candidates = facing[polygons, sides, :]
    if wanted is not None:
        candidates &= wanted
    # pairs by source, then point: the order of the links
    source, point = np.nonzero(candidates.T)
    height = np.einsum("ij,ij->i", at[point], scene.normals[source]) + scene.plane_offsets[source]
    side = np.where(height > eps, FRONT, BACK)
    keep = (height > eps) | ((height < -eps) & scene.two_sided[source])
    source, point, side = source[keep], point[keep], side[keep]
    if settings.exact:
        lists = None if shafts is None else (shafts.lookup(polygons[point], source), shafts.lists)
        ff = exact_pair_form_factors(scene, at[point], normals[point], source, bvh=bvh, shafts=lists)
    else:
        ff = np.empty(len(point))
        bounds = np.searchsorted(source, np.arange(scene.n_polygons + 1))
        for q in np.flatnonzero(np.diff(bounds)):
            pairs = slice(bounds[q], bounds[q + 1])
            ff[pairs] = jittered_form_factors(
                scene, bvh, at[point[pairs]], normals[point[pairs]], q, settings.form_factors, settings.seed
            )
    seen = ff > 0.0
    return LinkSet(point[seen], 2 * source[seen] + side[seen], ff[seen])


# How far inside its polygon a point lying in another polygon's plane is evaluated: a small fraction of the way
# to its interior point (so that, at a corner where several planes meet, it is clear of each of them), and at
# least a few length tolerances (the visibility code takes closer points for points of the plane).
_LIMIT_LENGTHS = 4.0
_LIMIT_FRACTION = 1e-5


def _inside_limit(scene, points, polygons, sides, facing, interior) -> np.ndarray:
    """Where each point's form factors are evaluated: the point itself, or, when it lies in the plane of a
    polygon it touches that rises in front of it (a floor corner in a wall's plane, the edge of a box top
    against a box standing on it), a point just inside its own polygon, toward `interior`: the form factor is
    discontinuous there and the radiosity of the polygon is the limit from its (visible) inside. The other
    faces of a convex corner lie behind the point and change nothing."""
    eps = scene.tol.length
    out = points.copy()
    for start in range(0, len(points), _CHUNK):
        pts = points[start : start + _CHUNK]
        own = polygons[start : start + _CHUNK]
        near = np.all(
            (pts[:, None, :] >= scene.polygon_min[None] - eps) & (pts[:, None, :] <= scene.polygon_max[None] + eps),
            axis=2,
        )
        in_plane = np.abs(pts @ scene.normals.T + scene.plane_offsets[None, :]) <= eps
        in_front = facing[own, sides[start : start + _CHUNK]]
        touching = np.any(near & in_plane & in_front, axis=1)
        if not touching.any():
            continue
        idx = np.nonzero(touching)[0]
        inward = interior[start + idx] - pts[idx]
        distance = np.linalg.norm(inward, axis=1)
        step = np.minimum(np.maximum(_LIMIT_FRACTION * distance, _LIMIT_LENGTHS * eps), 0.5 * distance)
        out[start + idx] = pts[idx] + (step / np.maximum(distance, eps))[:, None] * inward
    return out


_CHUNK = 1024
