"""visrad_addon.write_back on a result computed here, independently of the solver.

The scene: a square area light over a closed box and a floating open (two-sided) vertical panel. The result:
the leaves of core.hierarchy's regular grid on every polygon, with direct light B = E + rho sum_l E_l F_l from
core.visibility.exact_form_factors at each leaf vertex, and for the panel's back side a second, reversed copy
of its triangles on vertices of their own with B computed for the back normal.
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.hierarchy import Hierarchy  # noqa: E402
from visrad.core.visibility import exact_form_factors  # noqa: E402
from visrad.visrad_addon import write_back  # noqa: E402
from visrad.visrad_addon.convert import scene_from_blender  # noqa: E402
from visrad.visrad_addon.session import fingerprint  # noqa: E402
from visrad.visrad_addon.write_back import (  # noqa: E402
    DISCONTINUITIES_COLLECTION,
    FRONT_ONLY_MATERIAL,
    RADIANCE_ATTRIBUTE,
    RADIANCE_MATERIAL,
    RESULTS_COLLECTION,
    ROLE_PROPERTY,
    SIDE_GAP,
    ResultArrays,
    clear_results,
    write_results,
)

from tests.addon.blender_scenes import area_light, box, diffuse_material, grid, user_data_fingerprint  # noqa: E402

BOX_LOW, BOX_HIGH = (-0.9, -0.4, 0.0), (-0.3, 0.2, 0.6)
PANEL_X = 0.3


@pytest.fixture
def lit():
    """(core Scene, SourceMap, result, first back-side vertex id) of the light / box / panel scene, freshly
    built in an empty file."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    area_light("Light", size=1.0, power=100.0, location=(0.0, 0.0, 2.0))
    box("Box", BOX_LOW, BOX_HIGH, diffuse_material("grey", (0.5, 0.5, 0.5)))
    grid("Panel", (PANEL_X, -0.5, 0.2), (0, 1, 0), (0, 0, 1), 1, diffuse_material("warm", (0.8, 0.6, 0.4)))
    scene, source_map = scene_from_blender(bpy.context)
    return scene, source_map, *direct_light_result(scene)


def direct_light(scene, points, normals, polygons) -> np.ndarray:
    """B = E + rho sum_l E_l F_l at points (N, 3) with normals (N, 3) on scene polygons (N,)."""
    radiosity = scene.emission[polygons].copy()
    for light in scene.lights:
        receiving = polygons != light
        form_factors = exact_form_factors(scene, points[receiving], normals[receiving], int(light))
        radiosity[receiving] += scene.reflectance[polygons[receiving]] * form_factors[:, None] * scene.emission[light]
    return radiosity


def direct_light_result(scene) -> tuple[ResultArrays, int]:
    """The result, and the id of its first back-side vertex (back-side vertices come after the front's)."""
    hierarchy = Hierarchy.from_scene(scene)
    hierarchy.queue_regular_grid(hierarchy.leaves())
    hierarchy.complete_step()
    leaves = hierarchy.export_leaves()
    vertices, triangles, polygons = leaves.vertices, leaves.triangles, leaves.triangle_polygon
    radiosity = direct_light(scene, vertices, scene.normals[leaves.vertex_polygon], leaves.vertex_polygon)

    two_sided = np.isin(polygons, np.flatnonzero(scene.two_sided))
    back_vertices = np.unique(triangles[two_sided])
    renumber = np.full(len(vertices), -1)
    renumber[back_vertices] = len(vertices) + np.arange(len(back_vertices))
    back_polygons = leaves.vertex_polygon[back_vertices]
    back_radiosity = direct_light(scene, vertices[back_vertices], -scene.normals[back_polygons], back_polygons)

    panel_polygon = int(np.flatnonzero(scene.two_sided)[0])
    corners = scene.polygon(panel_polygon)
    box_top = int(np.argmax(scene.centroids[:, 2] * (~scene.two_sided) * (scene.emission.max(axis=1) == 0)))
    top = scene.polygon(box_top)
    discontinuities = {
        panel_polygon: np.array([[corners[0], corners[2]], [corners[1], corners[3]], [corners[0], corners[1]]]),
        box_top: np.array([[top[0], top[2]], [0.5 * (top[0] + top[1]), 0.5 * (top[2] + top[3])]]),
    }
    result = ResultArrays(
        vertices=np.concatenate([vertices, vertices[back_vertices]]),
        triangles=np.concatenate([triangles, renumber[triangles[two_sided]][:, ::-1]]),
        triangle_polygon=np.concatenate([polygons, polygons[two_sided]]),
        radiosity=np.concatenate([radiosity, back_radiosity]),
        discontinuities=discontinuities,
    )
    return result, len(vertices)


