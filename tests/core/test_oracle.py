"""The link oracle (core/pipeline/oracle.py) and the lazy links it drives: the form-factor bound holds, the
selection inherits the cheapest transfers within the allowance, emitters stay exact, and a lazily linked
solution stays within the JND of the same mesh linked exactly everywhere."""

import numpy as np

from bench.scenes import closed_furnished_room
from core.formfactor import point_polygon_ff
from core.pipeline import Settings, Solver
from core.pipeline.interpolation import locate
from core.pipeline.links import LinkSet
from core.pipeline.oracle import distance_bounds, form_factor_bounds, select_exact
from core.pipeline.perception import LUMINANCE_WEIGHTS
from core.scene import Scene


def _lit_room(seed: int) -> Scene:
    spec = closed_furnished_room(seed, n_boxes=6)
    count = len(spec.polygons)
    plain = Scene.from_polygons(spec.vertices, spec.polygons, np.full((count, 3), 0.5), np.zeros((count, 3)))
    down = np.flatnonzero(plain.normals[:, 2] < -0.99)
    ceiling = int(plain.source_polygon[down[np.argmax(plain.centroids[down, 2])]])
    emission = np.zeros((count, 3))
    emission[ceiling] = 10.0
    return Scene.from_polygons(spec.vertices, spec.polygons, np.full((count, 3), 0.6), emission,
                               object_ids=spec.object_ids)  # fmt: skip


def test_form_factor_bound_holds_everywhere_in_the_region():
    scene = _lit_room(2)
    rng = np.random.default_rng(11)
    centres = rng.uniform(scene.vertices.min(axis=0), scene.vertices.max(axis=0), (30, 3))
    radii = rng.uniform(0.01, 0.5, 30)
    bounds = form_factor_bounds(distance_bounds(centres, radii, scene), scene.areas)
    for region in range(30):
        offsets = rng.normal(size=(200, 3))
        offsets *= (radii[region] * rng.uniform(0, 1, 200) ** (1 / 3) / np.linalg.norm(offsets, axis=1))[:, None]
        points = centres[region] + offsets
        normals = rng.normal(size=(200, 3))
        for source in range(scene.n_polygons):
            unoccluded = point_polygon_ff(points, normals, scene.polygon(source))
            assert unoccluded.max() <= bounds[region, source] + 1e-12, (region, source)


def _naive_selection(cost, live, always, allowance):
    exact = np.zeros_like(live)
    for row in range(len(cost)):
        spent = 0.0
        for source in sorted(np.flatnonzero(live[row]), key=lambda q: (always[q], cost[row, q], q)):
            price = np.inf if always[source] else cost[row, source]
            if spent + price > allowance[row]:
                exact[row, source] = True
            spent += price
    return exact


def test_selection_inherits_the_cheapest_within_the_allowance():
    rng = np.random.default_rng(5)
    cost = rng.exponential(1.0, (40, 25))
    cost[rng.random(cost.shape) < 0.2] = 0.0
    live = rng.random(cost.shape) < 0.8
    always = np.zeros(25, bool)
    always[[3, 17]] = True
    allowance = rng.uniform(0.0, 6.0, 40)
    exact = select_exact(cost, live, always, allowance)
    np.testing.assert_array_equal(exact, _naive_selection(cost, live, always, allowance))
    assert not exact[~live].any()
    assert exact[:, always][live[:, always]].all()
    inherited = np.where(live & ~exact, cost, 0.0).sum(axis=1)
    assert np.all(inherited <= allowance)


def _touching_another_polygon(scene: Scene, hierarchy) -> np.ndarray:
    """(N,) bool: vertices lying on a polygon other than their own (room corners, contact outlines), where a
    form factor is a limit whose value depends on the side it is taken from, and so on the mesh around."""
    positions = hierarchy.vertex_positions()
    own = hierarchy.vertex_polygon()
    tol = 1e-9 * scene.diagonal
    touching = np.zeros(len(positions), bool)
    for polygon in range(scene.n_polygons):
        corners = scene.polygon(polygon)
        normal = scene.normals[polygon]
        on_plane = np.abs(positions @ normal + scene.plane_offsets[polygon]) <= tol
        inside = on_plane.copy()
        for k in range(len(corners)):
            inward = np.cross(normal, corners[(k + 1) % len(corners)] - corners[k])
            inward /= np.linalg.norm(inward)
            inside &= (positions - corners[k]) @ inward >= -tol
        touching |= inside & (scene.source_polygon[own] != scene.source_polygon[polygon])
    return touching


def test_lazy_links_stay_within_the_jnd_of_exact_links_on_the_same_mesh():
    scene = _lit_room(4)
    lazy = Solver(scene, Settings(max_iterations=4))
    lazy.solve()
    state = lazy.lighting
    eager = Solver(scene, Settings(max_iterations=0))
    eager.build_skeleton()
    parts: list[LinkSet] = []
    for _ in eager._link_new_vertices(state.hierarchy, parts, 0):
        pass
    exact_links = LinkSet.concatenate(parts)
    exact = eager._gathered(state.hierarchy, exact_links)
    shape = (len(state.radiosity), 2 * scene.n_polygons)
    differs = np.abs(
        lazy._gather_matrix(state.links, shape[0], state.hierarchy)
        - eager._gather_matrix(exact_links, shape[0], state.hierarchy)
    )
    inherited = int((differs > 1e-12).sum())
    touching = np.repeat(_touching_another_polygon(scene, state.hierarchy), 2)
    difference = np.abs(state.radiosity - exact.radiosity)[~touching] @ LUMINANCE_WEIGHTS
    relative = difference / exact.threshold
    print(f"\nlazy vs exact links: {inherited} of {len(exact_links.form_factor)} transfers inherited, worst "
          f"difference {relative.max():.3f} JND, mean {relative.mean():.4f} JND")
    assert lazy.iterations >= 3
    assert inherited > 0
    assert relative.max() <= 1.0


def test_locate_agrees_with_a_naive_search_and_skips_flat_triangles():
    rng = np.random.default_rng(9)
    square = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 0.0]])
    triangles = np.array([[0, 1, 2], [0, 2, 3], [0, 4, 1]])  # the last one is flat
    points = np.column_stack([rng.uniform(0, 1, 200), rng.uniform(0, 1, 200), np.zeros(200)])
    with np.errstate(all="raise"):
        best, _, weights = locate(square, triangles, np.zeros(3, np.int64), points, np.zeros(200, np.int64))
    below = points[:, 1] <= points[:, 0]
    np.testing.assert_array_equal(best, np.where(below, 0, 1))
    np.testing.assert_allclose(np.einsum("qk,qkc->qc", weights, square[triangles[best]]), points, atol=1e-12)
