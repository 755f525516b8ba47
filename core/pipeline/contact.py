"""Faces hidden by contact (DESIGN.md section 4): where two polygons lie in one plane facing each other (a box
resting on a floor, two boxes side by side), the touching parts never see anything and never show.

`contact_regions` finds, for every polygon, the convex pieces of it that other polygons cover that way; the
solver inserts their sides into the polygon's mesh (a contact boundary is a discontinuity of the lighting),
drops the leaf triangles inside them from gathering, the pull and the result, and drops polygons covered
entirely.
"""

from __future__ import annotations

import numpy as np


def contact_regions(scene) -> dict:
    """polygon -> list of (K, 3) float64 convex pieces of it covered by a polygon touching it face to face."""
    eps = scene.tol.length
    opposite = scene.normals @ scene.normals.T <= -1.0 + scene.tol.cosine
    same_plane = np.abs(scene.plane_offsets[:, None] + scene.plane_offsets[None, :]) <= eps
    overlap = np.all(
        (scene.polygon_min[:, None, :] <= scene.polygon_max[None, :, :] + eps)
        & (scene.polygon_max[:, None, :] >= scene.polygon_min[None, :, :] - eps),
        axis=2,
    )
    # a closed object enclosing nothing (a card modelled as two faces back to back) is one surface seen from its
    # two sides, not two surfaces in contact: each face shows its own side
    flat = ~scene.solid & ~scene.two_sided
    same_surface = flat[:, None] & (scene.object_ids[:, None] == scene.object_ids[None, :])
    regions: dict[int, list] = {}
    for r, q in zip(*np.nonzero(opposite & same_plane & overlap & ~same_surface), strict=True):
        piece = _clip_convex(scene.polygon(q)[::-1], scene.polygon(r), scene.normals[r], eps)
        if len(piece) >= 3 and _area(piece, scene.normals[r]) > scene.tol.area:
            regions.setdefault(int(r), []).append(piece)
    return regions


def covered_fraction(scene, regions: dict) -> np.ndarray:
    """(P,) float64: the fraction of each polygon's area covered by contact pieces (they never overlap: the
    polygons covering one face would interpenetrate)."""
    fraction = np.zeros(scene.n_polygons)
    for polygon, pieces in regions.items():
        fraction[polygon] = sum(_area(p, scene.normals[polygon]) for p in pieces) / scene.areas[polygon]
    return fraction


def inside_regions(points: np.ndarray, polygons: np.ndarray, scene, regions: dict) -> np.ndarray:
    """(M,) bool: points (M, 3) of polygons (M,) lying strictly inside a contact piece of their polygon."""
    hidden = np.zeros(len(points), dtype=bool)
    eps = scene.tol.length
    for polygon, pieces in regions.items():
        idx = np.nonzero(polygons == polygon)[0]
        if not len(idx):
            continue
        normal = scene.normals[polygon]
        for piece in pieces:
            sides = np.roll(piece, -1, axis=0) - piece
            inward = np.cross(normal[None], sides)
            inward /= np.linalg.norm(inward, axis=1)[:, None]
            depth = np.einsum("mkj,kj->mk", points[idx, None, :] - piece[None], inward)
            hidden[idx] |= depth.min(axis=1) > eps
    return hidden


def _clip_convex(subject: np.ndarray, clip: np.ndarray, normal: np.ndarray, eps: float) -> np.ndarray:
    """The part of convex polygon subject (K, 3) inside convex polygon clip (J, 3), both counter-clockwise
    around normal and in one plane (Sutherland-Hodgman)."""
    out = np.asarray(subject, dtype=np.float64)
    for a, b in zip(clip, np.roll(clip, -1, axis=0), strict=True):
        if len(out) == 0:
            break
        inward = np.cross(normal, b - a)
        inward /= np.linalg.norm(inward)
        depth = (out - a) @ inward
        kept = []
        for k in range(len(out)):
            j = (k + 1) % len(out)
            if depth[k] >= -eps:
                kept.append(out[k])
            if (depth[k] < -eps < depth[j]) or (depth[j] < -eps < depth[k]):
                t = depth[k] / (depth[k] - depth[j])
                kept.append(out[k] + t * (out[j] - out[k]))
        out = np.array(kept).reshape(-1, 3)
    if len(out):
        distinct = np.linalg.norm(out - np.roll(out, 1, axis=0), axis=1) > eps
        out = out[distinct]
    return out


def _area(polygon: np.ndarray, normal: np.ndarray) -> float:
    total = np.zeros(3)
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        total += np.cross(a, b)
    return abs(float(total @ normal)) / 2.0
