"""visrad_addon.session (state between stage operators), settings, Check Scene, and the numba cache."""

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.errors import SceneError  # noqa: E402
from visrad.visrad_addon import numba_cache  # noqa: E402
from visrad.visrad_addon.properties import solver_settings  # noqa: E402
from visrad.visrad_addon.session import SessionStore, store  # noqa: E402
from visrad.visrad_addon.write_back import ROLE_PROPERTY, ResultArrays, write_results  # noqa: E402

from tests.addon.blender_scenes import area_light, box, diffuse_material, grid, user_data_fingerprint  # noqa: E402

SETTINGS = {
    "jnd": 0.02,
    "max_iterations": 10,
    "max_bounces": None,
    "form_factors": "exact",
    "discontinuities": True,
    "source_refinement": False,
    "preset": "accurate",
}


@pytest.fixture
def small_scene(registered_addon):
    """A light over a box on a floor; the add-on's depsgraph handler is registered. Returns a fresh store."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    area_light("Light", size=0.5, power=50.0, location=(0.0, 0.0, 2.0))
    box("Box", (-0.2, -0.2, 0.0), (0.2, 0.2, 0.4), diffuse_material("grey", (0.5, 0.5, 0.5)))
    grid("Floor", (-1.0, -1.0, 0.0), (2, 0, 0), (0, 2, 0), 2, diffuse_material("floor", (0.7, 0.7, 0.7)))
    bpy.context.view_layer.update()
    return SessionStore()


def test_an_unchanged_scene_keeps_its_session_and_state(small_scene):
    session = small_scene.open(bpy.context, SETTINGS)
    session.state["solver"] = "kept"
    bpy.context.view_layer.update()
    again = small_scene.open(bpy.context, SETTINGS)
    assert again is session and again.state == {"solver": "kept"}
    assert small_scene.get(bpy.context.scene) is session


@pytest.mark.parametrize(
    "change",
    [
        lambda: (
            bpy.data.materials["grey"]
            .node_tree.nodes["Diffuse BSDF"]
            .inputs["Color"]
            .default_value.__setitem__(1, 0.25)
        ),
        lambda: bpy.data.meshes["Floor"].vertices[4].co.__setitem__(2, 0.05),
        lambda: setattr(bpy.data.objects["Box"], "location", (0.1, 0.0, 0.0)),
        lambda: setattr(bpy.data.lights["Light"], "energy", 60.0),
        lambda: setattr(bpy.data.objects["Box"], "visrad_exclude", True),
        lambda: setattr(bpy.data.objects["Box"], "hide_render", True),
        lambda: bpy.data.objects.remove(bpy.data.objects["Box"]),
    ],
    ids=["material colour", "vertex", "transform", "light power", "exclusion", "hidden from render", "deletion"],
)
def test_a_change_of_the_scene_drops_the_session(small_scene, monkeypatch, change):
    monkeypatch.setattr("visrad.visrad_addon.session.store", small_scene)
    session = small_scene.open(bpy.context, SETTINGS)
    session.state["solver"] = "stale"
    bpy.context.view_layer.update()
    assert not session.dirty
    change()
    bpy.context.view_layer.update()
    assert session.dirty, "the depsgraph handler marks the session out of date"
    fresh = small_scene.open(bpy.context, SETTINGS)
    assert fresh is not session and fresh.state == {} and fresh.key != session.key
    assert not fresh.dirty


def test_a_change_of_settings_drops_the_session(small_scene):
    session = small_scene.open(bpy.context, SETTINGS)
    assert small_scene.open(bpy.context, {**SETTINGS, "jnd": 0.05}) is not session


def test_writing_results_neither_dirties_nor_drops_the_session(small_scene, monkeypatch):
    monkeypatch.setattr("visrad.visrad_addon.session.store", small_scene)
    session = small_scene.open(bpy.context, SETTINGS)
    bpy.context.view_layer.update()
    scene = session.scene
    floor = int(np.flatnonzero(session.source_map.polygon_object[scene.source_polygon] == 2)[0])
    corners = scene.polygon(floor)
    result = ResultArrays(corners, np.array([[0, 1, 2]]), np.array([floor]), np.ones((len(corners), 3)))
    write_results(bpy.context.scene, result, scene, session.source_map)
    bpy.context.view_layer.update()
    assert not session.dirty
    assert small_scene.open(bpy.context, SETTINGS) is session


def test_a_scene_that_no_longer_converts_drops_its_session(small_scene):
    small_scene.open(bpy.context, SETTINGS)
    bpy.data.objects.remove(bpy.data.objects["Light"])
    with pytest.raises(SceneError, match="has no light"):
        small_scene.open(bpy.context, SETTINGS)
    assert small_scene.get(bpy.context.scene) is None


def test_check_scene_operator_reports_counts_and_errors(small_scene):
    store.clear()
    assert bpy.ops.visrad.check_scene() == {"FINISHED"}
    session = store.get(bpy.context.scene)
    assert session.summary == "11 polygons (11 convex), 2 objects, 1 area lights, 1 emitting polygons"
    assert session.settings == solver_settings(bpy.context.scene.visrad)
    bpy.data.objects["Box"].data.vertices[1].co = bpy.data.objects["Box"].data.vertices[0].co
    bpy.data.objects["Box"].data.vertices[2].co = bpy.data.objects["Box"].data.vertices[0].co
    with pytest.raises(RuntimeError, match='mesh "Box"'):
        bpy.ops.visrad.check_scene()
    assert store.get(bpy.context.scene) is None


def test_settings_presets_and_solver_keywords(small_scene):
    props = bpy.context.scene.visrad
    assert solver_settings(props) == SETTINGS
    props.preset = "FAST"
    assert solver_settings(props) == {
        "preset": "fast",
        "jnd": pytest.approx(0.05),
        "max_iterations": 4,
        "max_bounces": None,
        "form_factors": 16,
        "discontinuities": False,
        "source_refinement": False,
    }
    props.preset = "CUSTOM"
    props.form_factors, props.rays, props.max_bounces = "EXACT", 64, 1
    assert solver_settings(props)["form_factors"] == "exact"
    assert solver_settings(props)["max_bounces"] == 1
    props.form_factors = "RAYS"
    assert solver_settings(props)["form_factors"] == 64
    props.discontinuities = True
    assert solver_settings(props)["discontinuities"] is True
    props.source_refinement = True
    assert solver_settings(props)["source_refinement"] is True


def test_the_exclusion_toggle_is_the_custom_property_conversion_reads(small_scene):
    obj = bpy.data.objects["Box"]
    assert not obj.visrad_exclude
    obj.visrad_exclude = True
    assert obj.get("visrad_exclude")
    session = small_scene.open(bpy.context, SETTINGS)
    assert session.source_map.excluded == ["Box"]
    assert session.scene.n_polygons == 5
    del obj["visrad_exclude"]
    assert not obj.visrad_exclude


def test_core_kernels_of_the_addon_cache_apart_from_the_plain_core_package():
    """tests/core import the checkout's `core`; the add-on's `visrad.core` must not share its numba cache."""
    import visrad.core.visibility as ours
    from numba.core.registry import CPUDispatcher

    import core.visibility as plain

    def cache_dirs(module):
        kernels = [v for v in vars(module).values() if isinstance(v, CPUDispatcher) and v.__module__ == module.__name__]
        assert kernels
        return {kernel._cache._cache_path for kernel in kernels}

    expected = numba_cache.CHECKOUT_ROOT / "__pycache__" / "numba" / "visrad"
    assert all(path.startswith(str(expected)) for path in cache_dirs(ours))
    assert cache_dirs(plain) == {str(numba_cache.CHECKOUT_ROOT / "core" / "__pycache__")}


def _remove_light():
    bpy.data.objects.remove(bpy.data.objects["Light"])


def _remove_meshes():
    for name in ("Box", "Floor"):
        bpy.data.objects.remove(bpy.data.objects[name])


def _collapse_a_face():
    vertices = bpy.data.meshes["Floor"].vertices
    vertices[1].co = vertices[0].co
    vertices[4].co = vertices[0].co


def _nan_transform():
    bpy.data.objects["Box"].location = (float("nan"), 0.0, 0.0)


@pytest.mark.parametrize(
    ("damage", "message"),
    [
        (_remove_light, "has no light"),
        (_remove_meshes, "has no visible mesh"),
        (_collapse_a_face, 'polygon 0 of mesh "Floor"'),
        (_nan_transform, 'object "Box" has a non-finite world transform'),
    ],
    ids=["no light", "no mesh", "zero-area face", "NaN transform"],
)
def test_check_scene_reports_a_bad_scene_by_name_and_changes_nothing(small_scene, damage, message):
    damage()
    # Blender derives matrix_world and the like when it evaluates the scene, which conversion does
    bpy.context.view_layer.update()
    before = user_data_fingerprint(ROLE_PROPERTY)
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.visrad.check_scene()
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    assert store.get(bpy.context.scene) is None
