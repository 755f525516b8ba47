"""Source refinement (core/pipeline/sources.py): element averages, ranges and ancestry against plain loops, and
indirect light from an uneven source against a quadrature of the exact direct light it reflects."""

import numpy as np
import pytest

from core.hierarchy import Hierarchy
from core.pipeline import Settings, Solver
from core.pipeline.links import LinkSet
from core.pipeline.perception import LUMINANCE_WEIGHTS
from core.pipeline.sources import element_pull, element_variation, fold_to_polygons, leaf_ancestors
from core.scene import Scene
from core.tolerance import Tolerance
from core.visibility import exact_form_factors
from tests.core.naive_visibility import lambert_form_factor


def refined_hierarchy(seed):
    polygons = [np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]),
                np.array([[0.0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1]])]  # fmt: skip
    h = Hierarchy(polygons, Tolerance.for_points(np.concatenate(polygons)))
    rng = np.random.default_rng(seed)
    h.queue_regular_grid([0, 1])
    h.complete_step()
    for _ in range(2):
        u, v = rng.uniform(0.05, 0.95, size=(2, 6))
        h.insert_points(0, np.stack([u, v, np.zeros(6)], axis=1))
        h.insert_points(1, np.stack([np.zeros(6), u, v], axis=1))
        h.complete_step()
    return h


def ancestors_of(h, element):
    parent = h.element_parent()
    chain = []
    while element >= h.polygon_count:
        chain.append(element)
        element = parent[element]
    return chain


def test_leaf_ancestors_variation_and_pull_match_plain_loops():
    h = refined_hierarchy(3)
    mesh = h.export_leaves()
    parent = h.element_parent()
    rng = np.random.default_rng(4)
    radiosity = rng.uniform(0.0, 2.0, size=(2 * h.vertex_count, 3))
    shown = rng.uniform(size=len(mesh.triangles)) > 0.2
    leaf, element = leaf_ancestors(mesh, parent, h.polygon_count)
    for t in range(len(mesh.triangles)):
        assert sorted(element[leaf == t].tolist()) == sorted(ancestors_of(h, int(mesh.triangle_element[t])))

    variation = element_variation(mesh, shown, radiosity, parent, h.polygon_count)
    luminance = radiosity @ LUMINANCE_WEIGHTS
    below = {e: [t for t in range(len(mesh.triangles)) if shown[t] and (e in ancestors_of(h, int(
        mesh.triangle_element[t])) or e == mesh.triangle_polygon[t])] for e in range(h.element_count)}  # fmt: skip
    for e, leaves in below.items():
        for side in (0, 1):
            values = [luminance[2 * v + side] for t in leaves for v in mesh.triangles[t]]
            expected = max(values) - min(values) if values else 0.0
            assert variation[e, side] == pytest.approx(expected, abs=1e-15), (e, side)

    elements = np.array([e for e in range(h.polygon_count, h.element_count) if below[e]][::7])
    pull = element_pull(mesh, shown, parent, h.polygon_count, elements, 2 * h.vertex_count)
    averaged = pull @ radiosity
    corners = mesh.vertices[mesh.triangles]
    areas = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    for k, e in enumerate(elements.tolist()):
        for side in (0, 1):
            total = sum(areas[t] for t in below[e])
            expected = sum(areas[t] * radiosity[2 * mesh.triangles[t] + side].mean(axis=0) for t in below[e]) / total
            np.testing.assert_allclose(averaged[2 * k + side], expected, rtol=1e-12)


def test_folding_adds_element_links_to_their_polygon():
    element_polygon = np.array([0, 1, 0, 0, 1])
    links = LinkSet(np.array([0, 0, 1, 1]), np.array([0, 5, 4, 9]), np.array([0.1, 0.2, 0.3, 0.4]))
    folded = fold_to_polygons(links, element_polygon)
    np.testing.assert_array_equal(folded.column, [0, 1, 0, 3])
    np.testing.assert_array_equal(folded.form_factor, links.form_factor)


LIGHT = (0.3, 0.7, 0.8, 1.2, 0.5)  # x0, x1, y0, y1, height of a light facing down (two-sided: it emits up too)


