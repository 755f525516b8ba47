"""The refinement test of leaf triangles (seed 000 sections 6.2 and 6.4) and what it remembers between iterations.

Each leaf triangle is checked at its samples (centroid and edge midpoints, interpolation.py): the exact form
factors of the *live* transfers of the leaf against the interpolation of its corners' effective form factors.
The difference weighted by the radiosity each source radiates gives the leaf's error (does it need subdividing,
and where) and the error of each transfer (which sources the vertices inserted in the leaf must link exactly,
oracle.select_exact). The live transfers of a new leaf are those its parent leaf had to link exactly: a transfer
interpolated well enough at the parent's samples stays inherited below it, which is the lazy linking of
section 4.2.2. The sample form factors of a leaf never change, so they are computed once per leaf and carried
while the leaf exists (a leaf is known by its three corner vertices).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .interpolation import SAMPLE_WEIGHTS, locate
from .links import BACK, FRONT, LinkSet, _inside_limit, compute_links
from .perception import LUMINANCE_WEIGHTS

N_SAMPLES = len(SAMPLE_WEIGHTS)
# leaf sides whose samples are linked at once (progress and cancel get a say this often)
_CHUNK_LEAVES = 1024


@dataclass(frozen=True)
class LeafChecks:
    """Per leaf triangle of a hierarchy export (T leaves, P polygons, S = N_SAMPLES samples).

    corners: (T, 3) int64 the leaf's vertices, sorted (its identity across iterations);
    live: (T, P) bool the sources checked at the leaf's samples;
    sampled: (2 T S, 2 P) sparse float64 exact form factors of the live sources at the samples, row
        (2 t + side) S + s, column 2 q + side of q;
    known: (T,) bool whether the leaf's rows of `sampled` are computed.
    """

    corners: np.ndarray
    live: np.ndarray
    sampled: sp.csr_matrix
    known: np.ndarray

    @staticmethod
    def fresh(triangles, live) -> LeafChecks:
        count, n_sources = live.shape
        return LeafChecks(
            np.sort(triangles, axis=1),
            live,
            sp.csr_matrix((2 * count * N_SAMPLES, 2 * n_sources)),
            np.zeros(count, dtype=bool),
        )


def sample_points(mesh) -> np.ndarray:
    """(T, S, 3) the samples of every leaf triangle."""
    return np.einsum("sk,tkc->tsc", SAMPLE_WEIGHTS, mesh.vertices[mesh.triangles])


def complete_steps(checks: LeafChecks, mesh, scene, bvh, facing, settings, shafts=None):
    """Compute the sample form factors of the leaves not known yet (both sides of two-sided polygons); a
    generator yielding the fraction done and returning the completed LeafChecks.

    A sample shared by leaves (an edge midpoint between two leaves of the same polygon side, evaluated at the
    same point) is linked once, to the sources live at any of them; each leaf keeps those live at it."""
    todo = np.flatnonzero(~checks.known)
    if not len(todo):
        return checks
    samples = sample_points(mesh)
    back = todo[scene.two_sided[mesh.triangle_polygon[todo]]]
    leaves = np.concatenate([todo, back])
    sides = np.concatenate([np.full(len(todo), FRONT), np.full(len(back), BACK)])
    # by polygon and side, so that leaves sharing edges fall into the same chunk
    order = np.lexsort((leaves, sides, mesh.triangle_polygon[leaves]))
    leaves, sides = leaves[order], sides[order]
    parts = [checks.sampled.tocoo()]
    for start in range(0, len(leaves), _CHUNK_LEAVES):
        chunk, chunk_sides = leaves[start : start + _CHUNK_LEAVES], sides[start : start + _CHUNK_LEAVES]
        links = _link_samples(checks, mesh, samples, chunk, chunk_sides, scene, bvh, facing, settings, shafts)
        leaf, sample = links.point // N_SAMPLES, links.point % N_SAMPLES
        rows = (2 * chunk[leaf] + chunk_sides[leaf]) * N_SAMPLES + sample
        parts.append(sp.coo_matrix((links.form_factor, (rows, links.column)), shape=checks.sampled.shape))
        yield min(start + _CHUNK_LEAVES, len(leaves)) / len(leaves)
    # the rows of the leaves not known were empty: one sum of the parts
    sampled = sp.csr_matrix(
        (
            np.concatenate([part.data for part in parts]),
            (np.concatenate([part.row for part in parts]), np.concatenate([part.col for part in parts])),
        ),
        shape=checks.sampled.shape,
    )
    return LeafChecks(checks.corners, checks.live, sampled, np.ones(len(checks.known), dtype=bool))


def _link_samples(checks, mesh, samples, leaves, sides, scene, bvh, facing, settings, shafts) -> LinkSet:
    """The links of the samples of leaves (C,) on sides (C,) to the sources live at their leaf (point: the
    sample's index c S + s), each distinct sample point linked once."""
    points = samples[leaves].reshape(-1, 3)
    polygons = np.repeat(mesh.triangle_polygon[leaves], N_SAMPLES)
    point_sides = np.repeat(sides, N_SAMPLES)
    interior = np.repeat(samples[leaves, 0], N_SAMPLES, axis=0)
    at = _inside_limit(scene, points, polygons, point_sides, facing, interior)
    # a sample is the same for its leaves when they share polygon, side and evaluation point (an edge midpoint is
    # the same sum of the same two corners either way round)
    key = np.column_stack([polygons.astype(np.float64), point_sides.astype(np.float64), at])
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.ravel()
    by_point = np.argsort(inverse, kind="stable")
    starts = np.searchsorted(inverse[by_point], np.arange(len(first) + 1))
    live = np.repeat(checks.live[leaves], N_SAMPLES, axis=0)
    wanted = np.logical_or.reduceat(live[by_point], starts[:-1], axis=0)
    distinct = compute_links(
        scene, bvh, at[first], polygons[first], point_sides[first], facing, settings, wanted=wanted, evaluated=True,
        shafts=shafts,
    )
    # every link of a distinct point goes to each sample sharing it where its source is live
    count = np.diff(starts)[distinct.point]
    link = np.repeat(np.arange(len(distinct)), count)
    offset = np.arange(len(link)) - np.repeat(np.cumsum(count) - count, count)
    sample = by_point[starts[distinct.point][link] + offset]
    column = distinct.column[link]
    keep = live[sample, column // 2]
    return LinkSet(sample[keep], column[keep], distinct.form_factor[link][keep])


def measure(checks: LeafChecks, mesh, gather, sources, reflectance, two_sided, visible) -> tuple:
    """The interpolation errors of every leaf at its samples, for its live transfers.

    gather (2 N, 2 P) sparse: the effective form factors of the vertex sides; sources (2 P, 3): what each
    polygon side radiates; reflectance (P, 3) and two_sided (P,) of the scene's polygons; visible (T,) bool:
    leaves not hidden by contact (the others have no error). Returns (errors (T,), worst (T, 3), per_source
    (T, P) sparse): the largest luminance-weighted radiosity error of a sample, that sample, and for each source
    the largest error of its transfer alone.
    """
    count = len(mesh.triangles)
    n_rows = 2 * count * N_SAMPLES
    row = np.arange(n_rows)
    leaf = row // (2 * N_SAMPLES)
    side = (row // N_SAMPLES) % 2
    sample = row % N_SAMPLES
    corners = 2 * mesh.triangles[leaf] + side[:, None]
    spread = sp.csr_matrix(
        (SAMPLE_WEIGHTS[sample].ravel(), (np.repeat(row, 3), corners.ravel())), shape=(n_rows, gather.shape[0])
    )
    interpolated = (spread @ gather).tocoo()
    keep = checks.live[leaf[interpolated.row], interpolated.col // 2]
    interpolated = sp.csr_matrix(
        (interpolated.data[keep], (interpolated.row[keep], interpolated.col[keep])), shape=checks.sampled.shape
    )
    difference = (checks.sampled - interpolated).tocoo()
    polygon = mesh.triangle_polygon
    rho = reflectance[polygon[leaf]]
    counted = (side == FRONT) | two_sided[polygon[leaf]]
    counted &= visible[leaf]
    flux = sp.csr_matrix((difference.data, (difference.row, difference.col)), shape=difference.shape) @ sources
    error = np.abs(flux * rho) @ LUMINANCE_WEIGHTS
    error[~counted] = 0.0
    per_leaf = error.reshape(count, 2 * N_SAMPLES)
    pick = np.argmax(per_leaf, axis=1)
    errors = per_leaf[np.arange(count), pick]
    samples = sample_points(mesh)
    worst = samples[np.arange(count), pick % N_SAMPLES]
    entry_leaf = leaf[difference.row]
    entry_error = np.abs(difference.data) * np.einsum(
        "ec,ec,c->e", rho[difference.row], sources[difference.col], LUMINANCE_WEIGHTS
    )
    entry_error[~counted[difference.row]] = 0.0
    key = entry_leaf * len(reflectance) + difference.col // 2
    order = np.argsort(key, kind="stable")
    key, entry_error = key[order], entry_error[order]
    first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]]) if len(key) else np.zeros(0, np.int64)
    largest = np.maximum.reduceat(entry_error, first) if len(key) else np.zeros(0)
    per_source = sp.csr_matrix(
        (largest, (key[first] // len(reflectance), key[first] % len(reflectance))), shape=(count, len(reflectance))
    )
    return errors, worst, per_source


def carry(checks: LeafChecks, mesh, exact, new_mesh, always) -> LeafChecks:
    """The checks of a refined hierarchy's leaves: a leaf that existed keeps its checks; a new leaf is known
    later and checks the sources its parent (the old leaf holding its centroid) links exactly, and `always`
    (P,) bool (the emitters)."""
    new_corners = np.sort(new_mesh.triangles, axis=1)
    _, inverse = np.unique(np.concatenate([checks.corners, new_corners]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    old_id, new_id = inverse[: len(checks.corners)], inverse[len(checks.corners) :]
    lookup = np.full(inverse.max() + 1, -1, dtype=np.int64)
    lookup[old_id] = np.arange(len(old_id))
    previous = lookup[new_id]
    kept = previous >= 0
    centroids = new_mesh.vertices[new_mesh.triangles].mean(axis=1)
    live = np.empty((len(new_corners), checks.live.shape[1]), dtype=bool)
    live[kept] = checks.live[previous[kept]]
    fresh = np.flatnonzero(~kept)
    if len(fresh):
        parent, _, _ = locate(
            mesh.vertices, mesh.triangles, mesh.triangle_polygon, centroids[fresh], new_mesh.triangle_polygon[fresh]
        )
        live[fresh] = exact[parent] | always[None, :]
    rows_per_leaf = 2 * N_SAMPLES
    new_rows = (np.flatnonzero(kept)[:, None] * rows_per_leaf + np.arange(rows_per_leaf)).ravel()
    old_rows = (previous[kept][:, None] * rows_per_leaf + np.arange(rows_per_leaf)).ravel()
    shape = (len(new_corners) * rows_per_leaf, checks.sampled.shape[0])
    select = sp.csr_matrix((np.ones(len(new_rows)), (new_rows, old_rows)), shape=shape)
    known = kept & checks.known[np.maximum(previous, 0)]
    return LeafChecks(new_corners, live, (select @ checks.sampled).tocsr(), known)


def links_at_samples(checks: LeafChecks, mesh, points, sides, leaves, wanted, eps) -> tuple[np.ndarray, LinkSet]:
    """The links of points that are samples of leaves already checked: a vertex inserted at a leaf's edge
    midpoint or centroid needs the form factors its leaf's sample got (the same point, the same sources).

    points (N, 3) float64, sides (N,) FRONT/BACK; leaves (N, 2) int64: the leaf of `mesh` holding each point
    and the one sharing the edge it lies on (-1: none); wanted (N, P) bool: the sources each point links
    exactly. A point is found when it lies within eps of a sample of each of its leaves, those leaves are known
    and every wanted source is live at one of them (the sample links only live sources; a missing link is a
    zero form factor). Returns (found (N,) bool, LinkSet with point = index into points, of the found points,
    restricted to wanted).
    """
    count = len(points)
    found = np.ones(count, dtype=bool)
    covered = np.zeros_like(wanted)
    rows = np.full((count, 2), -1, dtype=np.int64)
    samples = sample_points(mesh)
    for k in range(2):
        leaf = leaves[:, k]
        present = leaf >= 0
        at = np.maximum(leaf, 0)
        distance = np.linalg.norm(samples[at] - points[:, None, :], axis=2)
        sample = np.argmin(distance, axis=1)
        matched = present & (distance[np.arange(count), sample] <= eps) & checks.known[at]
        found &= matched | ~present
        rows[matched, k] = (2 * at[matched] + sides[matched]) * N_SAMPLES + sample[matched]
        covered[matched] |= checks.live[at[matched]]
    found &= ~(wanted & ~covered).any(axis=1)
    found &= (rows >= 0).any(axis=1)
    taken = found.repeat(2) & (rows.ravel() >= 0)
    point = np.repeat(np.arange(count), 2)[taken]
    picked = checks.sampled[rows.ravel()[taken]].tocoo()
    point, column, value = point[picked.row], picked.col.astype(np.int64), picked.data
    keep = wanted[point, column // 2]
    point, column, value = point[keep], column[keep], value[keep]
    # a point on a shared edge is a sample of both leaves: one link per source
    _, first = np.unique(point * checks.sampled.shape[1] + column, return_index=True)
    return found, LinkSet(point[first], column[first], value[first])
