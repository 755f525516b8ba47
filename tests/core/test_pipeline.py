"""The solver end to end: exact direct light at the vertices (independent oracle), white furnace, energy
balance, the reconstruction against exact direct light at random points (Ward display units), two-sided
surfaces, cancellation and settings."""

import math

import numpy as np
import pytest

from bench.scenes import box_mesh, closed_furnished_room
from core.errors import CancelledError, VisradError
from core.pipeline import Settings, Solver
from core.scene import Scene
from core.visibility import exact_form_factors
from tests.core.naive_visibility import oracle_form_factor

LIGHT_EXITANCE = 12.0


def _light_box_plane_scene():
    """A floor lit by a downward area light, a floating box and a floating tilted open plane (two-sided)."""
    vertices = [[-2.0, -2.0, 0.0], [2.0, -2.0, 0.0], [2.0, 2.0, 0.0], [-2.0, 2.0, 0.0]]
    polygons = [[0, 1, 2, 3]]
    rho = [[0.5, 0.5, 0.5]]
    emission = [[0.0, 0.0, 0.0]]
    two_sided = [True]
    base = len(vertices)
    vertices += [[-0.5, -0.5, 2.5], [0.5, -0.5, 2.5], [0.5, 0.5, 2.5], [-0.5, 0.5, 2.5]]
    polygons.append([base, base + 3, base + 2, base + 1])  # facing down
    rho.append([0.0, 0.0, 0.0])
    emission.append([LIGHT_EXITANCE] * 3)
    two_sided.append(False)
    box_v, box_p = box_mesh([0.3, -0.6, 0.7], [0.9, 0.1, 1.2], yaw=0.3)
    base = len(vertices)
    vertices += box_v.tolist()
    polygons += [[base + i for i in q] for q in box_p]
    rho += [[0.6, 0.4, 0.3]] * len(box_p)
    emission += [[0.0] * 3] * len(box_p)
    two_sided += [False] * len(box_p)
    base = len(vertices)
    vertices += [[-1.6, -1.2, 0.9], [-0.4, -1.2, 1.3], [-0.4, 0.4, 1.3], [-1.6, 0.4, 0.9]]
    polygons.append([base, base + 1, base + 2, base + 3])
    rho.append([0.3, 0.6, 0.8])
    emission.append([0.0] * 3)
    two_sided.append(True)
    return Scene.from_polygons(np.array(vertices), polygons, rho, emission, two_sided=two_sided)


def _room_scene(seed: int, emission_all: float | None = None, rho: float = 0.5):
    spec = closed_furnished_room(seed, n_boxes=6)
    count = len(spec.polygons)
    reflectance = np.full((count, 3), rho)
    if emission_all is not None:
        emission = np.full((count, 3), emission_all)
    else:
        emission = np.zeros((count, 3))
        ceiling = _ceiling(spec)
        emission[ceiling] = LIGHT_EXITANCE
    return Scene.from_polygons(spec.vertices, spec.polygons, reflectance, emission, object_ids=spec.object_ids)


def _ceiling(spec) -> int:
    scene = Scene.from_polygons(spec.vertices, spec.polygons, np.full((len(spec.polygons), 3), 0.5),
                                np.zeros((len(spec.polygons), 3)))  # fmt: skip
    down = np.nonzero(scene.normals[:, 2] < -0.99)[0]
    return int(scene.source_polygon[down[np.argmax(scene.centroids[down, 2])]])


def _oracle_direct(scene, point, polygon, side):
    """E + rho sum_l E_l F_l at a point, F from the independent clipping oracle."""
    normal = scene.normals[polygon] * (1.0 if side == 0 else -1.0)
    total = np.zeros(3)
    for light in scene.lights:
        height = scene.normals[light] @ point + scene.plane_offsets[light]
        if height <= 0.0 and not scene.two_sided[light]:
            continue
        blockers = [scene.polygon(q) for q in range(scene.n_polygons)
                    if q != light and abs(scene.normals[q] @ point + scene.plane_offsets[q]) > 1e-9]  # fmt: skip
        total += scene.emission[light] * oracle_form_factor(point, normal, scene.polygon(light), blockers)
    own = scene.emission[polygon] if side == 0 or scene.two_sided[polygon] else np.zeros(3)
    return own + scene.reflectance[polygon] * total


