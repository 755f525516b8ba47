"""Tests of the benchmark scene generators (bench/scenes.py): counts, validity, determinism, geometry."""

import itertools
import json

import numpy as np
import pytest

from bench import scenes
from bench.scenes import (
    CLOSED_KINDS,
    OFFICE_SIZES,
    SCENES,
    SceneSpec,
    closed_furnished_room,
    cornell_box,
    desk,
    indirect_bedroom,
    many_lights,
    office,
    village,
)

ALL_SCENES = sorted(SCENES)
RANDOM_SEEDS = (0, 1, 2, 7)


def _scene(name: str) -> SceneSpec:
    return SCENES[name]()


def _all_specs():
    for name in ALL_SCENES:
        yield name, _scene(name)
    for seed in RANDOM_SEEDS:
        yield f"closed-furnished-room-{seed}", closed_furnished_room(seed)


def _newell_normal(points: np.ndarray) -> np.ndarray:
    """Unnormalised area vector (3,) of a polygon (k, 3)."""
    following = np.roll(points, -1, axis=0)
    return 0.5 * np.cross(points, following).sum(axis=0)


def _unit_normal(spec: SceneSpec, polygon: int) -> np.ndarray:
    n = _newell_normal(spec.vertices[spec.polygons[polygon]])
    return n / np.linalg.norm(n)


def _object_vertices(spec: SceneSpec, object_id: int) -> np.ndarray:
    indices = sorted({i for p in spec.object_polygons(object_id) for i in spec.polygons[p]})
    return spec.vertices[indices]


def _aabbs(spec: SceneSpec, kinds) -> tuple[list[int], np.ndarray, np.ndarray]:
    ids = [i for i, kind in enumerate(spec.object_kinds) if kind in kinds]
    points = [_object_vertices(spec, i) for i in ids]
    return ids, np.array([p.min(axis=0) for p in points]), np.array([p.max(axis=0) for p in points])


def _object_name(spec: SceneSpec, polygon: int) -> str:
    return spec.object_names[spec.object_ids[polygon]]


def _room_bounds(spec: SceneSpec) -> tuple[np.ndarray, np.ndarray]:
    (room,) = [i for i, kind in enumerate(spec.object_kinds) if kind == scenes.ROOM]
    points = _object_vertices(spec, room)
    return points.min(axis=0), points.max(axis=0)


# --- counts and registry -------------------------------------------------------------------------------


@pytest.mark.parametrize("n", OFFICE_SIZES)
def test_office_polygon_count_is_exact(n):
    spec = office(n)
    assert spec.n_polygons == n == len(spec.reflectance) == len(spec.emission)
    assert spec.name == f"office-{n}"
    assert SCENES[f"office-{n}"]().n_polygons == n


def test_office_rejects_other_sizes():
    with pytest.raises(ValueError, match="84"):
        office(100)


def test_registry_holds_the_paper_scenes():
    expected = {f"office-{n}" for n in OFFICE_SIZES} | {
        "desk",
        "many-lights",
        "indirect-bedroom",
        "village",
        "cornell-box",
    }
    assert set(SCENES) == expected
    for name in SCENES:
        assert _scene(name).name == name


def test_paper_scene_sizes():
    assert desk().n_polygons == 444
    assert many_lights().n_polygons == 452
    assert indirect_bedroom().n_polygons == 534
    assert village().n_polygons == 312
    assert cornell_box().n_polygons == 16


# --- arrays --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_arrays_are_consistent(name, spec):
    p = spec.n_polygons
    assert spec.vertices.dtype == np.float64 and spec.vertices.shape == (len(spec.vertices), 3)
    assert np.isfinite(spec.vertices).all()
    assert spec.reflectance.shape == (p, 3) and spec.reflectance.dtype == np.float64
    assert spec.emission.shape == (p, 3) and spec.emission.dtype == np.float64
    assert spec.object_ids.shape == (p,) and spec.object_ids.dtype == np.int64
    assert spec.two_sided.shape == (p,) and spec.two_sided.dtype == np.bool_
    assert len(spec.object_names) == len(spec.object_kinds) == spec.object_ids.max() + 1
    assert set(np.unique(spec.object_ids)) == set(range(len(spec.object_names)))
    assert all(len(polygon) >= 3 for polygon in spec.polygons)
    assert all(0 <= i < len(spec.vertices) for polygon in spec.polygons for i in polygon)
    assert (spec.reflectance >= 0).all() and (spec.reflectance < 1).all()
    assert (spec.emission >= 0).all()
    emitting = np.flatnonzero((spec.emission > 0).any(axis=1))
    assert spec.lights.dtype == np.int64
    np.testing.assert_array_equal(spec.lights, emitting)
    assert all(spec.object_kinds[spec.object_ids[i]] == scenes.LIGHT for i in spec.lights)


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_objects_do_not_share_vertices(name, spec):
    owner = np.full(len(spec.vertices), -1)
    for polygon, object_id in zip(spec.polygons, spec.object_ids, strict=True):
        for i in polygon:
            assert owner[i] in (-1, object_id), f"{name}: vertex {i} shared across objects"
            owner[i] = object_id


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_polygons_are_planar_and_not_degenerate(name, spec):
    scale = np.linalg.norm(spec.vertices.max(axis=0) - spec.vertices.min(axis=0))
    for index, polygon in enumerate(spec.polygons):
        points = spec.vertices[polygon]
        area_vector = _newell_normal(points)
        assert np.linalg.norm(area_vector) > 1e-6, f"{name}: polygon {index} has no area"
        if spec.object_names[spec.object_ids[index]] == "left_wall":
            continue  # the Cornell box's published left wall is slightly non-planar on purpose
        normal = area_vector / np.linalg.norm(area_vector)
        distances = (points - points.mean(axis=0)) @ normal
        assert np.abs(distances).max() < 1e-12 * scale, f"{name}: polygon {index} is not planar"