def expected_part(result, scene, source_map, name: str):
    """(used result vertex ids, triangles of the object in those ids) of source object `name`."""
    index = next(i for i, source in enumerate(source_map.objects) if source.name == name)
    mine = source_map.polygon_object[scene.source_polygon[result.triangle_polygon]] == index
    used, local = np.unique(result.triangles[mine], return_inverse=True)
    return used, local.reshape(-1, 3)


def mesh_arrays(mesh):
    """(positions (N, 3), faces (T, 3), radiance RGBA (N, 4), Blender's face normals (T, 3))."""
    positions = np.empty(3 * len(mesh.vertices), dtype=np.float32)
    mesh.vertices.foreach_get("co", positions)
    loops = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    radiance = np.empty(4 * len(mesh.vertices), dtype=np.float32)
    mesh.color_attributes[RADIANCE_ATTRIBUTE].data.foreach_get("color", radiance)
    normals = np.empty(3 * len(mesh.polygons), dtype=np.float32)
    mesh.polygons.foreach_get("normal", normals)
    return positions.reshape(-1, 3), loops.reshape(-1, 3), radiance.reshape(-1, 4), normals.reshape(-1, 3)


def canonical(triangles: np.ndarray) -> set:
    """Triangles as a set of vertex triples, each rotated to start at its smallest id (winding kept)."""
    rolled = [np.roll(t, -int(np.argmin(t))) for t in triangles]
    return {tuple(t.tolist()) for t in rolled}


def owned_datablocks() -> set[str]:
    kinds = ("objects", "meshes", "curves", "materials", "collections")
    return {f"{k}/{d.name}" for k in kinds for d in getattr(bpy.data, k) if d.get(ROLE_PROPERTY) is not None}


def all_datablocks() -> set[str]:
    kinds = ("objects", "meshes", "curves", "materials", "collections", "lights")
    return {f"{k}/{d.name}" for k in kinds for d in getattr(bpy.data, k)}


# ---------------------------------------------------------------------------------------------------------


def test_radiance_times_pi_is_the_given_radiosity_on_the_right_objects(lit):
    scene, source_map, result, first_back = lit
    summary = write_results(bpy.context.scene, result, scene, source_map)

    collection = bpy.data.collections[RESULTS_COLLECTION]
    assert collection.name in bpy.context.scene.collection.children
    assert sorted(obj.name for obj in collection.objects) == ["Box.visrad", "Panel.visrad"]
    assert sorted(summary.objects) == ["Box.visrad", "Panel.visrad"]
    assert summary.triangles == int(np.sum(result.triangle_polygon != scene.lights[0]))
    for name in ("Box", "Panel"):
        obj = bpy.data.objects[f"{name}.visrad"]
        mesh = obj.data
        used, faces = expected_part(result, scene, source_map, name)
        positions, loops, radiance, _ = mesh_arrays(mesh)
        attribute = mesh.color_attributes[RADIANCE_ATTRIBUTE]
        assert (attribute.data_type, attribute.domain) == ("FLOAT_COLOR", "POINT")
        assert mesh.color_attributes.active_color_name == RADIANCE_ATTRIBUTE
        assert mesh.color_attributes[mesh.color_attributes.render_color_index].name == RADIANCE_ATTRIBUTE
        # the back side of the two-sided panel lies SIDE_GAP x the diagonal behind its front
        expected_positions = result.vertices[used].copy()
        expected_positions[used >= first_back, 0] -= SIDE_GAP * scene.diagonal
        np.testing.assert_allclose(positions, expected_positions, rtol=0, atol=1e-6)
        assert canonical(loops) == canonical(faces)
        expected = result.radiosity[used]
        np.testing.assert_allclose(radiance[:, :3] * math.pi, expected, rtol=1e-6, atol=1e-6 * expected.max())
        np.testing.assert_array_equal(radiance[:, 3], 1.0)
        assert np.asarray(obj.matrix_world).tolist() == np.eye(4).tolist()
        assert obj["visrad_exclude"] and obj["visrad_source"] == name
        assert obj.visible_camera and not (obj.visible_diffuse or obj.visible_glossy or obj.visible_shadow)

    # geometric check of the mapping, independent of the SourceMap: where the vertices lie
    box_positions = mesh_arrays(bpy.data.objects["Box.visrad"].data)[0]
    assert (box_positions >= np.array(BOX_LOW) - 1e-6).all() and (box_positions <= np.array(BOX_HIGH) + 1e-6).all()
    panel_positions = mesh_arrays(bpy.data.objects["Panel.visrad"].data)[0]
    np.testing.assert_allclose(panel_positions[:, 0], PANEL_X, atol=2 * SIDE_GAP * scene.diagonal)
    assert result.radiosity[:, 0].max() > 0.0