def test_direct_light_at_vertices_is_exact():
    scene = _light_box_plane_scene()
    result = Solver(scene, Settings(max_bounces=1, max_iterations=3)).solve()
    assert result.stats["leaf_triangles"] > 100
    rng = np.random.default_rng(1)
    sides = np.zeros(len(result.vertices), np.int64)
    polygons = np.zeros(len(result.vertices), np.int64)
    sides[result.triangles.ravel()] = np.repeat(result.triangle_side, 3)
    polygons[result.triangles.ravel()] = np.repeat(result.triangle_polygon, 3)
    assert (sides == 1).any()
    for vertex in rng.choice(len(result.vertices), 80, replace=False):
        expected = _oracle_direct(scene, result.vertices[vertex], polygons[vertex], sides[vertex])
        assert np.allclose(result.radiosity[vertex], expected, rtol=0.0, atol=1e-9 * LIGHT_EXITANCE), vertex


def test_two_sided_plane_back_sees_what_is_behind_it():
    scene = _light_box_plane_scene()
    direct = Solver(scene, Settings(max_bounces=1, max_iterations=0)).solve()
    full = Solver(scene, Settings(max_bounces=None, max_iterations=0)).solve()
    plane = scene.n_polygons - 1
    back = (direct.triangle_polygon == plane) & (direct.triangle_side == 1)
    # the light is above the plane's front: its back side gets no direct light, only light from the floor
    assert np.all(direct.radiosity[np.unique(direct.triangles[back])] == 0.0)
    back_full = (full.triangle_polygon == plane) & (full.triangle_side == 1)
    assert np.all(full.radiosity[np.unique(full.triangles[back_full])] > 0.0)


def test_white_furnace():
    scene = _room_scene(3, emission_all=1.0, rho=0.5)
    result = Solver(scene, Settings(max_iterations=1)).solve()
    assert np.allclose(result.radiosity, 2.0, rtol=0.01)


def _integral(result, values):
    corners = result.vertices[result.triangles]
    area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    return area[:, None] * values[result.triangles].mean(axis=1), area


def test_energy_balance_in_a_closed_room():
    scene = _room_scene(5)
    result = Solver(scene, Settings(max_iterations=3)).solve()
    rho = scene.reflectance[result.triangle_polygon]
    emission = scene.emission[result.triangle_polygon]
    gathered, area = _integral(result, result.radiosity)
    # every surface reflects (rho > 0): irradiance integral = (integral of B - E A) / rho
    absorbed = (1.0 - rho) * (gathered - emission * area[:, None]) / rho
    emitted = (emission * area[:, None]).sum(axis=0)
    ratio = absorbed.sum(axis=0) / emitted
    print(f"absorbed / emitted: {ratio}")
    assert np.all(np.abs(ratio - 1.0) < 0.005)


def _ward(values, average):
    luminance = 179.0 * (values @ np.array([0.2126, 0.7152, 0.0722])) / math.pi
    adaptation = 179.0 * (average @ np.array([0.2126, 0.7152, 0.0722])) / math.pi
    sf = ((1.219 + 50.0**0.4) / (1.219 + adaptation**0.4)) ** 2.5 / 100.0
    return sf * luminance


def test_reconstruction_within_jnd_of_exact_direct_light():
    scene = _room_scene(7)
    result = Solver(scene, Settings(max_bounces=1, max_iterations=6)).solve()
    rng = np.random.default_rng(2)
    # points on the surfaces the light falls on (the emitter itself is trivially exact)
    receiving = np.where(scene.emission.max(axis=1) > 0.0, 0.0, scene.areas)
    polygons = rng.choice(scene.n_polygons, 1200, p=receiving / receiving.sum())
    points = np.empty((len(polygons), 3))
    for i, polygon in enumerate(polygons):
        corners = scene.polygon(polygon)
        weights = rng.dirichlet(np.ones(len(corners)))
        points[i] = weights @ corners
    shown = ~np.array([_touched(scene, point, polygon) for point, polygon in zip(points, polygons, strict=True)])
    points, polygons = points[shown], polygons[shown]
    exact = scene.emission[polygons].copy()
    for light in scene.lights:
        for polygon in np.unique(polygons):
            idx = np.nonzero(polygons == polygon)[0]
            ff = exact_form_factors(scene, points[idx], np.repeat(scene.normals[polygon][None], len(idx), 0), light)
            exact[idx] += scene.reflectance[polygon] * scene.emission[light] * ff[:, None]
    approx = result.radiosity_at(points, polygons)
    averages, areas = exact_average(scene, result)
    average = (areas[:, None] * averages).sum(axis=0) / areas.sum()
    error = np.abs(_ward(approx, average) - _ward(exact, average))
    share = float(np.mean(error <= 0.02))
    print(f"points within the JND: {share:.3f}, leaf triangles {result.stats['leaf_triangles']}")
    assert share >= 0.9