def test_scene_arrays_are_deterministic():
    for name in ALL_SCENES:
        first, second = _scene(name), _scene(name)
        np.testing.assert_array_equal(first.vertices, second.vertices)
        assert first.polygons == second.polygons
        for field in ("reflectance", "emission", "object_ids", "two_sided", "lights"):
            np.testing.assert_array_equal(getattr(first, field), getattr(second, field))
        assert first.object_names == second.object_names
        assert first.object_kinds == second.object_kinds


def test_random_rooms_are_deterministic_in_their_seed():
    a, b, c = closed_furnished_room(3), closed_furnished_room(3), closed_furnished_room(4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.reflectance, b.reflectance)
    assert a.polygons == b.polygons
    assert a.vertices.shape != c.vertices.shape or not np.array_equal(a.vertices, c.vertices)


# --- building through the engine ----------------------------------------------------------------------


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_every_scene_builds(name, spec):
    from core.scene import Scene

    scene = spec.build()
    assert isinstance(scene, Scene)
    np.testing.assert_array_equal(np.unique(scene.source_polygon), np.arange(spec.n_polygons))
    np.testing.assert_array_equal(np.unique(scene.source_polygon[scene.lights]), spec.lights)
    np.testing.assert_array_equal(scene.two_sided, spec.two_sided[scene.source_polygon])
    expected = spec.n_polygons + (name == "cornell-box")  # only the Cornell left wall is split (in two)
    assert scene.n_polygons == expected


# --- topology and placement ----------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_closed_objects_are_watertight_and_oriented(name, spec):
    closed = [i for i, kind in enumerate(spec.object_kinds) if kind in CLOSED_KINDS]
    assert closed or name == "cornell-box"
    for object_id in closed:
        polygons = [spec.polygons[p] for p in spec.object_polygons(object_id)]
        edges = [(a, b) for polygon in polygons for a, b in zip(polygon, np.roll(polygon, -1), strict=True)]
        assert len(set(edges)) == len(edges), f"{name}: {spec.object_names[object_id]} repeats an edge"
        assert set(edges) == {(b, a) for a, b in edges}, f"{name}: {spec.object_names[object_id]} is open"
        # Divergence theorem: positive volume for outward normals, negative for a room's inward ones.
        volume = sum(np.dot(spec.vertices[p[0]], _newell_normal(spec.vertices[p])) for p in polygons) / 3
        if spec.object_kinds[object_id] == scenes.ROOM:
            assert volume < 0, f"{name}: room normals must point inwards"
        else:
            assert volume > 0, f"{name}: {spec.object_names[object_id]} normals must point outwards"


@pytest.mark.parametrize(("name", "spec"), [(n, s) for n, s in _all_specs() if n != "cornell-box"])
def test_no_two_solids_interpenetrate(name, spec):
    # (The Cornell blocks are turned, so their bounding boxes overlap although the blocks do not.)
    ids, lo, hi = _aabbs(spec, {scenes.BOX, scenes.SOLID, scenes.OPEN})
    overlap = np.clip(np.minimum(hi[:, None], hi[None, :]) - np.maximum(lo[:, None], lo[None, :]), 0, None)
    volume = overlap.prod(axis=2)
    np.fill_diagonal(volume, 0.0)
    bad = [(spec.object_names[ids[i]], spec.object_names[ids[j]]) for i, j in np.argwhere(volume > 0)]
    assert not bad, f"{name}: {bad[:3]}"