def test_each_side_of_the_open_panel_is_written_and_shown_from_its_front(lit):
    scene, source_map, result, first_back = lit
    write_results(bpy.context.scene, result, scene, source_map)
    panel = bpy.data.objects["Panel.visrad"].data
    positions, loops, radiance, normals = mesh_arrays(panel)

    front = normals[:, 0] > 0.5
    back = normals[:, 0] < -0.5
    assert front.sum() == back.sum() > 0 and (front | back).all()
    # the sides see different parts of the light: their radiance differs, each as computed for its normal
    front_vertices, back_vertices = np.unique(loops[front]), np.unique(loops[back])
    assert not set(front_vertices) & set(back_vertices)
    front_points = positions[front_vertices].astype(np.float64)
    panel_polygon = np.full(len(front_points), np.flatnonzero(scene.two_sided)[0])
    for vertices, sign in ((front_vertices, 1.0), (back_vertices, -1.0)):
        expected = direct_light(scene, front_points, sign * scene.normals[panel_polygon], panel_polygon)
        order = np.lexsort(positions[vertices].T)
        reference_order = np.lexsort(positions[front_vertices].T)
        np.testing.assert_allclose(
            radiance[vertices][order, :3] * math.pi, expected[reference_order], rtol=1e-5, atol=1e-5 * expected.max()
        )
    assert np.abs(radiance[front_vertices].sum(axis=0) - radiance[back_vertices].sum(axis=0)).max() > 0.01

    # the panel's faces (written on both sides) are culled from behind in EEVEE; the box's never are
    assert [m.name for m in panel.materials] == [RADIANCE_MATERIAL, FRONT_ONLY_MATERIAL]
    material_index = np.empty(len(panel.polygons), dtype=np.int32)
    panel.polygons.foreach_get("material_index", material_index)
    np.testing.assert_array_equal(material_index, 1)
    box_mesh = bpy.data.objects["Box.visrad"].data
    assert [m.name for m in box_mesh.materials] == [RADIANCE_MATERIAL]
    for name, culled in ((RADIANCE_MATERIAL, False), (FRONT_ONLY_MATERIAL, True)):
        material = bpy.data.materials[name]
        assert material.use_backface_culling == culled
        emission = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeEmission")
        attribute = emission.inputs["Color"].links[0].from_node
        assert emission.inputs["Strength"].default_value == 1.0
        assert (attribute.bl_idname, attribute.attribute_name) == ("ShaderNodeAttribute", RADIANCE_ATTRIBUTE)
        output = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial")
        assert output.inputs["Surface"].links[0].from_node == emission


def test_discontinuity_segments_become_poly_splines_per_receiver(lit):
    scene, source_map, result, first_back = lit
    summary = write_results(bpy.context.scene, result, scene, source_map)
    collection = bpy.data.collections[DISCONTINUITIES_COLLECTION]
    assert sorted(obj.name for obj in collection.objects) == [
        "Box.visrad_discontinuities",
        "Panel.visrad_discontinuities",
    ]
    assert summary.segments == sum(len(s) for s in result.discontinuities.values())
    owner = source_map.polygon_object[scene.source_polygon]
    for polygon, segments in result.discontinuities.items():
        name = source_map.objects[owner[polygon]].name
        curve = bpy.data.objects[f"{name}.visrad_discontinuities"].data
        assert all(spline.type == "POLY" and len(spline.points) == 2 for spline in curve.splines)
        written = np.array([[tuple(p.co)[:3] for p in spline.points] for spline in curve.splines])
        np.testing.assert_allclose(written, segments, atol=1e-6)


