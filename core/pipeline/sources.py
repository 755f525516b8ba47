"""Source refinement (seed 000 sections 4.2 and 5.3): a receiver gathers from the parts of a source whose
radiosity varies, not only from the source's average.

A link gathers B_avg(q) x F(x, q). Where the radiosity of q varies, the light that reaches x is the integral of
B over the part of q that x sees, and near a wall corner or a lit spot the average is far from it. A link whose
possible error rho(x) F(x, q) (max_q B - min_q B) exceeds a fraction of the just noticeable difference is
replaced by links to the elements of q's hierarchy, descending per receiver while the bound of an element (times
how much the point-to-area kernel varies over it) is too large (core.visibility.exact_cut_form_factors): exact
form factors to the visible part of each element, which share out the link's form factor. Each element radiates
the average of its leaves (the pull of section 3.2 below the polygon level), so the gather reads the hierarchy of
the source at the depth the receiver needs.

Settings.source_refinement turns it on (off by default). Measured on the Cornell box (3 iterations): 1 338 of
2 934 vertex sides refine some link, and the links grow from about 12 000 to 942 000, 94 % of them to leaves of
the first grid level (each polygon's first level has hundreds of elements: the tree lacks coarse levels between
the polygon and its grid). On a floor lit by a small lamp, the light it reflects onto a wall is within 0.1 JND of
a quadrature reference, against 6.5 JND (47 %) when gathered from the floor's average (tests/core/test_sources.py).

Columns. A link's column is 2 e + side for an element e of the hierarchy; input polygons are elements 0..P-1,
so polygon columns keep their meaning and element columns come after them.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..visibility import exact_cut_form_factors
from .links import BACK, LinkSet, _inside_limit
from .perception import LUMINANCE_WEIGHTS


def fold_to_polygons(links: LinkSet, element_polygon: np.ndarray) -> LinkSet:
    """The same links with every element column replaced by its polygon's column (form factors add up)."""
    column = 2 * element_polygon[links.column // 2] + links.column % 2
    if np.array_equal(column, links.column):
        return links
    return LinkSet(links.point, column, links.form_factor)


def leaf_ancestors(mesh, element_parent: np.ndarray, polygon_count: int) -> tuple:
    """(leaf triangle (M,), ancestor element (M,)): every leaf triangle of the export with each of its elements
    from itself up to (and without) its input polygon (elements 0..polygon_count-1)."""
    leaves = np.arange(len(mesh.triangles))
    current = mesh.triangle_element.copy()
    pairs_leaf, pairs_element = [], []
    while len(leaves):
        inner = current >= polygon_count
        pairs_leaf.append(leaves[inner])
        pairs_element.append(current[inner])
        leaves, current = leaves[inner], element_parent[current[inner]]
    return np.concatenate(pairs_leaf), np.concatenate(pairs_element)


def element_variation(mesh, shown: np.ndarray, radiosity: np.ndarray, element_parent: np.ndarray,
                      polygon_count: int) -> np.ndarray:
    """(E, 2) float64: the luminance-weighted range (max - min) of the radiosity over each element's shown leaf
    vertices, per side (radiosity rows 2 v + side); 0 for elements with no shown leaf."""
    luminance = (radiosity @ LUMINANCE_WEIGHTS).reshape(-1, 2)
    low = np.full((len(element_parent), 2), np.inf)
    high = np.full((len(element_parent), 2), -np.inf)
    corners = luminance[mesh.triangles[shown]]  # (T, 3, 2)
    leaf, element = leaf_ancestors(mesh, element_parent, polygon_count)
    keep = shown[leaf]
    leaf_index = np.cumsum(shown) - 1
    leaf, element = leaf_index[leaf[keep]], element[keep]
    np.minimum.at(low, element, corners.min(axis=1)[leaf])
    np.maximum.at(high, element, corners.max(axis=1)[leaf])
    polygon = mesh.triangle_polygon[shown]
    np.minimum.at(low, polygon, corners.min(axis=1))
    np.maximum.at(high, polygon, corners.max(axis=1))
    return np.where(high >= low, high - low, 0.0)


def element_pull(mesh, shown: np.ndarray, element_parent: np.ndarray, polygon_count: int, elements: np.ndarray,
                 n_rows: int):
    """(2 K, n_rows) sparse: for each element of `elements` (K,) (non-polygon ids), each side's area-weighted
    average of its shown leaf triangles' vertex means (rows 2 k + side of the vertex rows 2 v + side)."""
    corners = mesh.vertices[mesh.triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    area = np.where(shown, area, 0.0)
    position = np.full(len(element_parent), -1, dtype=np.int64)
    position[elements] = np.arange(len(elements))
    leaf, element = leaf_ancestors(mesh, element_parent, polygon_count)
    k = position[element]
    leaf, k = leaf[k >= 0], k[k >= 0]
    total = np.bincount(k, area[leaf], minlength=len(elements))
    weight = np.repeat(area[leaf] / (3.0 * np.maximum(total[k], np.finfo(float).tiny)), 3)
    vertex = mesh.triangles[leaf].ravel()
    row = np.repeat(k, 3)
    rows = np.concatenate([2 * row, 2 * row + 1])
    cols = np.concatenate([2 * vertex, 2 * vertex + 1])
    return sp.csr_matrix((np.concatenate([weight, weight]), (rows, cols)), shape=(2 * len(elements), n_rows))


def refine_sources(scene, bvh, hierarchy, links: LinkSet, positions, row_polygon, interior, facing,
                   variation, limits) -> tuple:
    """Replace the links whose source is too uneven for its average by links to elements of that source.

    links: polygon-level LinkSet of vertex rows (point = 2 v + side); positions (2 N, 3), row_polygon (2 N,),
    interior (2 N, 3) per row; variation (E, 2) from element_variation; limits (2 N,): the largest error
    F x variation a row's link may carry (rho and the JND folded in; inf: never refined). A link is refined when
    F x variation of its source polygon exceeds the row's limit and the polygon is subdivided. Returns
    (links, refined count): the kept links and the element links that replace the others.
    """
    vertices, first_child, child_count = hierarchy.element_tree()
    polygon_count = scene.n_polygons
    source = links.column // 2
    side = links.column % 2
    subdivided = child_count[:polygon_count] > 0
    bound = links.form_factor * variation[source, side]
    refine = subdivided[source] & (bound > limits[links.point])
    if not refine.any():
        return links, 0
    triangles = hierarchy.vertex_positions()[np.maximum(vertices, 0)]
    kept = LinkSet(links.point[~refine], links.column[~refine], links.form_factor[~refine])
    parts = [kept]
    rows, columns, totals = links.point[refine], links.column[refine], links.form_factor[refine]
    for q, s in sorted(set(zip((columns // 2).tolist(), (columns % 2).tolist(), strict=True))):
        group = columns == 2 * q + s
        chosen, total = rows[group], totals[group]
        polygons = row_polygon[chosen]
        receiver_side = chosen % 2
        normals = scene.normals[polygons] * np.where(receiver_side == BACK, -1.0, 1.0)[:, None]
        at = _inside_limit(scene, positions[chosen], polygons, receiver_side, facing, interior[chosen])
        roots = np.arange(first_child[q], first_child[q] + child_count[q])
        point, element, ff = exact_cut_form_factors(
            scene, at, normals, q, (triangles, first_child, child_count, roots), variation[:, s], limits[chosen],
            bvh=bvh,
        )
        # The cut shares out the link's form factor: where the point sits on a discontinuity of the form factor
        # (a corner against a touching box), the limit taken now and the one its link was made with can differ,
        # and the row's other links were made with the latter.
        cut_total = np.bincount(point, ff, len(chosen))
        seen = cut_total[point] > 0.0
        parts.append(LinkSet(chosen[point[seen]], 2 * element[seen] + s,
                             ff[seen] * (total[point[seen]] / cut_total[point[seen]])))  # fmt: skip
        unseen = cut_total == 0.0
        parts.append(LinkSet(chosen[unseen], np.full(unseen.sum(), 2 * q + s), total[unseen]))
    return LinkSet.concatenate(parts), int(refine.sum())