def test_rotated_box_overlap_is_detected():
    """The interpenetration check is not vacuous: overlapping boxes give a positive volume."""
    builder = scenes.SceneBuilder("overlap")
    builder.box("a", (0, 0, 0), (1, 1, 1), (0.5, 0.5, 0.5))
    builder.box("b", (0.9, 0, 0), (2, 1, 1), (0.5, 0.5, 0.5), yaw=0.3)
    spec = builder.spec()
    _, lo, hi = _aabbs(spec, {scenes.BOX})
    assert np.prod(np.minimum(hi[0], hi[1]) - np.maximum(lo[0], lo[1])) > 0


@pytest.mark.parametrize(("name", "spec"), [(n, s) for n, s in _all_specs() if scenes.ROOM in s.object_kinds])
def test_everything_is_inside_the_room(name, spec):
    room_lo, room_hi = _room_bounds(spec)
    assert (spec.vertices >= room_lo).all() and (spec.vertices <= room_hi).all()


def _contacts(lo: np.ndarray, hi: np.ndarray) -> dict[str, bool]:
    """Which arrangements occur among axis-aligned boxes (n, 3) lo/hi."""
    found = {"on floor": bool((lo[:, 2] == 0).any()), "stacked": False, "floating": False, "side by side": False}
    for i, j in itertools.permutations(range(len(lo)), 2):
        footprint = np.minimum(hi[i], hi[j]) - np.maximum(lo[i], lo[j])
        if lo[i, 2] == hi[j, 2] and (footprint[:2] > 0).all():
            found["stacked"] = True
        for axis in (0, 1):
            others = [a for a in range(3) if a != axis]
            if lo[i, axis] == hi[j, axis] and (footprint[others] > 0).all():
                found["side by side"] = True
    for i in range(len(lo)):
        below = (hi[:, 2] <= lo[i, 2]) & (np.minimum(hi[:, :2], hi[i, :2]) > np.maximum(lo[:, :2], lo[i, :2])).all(1)
        below[i] = False
        if lo[i, 2] > 0 and not (hi[below, 2] == lo[i, 2]).any():
            found["floating"] = True
    return found


@pytest.mark.parametrize("spec", [office(OFFICE_SIZES[-1]), *(closed_furnished_room(s) for s in RANDOM_SEEDS)])
def test_boxes_rest_stack_float_and_touch(spec):
    ids, lo, hi = _aabbs(spec, {scenes.BOX})
    found = _contacts(lo, hi)
    assert all(found.values()), found


def test_office_has_tables_chairs_shelves_and_decals():
    spec = office(84)
    names = " ".join(spec.object_names)
    for part in ("table top", "table leg 3", "chair seat", "chair back", "ceiling light", "rug", "poster"):
        assert part in names
    assert "board" in " ".join(office(312).object_names)


@pytest.mark.parametrize(("name", "spec"), [(n, s) for n, s in _all_specs() if scenes.ROOM in s.object_kinds])
def test_decals_face_into_the_room(name, spec):
    room_lo, room_hi = _room_bounds(spec)
    centre = (room_lo + room_hi) / 2
    for object_id, kind in enumerate(spec.object_kinds):
        if kind != scenes.PANEL:
            continue
        (polygon,) = spec.object_polygons(object_id)
        inward = centre - spec.vertices[spec.polygons[polygon]].mean(axis=0)
        assert np.dot(_unit_normal(spec, polygon), inward) > 0, f"{name}: {spec.object_names[object_id]}"


# --- lights --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(("name", "spec"), list(_all_specs()))
def test_open_panels_are_two_sided_closed_objects_one_sided(name, spec):
    for object_id, kind in enumerate(spec.object_kinds):
        sides = spec.two_sided[spec.object_polygons(object_id)]
        if kind in CLOSED_KINDS or kind == scenes.LIGHT or name == "cornell-box":
            assert not sides.any(), f"{name}: {spec.object_names[object_id]}"
        elif kind == scenes.PANEL:
            assert sides.all(), f"{name}: {spec.object_names[object_id]}"


@pytest.mark.parametrize("name", ALL_SCENES)
def test_lights_are_one_sided_quads(name):
    spec = _scene(name)
    assert len(spec.lights) >= 1
    assert not spec.two_sided[spec.lights].any()
    assert all(len(spec.polygons[i]) == 4 for i in spec.lights)


@pytest.mark.parametrize("name", [n for n in ALL_SCENES if n.startswith("office") or n in ("desk", "many-lights")])
def test_ceiling_lights_hang_below_the_ceiling_facing_the_room(name):
    spec = _scene(name)
    room_lo, room_hi = _room_bounds(spec)
    centre = (room_lo + room_hi) / 2
    ceiling_lights = [i for i in spec.lights if spec.object_names[spec.object_ids[i]].startswith("ceiling light")]
    assert ceiling_lights
    _, _, box_hi = _aabbs(spec, {scenes.BOX})
    for i in ceiling_lights:
        points = spec.vertices[spec.polygons[i]]
        assert np.dot(_unit_normal(spec, i), centre - points.mean(axis=0)) > 0
        assert (points[:, 2] < room_hi[2]).all() and (points[:, 2] > room_hi[2] - 0.05).all()
        assert (box_hi[:, 2] < points[:, 2].min()).all()