def test_results_are_left_out_of_the_next_conversion(lit):
    scene, source_map, result, first_back = lit
    before = fingerprint(scene, source_map, {})
    write_results(bpy.context.scene, result, scene, source_map)
    again, again_map = scene_from_blender(bpy.context)
    assert fingerprint(again, again_map, {}) == before


def test_the_users_data_is_never_modified(lit):
    scene, source_map, result, first_back = lit
    before = user_data_fingerprint(ROLE_PROPERTY)
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    write_results(bpy.context.scene, result, scene, source_map)
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    write_results(bpy.context.scene, result, scene, source_map)
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    clear_results(bpy.context.scene)
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    assert owned_datablocks() == set()
    # the fingerprint does see a change of the user's data
    bpy.data.meshes["Panel"].vertices[0].co.y += 1e-3
    bpy.data.materials["warm"].node_tree.nodes["Diffuse BSDF"].inputs["Color"].default_value[0] = 0.7
    changed = user_data_fingerprint(ROLE_PROPERTY)
    assert {key for key in before if changed[key] != before[key]} == {"meshes/Panel", "materials/warm"}


def brighter(result, factor: float, discontinuities=None) -> ResultArrays:
    """The result with `factor` x its radiosity, and the given discontinuities (default none)."""
    radiosity = factor * result.radiosity
    return ResultArrays(result.vertices, result.triangles, result.triangle_polygon, radiosity, discontinuities or {})


def radiance_of(name: str) -> np.ndarray:
    return mesh_arrays(bpy.data.objects[name].data)[2]


