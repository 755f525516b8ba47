"""Maxima of the important light transfers (seed 000 section 6.3): where the unoccluded radiosity a source
sends onto a receiver peaks, found by a local search, so that the first subdivision puts a vertex there.

A transfer (source polygon side -> receiver polygon) is important when the disk-disk estimate of the radiosity
it brings at the receiver's centroid is perceptible (Hanrahan et al. 1991 and the JND threshold). Sources are
every polygon side that radiates (emitters and lit surfaces alike: the search is iterated for indirect sources
simply by running it on the current solution). A maximum is kept when it brings a perceptible radiosity and
lies inside the receiver, away from its sides (a vertex there adds nothing to the corners and sides).
"""

from __future__ import annotations

import numpy as np

from ..formfactor import disk_ff_estimate, point_polygon_ff
from .perception import LUMINANCE_WEIGHTS

# The local search: starting step as a fraction of the receiver's longest side, halvings, and how far inside
# (fraction of the longest side) a maximum must be to be inserted.
_START_STEP = 0.25
_HALVINGS = 14
_MAX_MOVES = 200
_INSIDE_FRACTION = 0.05
_DIRECTIONS = np.array([[np.cos(a), np.sin(a)] for a in np.linspace(0.0, 2.0 * np.pi, 8, endpoint=False)])


def transfer_maxima(scene, sources: np.ndarray, threshold: float, receivers, settings):
    """Yield (polygon, points (M, 3)) for each receiver polygon with important maxima.

    sources (2 P, 3): the radiosity each polygon side radiates; threshold: the perceptible luminance-weighted
    radiosity difference; receivers: polygon ids to search.
    """
    radiant = np.nonzero(sources @ LUMINANCE_WEIGHTS > 0.0)[0]
    if not len(radiant):
        return
    power = sources[radiant] @ LUMINANCE_WEIGHTS
    for receiver in np.asarray(receivers, dtype=np.int64):
        found = []
        rho = float(scene.reflectance[receiver] @ LUMINANCE_WEIGHTS)
        corners = scene.polygon(receiver)
        normal = scene.normals[receiver]
        centre = scene.centroids[receiver][None]
        for column, radiated in zip(radiant, power, strict=True):
            source = column // 2
            if source == receiver:
                continue
            side = 1.0 if column % 2 == 0 else -1.0
            height = side * (centre[0] @ scene.normals[source] + scene.plane_offsets[source])
            if height <= scene.tol.length:
                continue
            estimate = disk_ff_estimate(
                centre, normal[None], scene.centroids[source], scene.normals[source], float(scene.areas[source])
            )[0]
            if rho * radiated * estimate < threshold:
                continue
            point, ff = _local_maximum(corners, normal, scene.polygon(source))
            if rho * radiated * ff >= threshold and _inside(point, corners, normal, _INSIDE_FRACTION):
                found.append(point)
        if found:
            yield int(receiver), np.array(found)


def _local_maximum(corners: np.ndarray, normal: np.ndarray, source: np.ndarray) -> tuple:
    """Pattern search for the largest unoccluded form factor to `source` over the convex receiver (K, 3)."""
    u = corners[1] - corners[0]
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    longest = float(np.max(np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)))
    # start at the source centroid's foot on the receiver, pulled inside
    foot = source.mean(axis=0)
    foot = foot - ((foot - corners[0]) @ normal) * normal
    point = foot if _inside(foot, corners, normal, 0.0) else corners.mean(axis=0)
    best = point_polygon_ff(point[None], normal[None], source)[0]
    step = _START_STEP * longest
    halvings = 0
    for _ in range(_MAX_MOVES):
        if halvings == _HALVINGS:
            break
        trial = point + step * (_DIRECTIONS[:, :1] * u + _DIRECTIONS[:, 1:] * v)
        inside = np.array([_inside(t, corners, normal, 0.0) for t in trial])
        if inside.any():
            values = point_polygon_ff(trial[inside], np.repeat(normal[None], inside.sum(), axis=0), source)
            k = int(np.argmax(values))
            if values[k] > best:
                best, point = values[k], trial[inside][k]
                continue
        step *= 0.5
        halvings += 1
    return point, float(best)


def _inside(point: np.ndarray, corners: np.ndarray, normal: np.ndarray, margin_fraction: float) -> bool:
    """Whether point lies in the convex polygon (K, 3), at least margin_fraction x longest side from its sides."""
    sides = np.roll(corners, -1, axis=0) - corners
    lengths = np.linalg.norm(sides, axis=1)
    inward = np.cross(normal[None], sides) / lengths[:, None]
    distance = np.einsum("ij,ij->i", point[None] - corners, inward)
    return bool(distance.min() >= margin_fraction * lengths.max())