def _touched(scene, point, polygon) -> bool:
    """Whether a point of `polygon` is covered by another polygon lying on it face to face (hidden)."""
    for other in range(scene.n_polygons):
        if scene.normals[other] @ scene.normals[polygon] > -0.999999:
            continue
        if abs(scene.normals[other] @ point + scene.plane_offsets[other]) > 1e-9:
            continue
        corners = scene.polygon(other)
        edges = np.roll(corners, -1, axis=0) - corners
        inward = np.cross(scene.normals[other], edges)
        if np.all(np.einsum("ij,ij->i", point - corners, inward) > 0.0):
            return True
    return False


def exact_average(scene, result):
    """Per-polygon area-weighted average radiosity of the result (front sides) and the area it covers, over
    the polygons with result triangles."""
    gathered, area = _integral(result, result.radiosity)
    total = np.zeros((scene.n_polygons, 3))
    weight = np.zeros(scene.n_polygons)
    front = result.triangle_side == 0
    np.add.at(total, result.triangle_polygon[front], gathered[front])
    np.add.at(weight, result.triangle_polygon[front], area[front])
    shown = weight > 0.0
    return total[shown] / weight[shown, None], weight[shown]


def test_cancel_leaves_the_last_consistent_state():
    scene = _light_box_plane_scene()
    calls = []
    solver = Solver(scene, Settings(max_bounces=1), progress=lambda stage, f: calls.append(stage),
                    cancel=lambda: "refine" in calls)  # fmt: skip
    solver.build_skeleton()
    solver.coarse_lighting()
    before = solver.result()
    with pytest.raises(CancelledError):
        solver.refine(1)
    after = solver.result()
    assert solver.iterations == 0
    assert np.array_equal(before.triangles, after.triangles)
    assert np.array_equal(before.radiosity, after.radiosity)


def test_bounces_add_light():
    scene = _room_scene(5)
    values = [Solver(scene, Settings(max_bounces=b, max_iterations=0)).solve().radiosity for b in (1, 2, 3, None)]
    for lower, higher in zip(values, values[1:], strict=False):
        assert np.all(higher >= lower - 1e-12)
    assert np.any(values[1] > values[0])


@pytest.mark.parametrize(
    "kwargs, culprit",
    [
        ({"jnd": 0.0}, "jnd"),
        ({"max_bounces": 0}, "max_bounces"),
        ({"form_factors": "rays"}, "form_factors"),
        ({"max_iterations": -1}, "max_iterations"),
    ],
)
def test_bad_settings_name_the_field(kwargs, culprit):
    with pytest.raises(VisradError, match=culprit):
        Settings(**kwargs)


def test_presets():
    assert Settings.preset("fast").form_factors == 16
    assert Settings.preset("Accurate", jnd=0.01).jnd == 0.01
    with pytest.raises(VisradError, match="presets"):
        Settings.preset("best")


def test_views_from_pair_blocker_lists_and_sample_links_change_nothing():
    """The solver computes views from the blocker lists of polygon pairs (empty lists: full visibility) and gives
    vertices inserted at samples the samples' links; the same solve with neither (every view from the whole
    scene's BVH, every new vertex linked afresh) gives the same radiosity."""
    scene = _light_box_plane_scene()
    fast = Solver(scene, Settings(max_iterations=3))
    result = fast.solve()
    lists = result.stats["blocker_lists"]
    assert lists["pairs"] > 10 and 0 < lists["unoccluded"] < lists["pairs"]
    assert sum(record["from_samples"] for record in result.stats["refinement"] if "from_samples" in record) > 0

    plain = Solver(scene, Settings(max_iterations=3))
    plain.build_skeleton()
    plain.shafts = None
    fresh = plain._link_refined_vertices

    def linking_every_vertex(hierarchy, state, old_mesh, exact, parts, checks, record):
        nothing_known = checks.__class__(checks.corners, checks.live, checks.sampled, np.zeros_like(checks.known))
        yield from fresh(hierarchy, state, old_mesh, exact, parts, nothing_known, record)

    plain._link_refined_vertices = linking_every_vertex
    reference = plain.solve()
    assert all(record.get("from_samples", 0) == 0 for record in reference.stats["refinement"])
    np.testing.assert_array_equal(result.triangles, reference.triangles)
    np.testing.assert_allclose(result.radiosity, reference.radiosity, rtol=1e-9, atol=1e-12 * LIGHT_EXITANCE)
