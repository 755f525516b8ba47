"""Faces hidden by contact (core/pipeline/contact.py): a box resting on a floor hides the floor under it and its
own bottom; a card made of two faces back to back is one surface with two sides, lit on each."""

import numpy as np

from bench.scenes import box_mesh
from core.pipeline import Settings, Solver
from core.pipeline.contact import contact_regions, covered_fraction
from core.scene import Scene
from core.visibility import exact_form_factors

LIGHT = [[-0.3, -0.3, 2.0], [-0.3, 0.3, 2.0], [0.3, 0.3, 2.0], [0.3, -0.3, 2.0]]  # facing down
FLOOR = [[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0]]


def _scene(extra_vertices, extra_polygons):
    vertices = np.array(LIGHT + FLOOR + list(extra_vertices), dtype=float)
    polygons = [[0, 1, 2, 3], [4, 5, 6, 7]] + [[8 + i for i in p] for p in extra_polygons]
    count = len(polygons)
    emission = np.zeros((count, 3))
    emission[0] = 10.0
    return Scene.from_polygons(vertices, polygons, np.full((count, 3), 0.5), emission)


def test_a_box_on_the_floor_hides_its_bottom_and_the_floor_under_it():
    vertices, quads = box_mesh([-0.5, -0.5, 0.0], [0.5, 0.5, 0.6], yaw=0.0)
    scene = _scene(vertices, quads)
    regions = contact_regions(scene)
    bottom = 2 + int(np.argmin(scene.normals[2:, 2]))
    fraction = covered_fraction(scene, regions)
    assert set(regions) == {1, bottom}
    np.testing.assert_allclose(fraction[[1, bottom]], [1.0 / 16.0, 1.0], rtol=1e-12)


def test_a_card_of_two_faces_back_to_back_is_lit_on_both_sides():
    card = [[-0.4, -0.4, 1.0], [0.4, -0.4, 1.0], [0.4, 0.4, 1.0], [-0.4, 0.4, 1.0]]
    scene = _scene(card, [[0, 1, 2, 3], [3, 2, 1, 0]])
    assert contact_regions(scene) == {}
    result = Solver(scene, Settings(max_bounces=1, max_iterations=0)).solve()
    up = 2 if scene.normals[2, 2] > 0 else 3
    on_top = np.unique(result.triangles[result.triangle_polygon == up])
    assert len(on_top) >= 4
    points = result.vertices[on_top]
    expected = 0.5 * 10.0 * exact_form_factors(scene, points, np.tile([0.0, 0.0, 1.0], (len(points), 1)), 0)
    assert expected.min() > 0.0
    np.testing.assert_allclose(result.radiosity[on_top, 0], expected, rtol=1e-9)
    down = 5 - up
    assert (result.triangle_polygon == down).any(), "the face turned to the floor has its own result"