def test_many_lights_is_desk_plus_eight_small_lights():
    base, lit = desk(), many_lights()
    assert lit.polygons[: base.n_polygons] == base.polygons
    np.testing.assert_array_equal(lit.vertices[: len(base.vertices)], base.vertices)
    assert len(lit.lights) == len(base.lights) + 8
    assert (lit.emission[base.lights] < base.emission[base.lights]).all()
    lamp = [i for i in lit.lights if _object_name(lit, i) == "lamp light"]
    assert len(lamp) == 1 and np.allclose(_unit_normal(lit, lamp[0]), (0, 0, -1))


def test_bedroom_lamp_points_down_inside_its_shade():
    spec = indirect_bedroom()
    (light,) = spec.lights
    assert np.allclose(_unit_normal(spec, light), (0, 0, -1))
    lamp_points = spec.vertices[spec.polygons[light]]
    shade = spec.object_names.index(_object_name(spec, light).replace("light", "shade"))
    shade_points = _object_vertices(spec, shade)
    assert (lamp_points >= shade_points.min(axis=0)).all() and (lamp_points <= shade_points.max(axis=0)).all()
    assert spec.two_sided[spec.object_polygons(shade)].all()
    # Small: the lamp is a tiny fraction of the room's surface.
    areas = [np.linalg.norm(_newell_normal(spec.vertices[p])) for p in spec.polygons]
    assert areas[light] < 0.001 * sum(areas)


def test_village_is_open_and_lit_from_above():
    spec = village()
    assert scenes.ROOM not in spec.object_kinds
    ground = spec.object_polygons(spec.object_names.index("ground"))
    assert spec.two_sided[ground].all()
    assert np.allclose(_unit_normal(spec, ground[0]), (0, 0, 1))
    (light,) = spec.lights
    assert np.allclose(_unit_normal(spec, light), (0, 0, -1))
    others = np.ones(len(spec.vertices), bool)
    others[spec.polygons[light]] = False
    assert spec.vertices[spec.polygons[light], 2].min() > spec.vertices[others, 2].max()
    assert sum(kind == scenes.SOLID for kind in spec.object_kinds) >= 10  # roofs


# --- Cornell box ---------------------------------------------------------------------------------------


def test_cornell_box_matches_the_published_data():
    data = json.loads(scenes.CORNELL_BOX_JSON.read_text())
    spec = cornell_box(z_up=False)
    assert spec.n_polygons == len(data["surfaces"]) + 1
    published = np.concatenate(
        [np.asarray(s["vertices_mm"]) for s in data["surfaces"]] + [data["light"]["vertices_mm"]]
    )
    in_order = np.concatenate([spec.vertices[p] for p in spec.polygons])
    np.testing.assert_allclose(in_order * 1000.0, published, rtol=0, atol=1e-9)
    np.testing.assert_allclose(spec.emission[spec.lights[0]], data["light"]["emission_rgb_band_avg"])
    for index, surface in enumerate(data["surfaces"]):
        np.testing.assert_allclose(spec.reflectance[index], surface["reflectance_rgb_band_avg"])
        np.testing.assert_allclose(_unit_normal(spec, index), surface["newell_normal"], atol=1e-4)


def test_cornell_box_is_half_a_metre_and_z_up():
    spec = cornell_box()
    extent = spec.vertices.max(axis=0) - spec.vertices.min(axis=0)
    assert np.all((extent > 0.54) & (extent < 0.57)), extent
    (light,) = spec.lights
    assert np.allclose(_unit_normal(spec, light), (0, 0, -1))
    floor = spec.object_polygons(spec.object_names.index("floor"))[0]
    assert np.allclose(_unit_normal(spec, floor), (0, 0, 1))
    left_wall = spec.object_polygons(spec.object_names.index("left_wall"))[0]
    points = spec.vertices[spec.polygons[left_wall]]
    normal = _unit_normal(spec, left_wall)
    assert np.ptp((points - points.mean(axis=0)) @ normal) > 1e-4  # kept non-planar, as published
    assert normal[0] > 0.99  # the red wall faces the box's inside (+x after the rotation)


def test_cornell_box_without_its_data_says_where_it_looked(monkeypatch, tmp_path):
    missing = tmp_path / "cornell_box.json"
    monkeypatch.setattr(scenes, "CORNELL_BOX_JSON", missing)
    with pytest.raises(FileNotFoundError, match="cornell_box.json"):
        cornell_box()