@pytest.mark.parametrize("failing", ["_result_object", "_curve_object"])
def test_a_failed_rewrite_keeps_the_previous_results(lit, monkeypatch, failing):
    scene, source_map, result, first_back = lit
    write_results(bpy.context.scene, result, scene, source_map)
    previous = {name: radiance_of(name) for name in ("Box.visrad", "Panel.visrad")}
    datablocks = all_datablocks()
    calls = []
    original = getattr(write_back, failing)

    def fail_on_the_second_call(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            raise RuntimeError("simulated failure while building")
        return original(*args, **kwargs)

    monkeypatch.setattr(write_back, failing, fail_on_the_second_call)
    with pytest.raises(RuntimeError, match="simulated failure"):
        write_results(bpy.context.scene, brighter(result, 2.0, result.discontinuities), scene, source_map)
    assert len(calls) == 2
    assert all_datablocks() == datablocks
    for name, radiance in previous.items():
        np.testing.assert_array_equal(radiance_of(name), radiance)


def test_a_rewrite_replaces_the_previous_results(lit):
    scene, source_map, result, first_back = lit
    write_results(bpy.context.scene, result, scene, source_map)
    first = all_datablocks()
    summary = write_results(bpy.context.scene, brighter(result, 2.0), scene, source_map)
    assert summary.replaced == 4
    # same names (no ".001"), the curves gone since the new result has no discontinuities
    assert all_datablocks() == {
        name for name in first if "discontinuities" not in name.lower() and not name.startswith("curves/")
    }
    for name in ("Box.visrad", "Panel.visrad"):
        used, _ = expected_part(result, scene, source_map, name.removesuffix(".visrad"))
        expected = 2.0 * result.radiosity[used]
        np.testing.assert_allclose(radiance_of(name)[:, :3] * math.pi, expected, rtol=1e-6, atol=1e-6 * expected.max())


def test_malformed_results_are_refused_by_name_and_change_nothing(lit):
    scene, source_map, result, first_back = lit
    datablocks = all_datablocks()
    radiosity = result.radiosity.copy()
    radiosity[7, 1] = np.nan
    bad = ResultArrays(result.vertices, result.triangles, result.triangle_polygon, radiosity)
    with pytest.raises(ValueError, match=r"result\.radiosity\[7\] is not finite"):
        write_results(bpy.context.scene, bad, scene, source_map)
    polygons = result.triangle_polygon.copy()
    polygons[3] = scene.n_polygons
    other = ResultArrays(result.vertices, result.triangles, polygons, result.radiosity)
    with pytest.raises(ValueError, match=r"triangle_polygon\[3\].*another scene"):
        write_results(bpy.context.scene, other, scene, source_map)
    # the panel's back side on the front side's vertices
    front = (result.triangles < first_back).all(axis=1)
    panel = front & scene.two_sided[result.triangle_polygon]
    shared = ResultArrays(
        result.vertices,
        np.concatenate([result.triangles[front], result.triangles[panel][:, ::-1]]),
        np.concatenate([result.triangle_polygon[front], result.triangle_polygon[panel]]),
        result.radiosity,
    )
    with pytest.raises(ValueError, match="used by triangles of both sides of a surface"):
        write_results(bpy.context.scene, shared, scene, source_map)
    assert all_datablocks() == datablocks


def test_clear_results_operator_removes_every_result_datablock(lit, registered_addon):
    scene, source_map, result, first_back = lit
    assert not bpy.ops.visrad.clear_results.poll()
    before = all_datablocks()
    write_results(bpy.context.scene, result, scene, source_map)
    assert bpy.ops.visrad.clear_results.poll()
    assert bpy.ops.visrad.clear_results() == {"FINISHED"}
    assert owned_datablocks() == set()
    assert all_datablocks() == before
    assert not any(c.get(ROLE_PROPERTY) for c in bpy.context.scene.collection.children)
    assert "UNDO" in bpy.types.VISRAD_OT_clear_results.bl_options


def test_cycles_renders_each_side_of_a_two_sided_result_with_its_own_radiance(tmp_path):
    """The materials render the bake: an orthographic camera sees exactly the front side's radiance from the
    front and the back side's from behind (the back side's faces lie just behind the front's)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    panel = grid("Panel", (0.0, -0.5, -0.5), (0, 1, 0), (0, 0, 1), 1)
    light = area_light("Light", size=0.5, power=10.0, location=(0.0, 0.0, 2.0))
    scene, source_map = scene_from_blender(bpy.context)
    (polygon,) = np.flatnonzero(scene.two_sided)
    corners = scene.polygon(polygon)
    front, back = np.array([0.2, 0.4, 0.6]), np.array([0.9, 0.1, 0.3])
    result = ResultArrays(
        vertices=np.concatenate([corners, corners]),
        triangles=np.array([[0, 1, 2], [0, 2, 3], [6, 5, 4], [7, 6, 4]]),
        triangle_polygon=np.full(4, polygon),
        radiosity=math.pi * np.repeat([front, back], 4, axis=0),
    )
    write_results(bpy.context.scene, result, scene, source_map)
    panel.hide_render = light.hide_render = True

    render_scene = bpy.context.scene
    render_scene.render.engine = "CYCLES"
    # every camera ray sees the emission it renders, noise-free: the denoiser could only blur it
    render_scene.cycles.samples, render_scene.cycles.device, render_scene.cycles.use_denoising = 4, "CPU", False
    render_scene.render.resolution_x = render_scene.render.resolution_y = 4
    render_scene.render.image_settings.file_format = "OPEN_EXR"
    render_scene.view_settings.view_transform = "Standard"
    camera = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
    camera.data.type, camera.data.ortho_scale = "ORTHO", 0.5
    render_scene.collection.objects.link(camera)
    render_scene.camera = camera
    for side, x, expected in (("front", 3.0, front), ("back", -3.0, back)):
        camera.location = (x, 0.0, 0.0)
        camera.rotation_euler = (math.pi / 2, 0.0, math.pi / 2 if x > 0 else -math.pi / 2)
        path = tmp_path / f"{side}.exr"
        render_scene.render.filepath = str(path)
        bpy.ops.render.render(write_still=True)
        image = bpy.data.images.load(str(path))
        pixels = np.array(image.pixels[:]).reshape(-1, 4)[:, :3]
        np.testing.assert_allclose(pixels, np.tile(expected, (len(pixels), 1)), rtol=1e-4, err_msg=side)