def floor_wall_light():
    x0, x1, y0, y1, z = LIGHT
    vertices = np.array([
        [0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0],
        [0, 0, 0], [0, 2, 0], [0, 2, 1.5], [0, 0, 1.5],
        [x0, y0, z], [x0, y1, z], [x1, y1, z], [x1, y0, z],
    ], dtype=float)  # fmt: skip
    reflectance = np.array([[0.8] * 3, [0.5] * 3, [0.0] * 3])
    emission = np.array([[0.0] * 3, [0.0] * 3, [50.0] * 3])
    return Scene.from_polygons(vertices, [[0, 1, 2, 3], [4, 5, 6, 7], [8, 9, 10, 11]], reflectance, emission)


def reference_wall_radiosity(scene, points, cells=240):
    """Two bounces at wall points (x = 0, normal +x): the light's exact direct light, plus the floor's exact
    direct radiosity at the centres of cells x cells squares, each seen through the light (a point test at its
    centre, exact Lambert form factors for the squares near the point)."""
    x0, x1, y0, y1, z = LIGHT
    normal = np.array([1.0, 0.0, 0.0])
    direct = 50.0 * exact_form_factors(scene, points, np.tile(normal, (len(points), 1)), 2)
    h = 2.0 / cells
    c = (np.arange(cells) + 0.5) * h
    cx, cy = np.meshgrid(c, c, indexing="ij")
    centres = np.stack([cx.ravel(), cy.ravel(), np.zeros(cells * cells)], axis=1)
    floor = 0.8 * 50.0 * exact_form_factors(scene, centres, np.tile([0.0, 0.0, 1.0], (len(centres), 1)), 2)
    out = np.empty(len(points))
    for i, p in enumerate(points):
        d = centres - p
        r2 = np.einsum("ij,ij->i", d, d)
        ff = (d @ normal) * (-d[:, 2]) / (np.pi * r2 * r2) * h * h
        for j in np.flatnonzero(r2 < (6 * h) ** 2):
            q = centres[j]
            square = q + np.array([[-h, -h, 0], [h, -h, 0], [h, h, 0], [-h, h, 0]]) / 2
            ff[j] = lambert_form_factor(p, normal, [square])
        t = (z - p[2]) / (centres[:, 2] - p[2])
        hit = p + t[:, None] * d
        ff[(t > 0) & (t < 1) & (hit[:, 0] > x0) & (hit[:, 0] < x1) & (hit[:, 1] > y0) & (hit[:, 1] < y1)] = 0.0
        out[i] = 0.5 * (direct[i] + ff @ floor)
    return out


def wall_vertices(solver):
    result = solver.result()
    wall = np.unique(result.triangles[(result.triangle_polygon == 1) & (result.triangle_side == 0)])
    points = result.vertices[wall].astype(np.float64)
    keep = points[:, 2] > 0.1  # the quadrature is not meant for points next to the floor
    return points[keep], result.radiosity[wall][keep, 0]


@pytest.fixture(scope="module")
def floor_wall():
    scene = floor_wall_light()
    solver = Solver(scene, Settings(max_bounces=2, max_iterations=4, discontinuities=False, source_refinement=True))
    solver.solve()
    points, radiosity = wall_vertices(solver)
    return scene, solver, points, radiosity, reference_wall_radiosity(scene, points)


def test_indirect_light_from_an_uneven_source_matches_the_quadrature(floor_wall):
    """The floor's radiosity varies from a bright spot under the light to dim corners: gathered from its
    average, the wall's light is wrong by several JND; refined, within a fraction of one (measured: 0.1)."""
    _, solver, points, radiosity, reference = floor_wall
    assert len(points) > 100
    refined = [record.get("source_links_refined", 0) for record in solver.refinement_log]
    assert sum(refined) > 0
    error = np.abs(radiosity - reference)
    threshold = solver.lighting.threshold
    assert error.max() < 0.25 * threshold, (error.max(), threshold)
    assert (error / reference).max() < 0.02


def test_without_source_refinement_the_same_wall_is_visibly_wrong(floor_wall):
    scene, solver, _, _, _ = floor_wall
    averaged = Solver(scene, Settings(max_bounces=2, max_iterations=4, discontinuities=False))
    averaged.solve()
    points_avg, radiosity_avg = wall_vertices(averaged)
    reference_avg = reference_wall_radiosity(scene, points_avg)
    assert np.abs(radiosity_avg - reference_avg).max() > 3.0 * solver.lighting.threshold
