"""The link oracle (seed 000 sections 4.2.2 and 6.4): which light transfers a region of a receiver must gather
exactly, and which it may take from the interpolation of coarser vertices.

A vertex created inside a leaf triangle T either links to a source exactly or inherits the source's effective
form factor from T's corners by barycentric interpolation (the lazy-wavelet Delta B of that transfer is zero,
section 3.2). The cost of inheriting transfer q is estimated two ways:

* a rigorous bound rho_T Y(X_q) F_max(T, q), with F_max an upper bound of the unoccluded point-to-polygon form
  factor over T: the exact and the interpolated form factors both lie in [0, F_max] (occlusion only lowers a
  form factor and interpolation stays between its corners' values);
* the error measured at T's samples (checks.py), trusted only when q is far from T compared with T's size, so
  that the unoccluded form factor is smooth over T and no peak can hide between the samples (the radiometric
  part of the oracle; shadows are what the samples see).

The transfers of each triangle are sorted by cost and the cheapest are inherited while their costs add up to at
most the allowance the solver gives (a fraction of the JND), so what a vertex inherits stays imperceptible.
Emitters are never inherited: direct light is exact at every vertex.

F_max(T, q) = min(1, A_q / (pi d^2)) with d a lower bound of the distance between T and q: the larger of the
gap between their bounding spheres and of the distance from T's bounding sphere to q's plane.
"""

from __future__ import annotations

import numpy as np

from .perception import LUMINANCE_WEIGHTS

# receiver regions processed at once: the (T, P) cost matrix of a chunk stays a few tens of MB
_CHUNK = 4096
# a source is far from a region when their distance is at least this many times the region's radius
_FAR = 2.0


def distance_bounds(centres, radii, scene) -> np.ndarray:
    """(T, P) float64 >= 0: lower bounds of the distance from any point of each region (bounding spheres
    centres (T, 3), radii (T,)) to each polygon of the scene."""
    source_radii = np.array(
        [np.linalg.norm(scene.polygon(q) - scene.centroids[q], axis=1).max() for q in range(scene.n_polygons)]
    )
    gap = np.linalg.norm(centres[:, None, :] - scene.centroids[None], axis=2) - source_radii[None]
    plane = np.abs(centres @ scene.normals.T + scene.plane_offsets[None])
    return np.maximum(np.maximum(gap, plane) - radii[:, None], 0.0)


def form_factor_bounds(distances, areas) -> np.ndarray:
    """(T, P) upper bounds of the unoccluded form factor from regions to sources at least `distances` (T, P)
    away, of areas (P,)."""
    with np.errstate(divide="ignore"):
        bound = areas[None] / (np.pi * np.square(distances))
    return np.minimum(bound, 1.0)


def exact_transfers(
    centres, radii, reflectance, scene, source_radiosity, emitters, allowance, live=None, measured=None
) -> np.ndarray:
    """(T, P) bool: the sources each receiver region must link exactly.

    centres (T, 3), radii (T,): bounding spheres of the regions (leaf triangles); reflectance (T, 3) of their
    polygons; scene: the core.scene.Scene; source_radiosity (2 P, 3): what each polygon side radiates;
    emitters (P,) bool: always exact; allowance (T,): the luminance-weighted radiosity error the inherited
    transfers of each region may cost together; live (T, P) bool: the transfers still in question (default
    all; the others are inherited already); measured: None, or (T, P) sparse errors of each transfer measured
    at the regions' samples, used where the source is far.
    """
    n_sources = scene.n_polygons
    radiated = (np.asarray(source_radiosity) @ LUMINANCE_WEIGHTS).reshape(n_sources, 2).max(axis=1)
    rho = np.asarray(reflectance).max(axis=1)
    out = np.empty((len(centres), n_sources), dtype=bool)
    for start in range(0, len(centres), _CHUNK):
        stop = min(start + _CHUNK, len(centres))
        distances = distance_bounds(centres[start:stop], radii[start:stop], scene)
        cost = rho[start:stop, None] * radiated[None] * form_factor_bounds(distances, scene.areas)
        if measured is not None:
            far = distances >= _FAR * radii[start:stop, None]
            cost = np.where(far, measured[start:stop].toarray(), cost)
        chunk_live = np.ones_like(cost, dtype=bool) if live is None else live[start:stop]
        out[start:stop] = select_exact(cost, chunk_live, emitters, allowance[start:stop])
    return out


def select_exact(cost, live, always, allowance) -> np.ndarray:
    """(T, P) bool: the live transfers of each region that must be linked exactly.

    cost (T, P) float64: what inheriting each transfer may cost; live (T, P) bool: the transfers still in
    question; always (P,) bool: sources linked exactly whenever live; allowance (T,): what the inherited live
    transfers of each region may cost together. The cheapest are inherited first.
    """
    cost = np.where(live, cost, 0.0)
    cost[:, always] = np.where(live[:, always], np.inf, 0.0)
    order = np.argsort(cost, axis=1, kind="stable")
    spent = np.cumsum(np.take_along_axis(cost, order, axis=1), axis=1)
    exact = np.empty_like(live)
    np.put_along_axis(exact, order, spent > np.asarray(allowance)[:, None], axis=1)
    return exact & live
