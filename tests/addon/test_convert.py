"""visrad_addon.convert against bench/scenes.py and DESIGN.md section 2, with the bpy module."""

import hashlib
import math
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.errors import SceneError  # noqa: E402
from visrad.visrad_addon.convert import DISK_SIDES, scene_from_blender  # noqa: E402

from bench.scenes import SCENES  # noqa: E402

SAMPLE_DIR = Path(__file__).resolve().parents[2] / "sample_blends"
SAMPLES = {
    "cornell_box": "cornell-box",
    "desk": "desk",
    "many_lights": "many-lights",
    "indirect_bedroom": "indirect-bedroom",
    "village": "village",
}


@pytest.fixture
def empty_file():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    yield bpy.context.scene


def material(name: str, shader: str, **inputs) -> "bpy.types.Material":
    mat = bpy.data.materials.new(name)
    tree = mat.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    node = tree.nodes.new(shader)
    for key, value in inputs.items():
        node.inputs[key.replace("_", " ")].default_value = value
    tree.links.new(node.outputs[0], output.inputs["Surface"])
    return mat


def mesh_object(name: str, vertices, polygons, mat=None, location=(0.0, 0.0, 0.0), collection=None):
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([list(v) for v in vertices], [], [list(p) for p in polygons])
    if mat is not None:
        mesh.materials.append(mat)
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    (collection or bpy.context.scene.collection).objects.link(obj)
    return obj


def unit_plane(name: str, mat=None, location=(0.0, 0.0, 0.0), collection=None):
    """A 1 x 1 m plane facing +z."""
    return mesh_object(name, [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)], [(0, 1, 2, 3)], mat, location, collection)


def cube(name: str, mat=None, location=(0.0, 0.0, 0.0), collection=None):
    vertices = [(x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    return mesh_object(name, vertices, quads, mat, location, collection)


def area_light(
    name: str, shape="SQUARE", size=1.0, size_y=1.0, energy=100.0, colour=(1.0, 1.0, 1.0), location=(0, 0, 3)
):
    light = bpy.data.lights.new(name, "AREA")
    light.shape, light.size, light.size_y = shape, size, size_y
    light.energy, light.color = energy, colour
    obj = bpy.data.objects.new(name, light)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    return obj


def converted_names(source_map) -> set[str]:
    return {source.name for source in source_map.objects}


def polygons_by_object(source_map) -> dict[str, np.ndarray]:
    """Input-polygon indices (int64) of each converted object, by name."""
    return {source.name: np.flatnonzero(source_map.polygon_object == i) for i, source in enumerate(source_map.objects)}


def input_polygon_areas(scene) -> np.ndarray:
    """(P_in,) area of each input polygon: the sum of its split pieces."""
    return np.bincount(scene.source_polygon, weights=scene.areas)


def input_polygon_values(scene, values: np.ndarray) -> np.ndarray:
    """Per-input-polygon rows of a per-scene-polygon array (every piece of a polygon carries its values)."""
    first_piece = np.unique(scene.source_polygon, return_index=True)[1]
    return values[first_piece]


# ---------------------------------------------------------------------------------------------------------
# The sample files against their generators


@pytest.mark.parametrize("sample", sorted(SAMPLES))
def test_sample_blend_matches_its_bench_scene(sample):
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLE_DIR / f"{sample}.blend"))
    spec = SCENES[SAMPLES[sample]]()
    scene, source_map = scene_from_blender(bpy.context)

    assert len(source_map.polygon_object) == spec.n_polygons
    assert converted_names(source_map) == set(spec.object_names)
    assert source_map.unsupported_lights == []
    reference = spec.build()
    np.testing.assert_allclose(scene.areas.sum(), reference.areas.sum(), rtol=1e-6)

    rho = input_polygon_values(scene, scene.reflectance)
    emission = input_polygon_values(scene, scene.emission)
    areas = input_polygon_areas(scene)
    reference_areas = input_polygon_areas(reference)
    for name, polygons in polygons_by_object(source_map).items():
        spec_polygons = spec.object_polygons(spec.object_names.index(name))
        assert len(polygons) == len(spec_polygons), name
        np.testing.assert_allclose(np.sort(areas[polygons]), np.sort(reference_areas[spec_polygons]), rtol=1e-5)
        # Blender stores float32: emission and reflectance agree to its precision
        np.testing.assert_allclose(emission[polygons], spec.emission[spec_polygons], rtol=1e-6, err_msg=name)
        if spec.emission[spec_polygons].max() == 0.0:
            np.testing.assert_allclose(rho[polygons], spec.reflectance[spec_polygons], atol=1e-6, err_msg=name)


def test_area_light_sample_faces_like_the_spec():
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLE_DIR / "cornell_box.blend"))
    spec = SCENES["cornell-box"]()
    scene, source_map = scene_from_blender(bpy.context)
    light = int(np.flatnonzero(scene.emission.max(axis=1) > 0)[0])
    reference = spec.build()
    reference_light = int(np.flatnonzero(reference.source_polygon == spec.lights[0])[0])
    np.testing.assert_allclose(scene.normals[light], reference.normals[reference_light], atol=1e-6)
    assert not scene.two_sided[light]
    np.testing.assert_array_equal(scene.reflectance[light], 0.0)


# ---------------------------------------------------------------------------------------------------------
# Emission and reflectance (DESIGN.md section 2)


def test_mesh_emission_is_pi_colour_strength_and_two_sided(empty_file):
    colour, strength = (0.5, 0.25, 1.0), 3.0
    unit_plane("lamp", material("glow", "ShaderNodeEmission", Color=(*colour, 1.0), Strength=strength))
    principled = material(
        "principled", "ShaderNodeBsdfPrincipled", Base_Color=(0.2, 0.4, 0.6, 1.0), Emission_Color=(1.0, 0.5, 0.0, 1.0)
    )
    principled.node_tree.nodes["Principled BSDF"].inputs["Emission Strength"].default_value = 2.0
    unit_plane("principled panel", principled, location=(0, 0, 2))
    cube("block", material("grey", "ShaderNodeBsdfDiffuse", Color=(0.3, 0.5, 0.7, 1.0)), location=(3, 0, 0))

    scene, source_map = scene_from_blender(bpy.context)
    by_name = polygons_by_object(source_map)
    emission = input_polygon_values(scene, scene.emission)
    rho = input_polygon_values(scene, scene.reflectance)
    sides = input_polygon_values(scene, scene.two_sided)
    np.testing.assert_allclose(emission[by_name["lamp"][0]], math.pi * np.array(colour) * strength, rtol=1e-6)
    np.testing.assert_array_equal(rho[by_name["lamp"][0]], 0.0)
    assert sides[by_name["lamp"][0]]  # an open emitting mesh emits from both sides
    np.testing.assert_allclose(emission[by_name["principled panel"][0]], math.pi * np.array([2.0, 1.0, 0.0]), rtol=1e-6)
    np.testing.assert_allclose(rho[by_name["principled panel"][0]], [0.2, 0.4, 0.6], rtol=1e-6)
    np.testing.assert_allclose(rho[by_name["block"]], np.tile([0.3, 0.5, 0.7], (6, 1)), rtol=1e-6)
    np.testing.assert_array_equal(emission[by_name["block"]], 0.0)
    assert not sides[by_name["block"]].any()  # closed mesh: one-sided


@pytest.mark.parametrize(
    ("shape", "size", "size_y", "area"),
    [
        ("SQUARE", 0.5, 9.0, 0.25),
        ("RECTANGLE", 0.5, 2.0, 1.0),
        ("DISK", 0.8, 9.0, math.pi * 0.16),
        ("ELLIPSE", 0.8, 0.4, math.pi * 0.4 * 0.2),
    ],
)
@pytest.mark.parametrize("normalize", [True, False])
def test_area_light_exitance_shape_and_facing(empty_file, shape, size, size_y, area, normalize):
    cube("floor block", location=(-5, -5, -1))
    colour, power, exposure, scale = np.array([1.0, 0.5, 0.25]), 40.0, 1.5, (2.0, 0.5, 1.0)
    light = area_light("panel", shape, size, size_y, power, tuple(colour))
    light.data.exposure = exposure
    light.data.normalize = normalize
    light.scale = scale
    light.rotation_euler = (math.pi / 2, 0.0, 0.0)  # local -Z turns to world +y
    scene, source_map = scene_from_blender(bpy.context)

    lit = np.flatnonzero(source_map.polygon_object[scene.source_polygon] == 1)
    world_area = area * scale[0] * scale[1]
    # Blender stores sizes and matrices in float32
    np.testing.assert_allclose(scene.areas[lit].sum(), world_area, rtol=1e-6)
    expected = colour * power * 2.0**exposure / (world_area if normalize else 1.0)
    np.testing.assert_allclose(scene.emission[lit], np.tile(expected, (len(lit), 1)), rtol=1e-6)
    np.testing.assert_allclose(scene.normals[lit], np.tile([0.0, 1.0, 0.0], (len(lit), 1)), atol=1e-6)
    assert not scene.two_sided[lit].any()
    n_corners = 4 if shape in ("SQUARE", "RECTANGLE") else DISK_SIDES
    assert len(np.flatnonzero(source_map.vertex_object == 1)) == n_corners


def test_point_spot_and_sun_lights_are_reported_by_name(empty_file):
    cube("box")
    area_light("key")
    for kind in ("POINT", "SPOT", "SUN"):
        obj = bpy.data.objects.new(f"my {kind.lower()}", bpy.data.lights.new(kind, kind))
        bpy.context.scene.collection.objects.link(obj)
    scene, source_map = scene_from_blender(bpy.context)
    assert sorted(source_map.unsupported_lights) == ["my point", "my spot", "my sun"]
    for name in source_map.unsupported_lights:
        assert any(f'"{name}"' in warning and "not supported" in warning for warning in source_map.warnings)
    assert converted_names(source_map) == {"box", "key"}


def test_unsupported_lights_alone_give_a_clear_error(empty_file):
    cube("box")
    bpy.context.scene.collection.objects.link(bpy.data.objects.new("bulb", bpy.data.lights.new("bulb", "POINT")))
    with pytest.raises(SceneError, match=r"no light.*'bulb'"):
        scene_from_blender(bpy.context)


# ---------------------------------------------------------------------------------------------------------
# What is read: evaluated geometry in world space, exclusion, render visibility


def test_modifiers_instances_and_world_space(empty_file):
    area_light("key")
    block = cube("block", location=(10.0, 0.0, 0.0))
    block.rotation_euler = (0.0, 0.0, math.pi / 2)
    array = block.modifiers.new("array", "ARRAY")
    array.count = 3
    hidden = bpy.data.collections.new("prototypes")
    unit_plane("tile", collection=hidden)
    for k in range(2):
        empty = bpy.data.objects.new(f"tile instance {k}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", hidden
        empty.location = (0.0, 5.0 + 2 * k, 0.0)
        bpy.context.scene.collection.objects.link(empty)

    scene, source_map = scene_from_blender(bpy.context)
    names = converted_names(source_map)
    assert {"tile instance 0/tile[0]", "tile instance 1/tile[0]"} <= names
    block_id = [s.name for s in source_map.objects].index("block")
    assert (source_map.polygon_object == block_id).sum() == 18  # the array made 3 cubes
    points = scene.vertices[source_map.vertex_object == block_id]
    # the array offsets along local x, which the rotation turns to world +y
    np.testing.assert_allclose(points.min(axis=0), [9.0, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(points.max(axis=0), [10.0, 3.0, 1.0], atol=1e-6)
    instance_id = [s.name for s in source_map.objects].index("tile instance 1/tile[0]")
    np.testing.assert_allclose(scene.vertices[source_map.vertex_object == instance_id][0], [0.0, 7.0, 0.0])
    assert len(bpy.data.meshes) == 2  # no temporary mesh left behind


def test_mirrored_object_keeps_its_rendered_normal(empty_file):
    area_light("key")
    plane = unit_plane("mirrored")
    plane.scale = (-1.0, 1.0, 1.0)
    scene, source_map = scene_from_blender(bpy.context)
    piece = int(np.flatnonzero(source_map.polygon_object[scene.source_polygon] == 1)[0])
    np.testing.assert_allclose(scene.normals[piece], [0.0, 0.0, 1.0], atol=1e-12)


def test_excluded_and_render_hidden_objects_are_left_out(empty_file):
    area_light("key")
    cube("kept")
    cube("excluded by toggle", location=(2, 0, 0))["visrad_exclude"] = True
    cube("hidden from render", location=(4, 0, 0)).hide_render = True
    hidden_collection = bpy.data.collections.new("render-hidden collection")
    hidden_collection.hide_render = True
    bpy.context.scene.collection.children.link(hidden_collection)
    cube("in render-hidden collection", location=(6, 0, 0), collection=hidden_collection)
    excluded_collection = bpy.data.collections.new("excluded collection")
    bpy.context.scene.collection.children.link(excluded_collection)
    cube("in excluded collection", location=(8, 0, 0), collection=excluded_collection)
    bpy.context.view_layer.layer_collection.children["excluded collection"].exclude = True
    hidden_light = area_light("hidden light")
    hidden_light.hide_render = True

    scene, source_map = scene_from_blender(bpy.context)
    assert converted_names(source_map) == {"key", "kept"}
    assert {"excluded by toggle", "hidden from render", "in render-hidden collection", "hidden light"} <= set(
        source_map.excluded
    )
    assert scene.n_polygons == 7


def _fingerprint() -> str:
    """A hash of every mesh's vertex coordinates and polygons and every material node's input values."""
    digest = hashlib.sha256()
    for mesh in sorted(bpy.data.meshes, key=lambda m: m.name):
        co = np.empty(3 * len(mesh.vertices), dtype=np.float32)
        mesh.vertices.foreach_get("co", co)
        loops = np.empty(len(mesh.loops), dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loops)
        digest.update(mesh.name.encode() + co.tobytes() + loops.tobytes())
    for mat in sorted(bpy.data.materials, key=lambda m: m.name):
        for node in mat.node_tree.nodes:
            for socket in node.inputs:
                value = getattr(socket, "default_value", None)
                if value is not None:
                    digest.update(f"{mat.name}/{node.name}/{socket.identifier}={np.asarray(value).tolist()}".encode())
    for obj in sorted(bpy.data.objects, key=lambda o: o.name):
        digest.update(f"{obj.name}{np.asarray(obj.matrix_world).tolist()}{len(obj.modifiers)}".encode())
    return digest.hexdigest()


def test_conversion_leaves_the_users_data_unchanged():
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLE_DIR / "village.blend"))
    bpy.data.objects["garage"].modifiers.new("bevel", "BEVEL")
    counts = (len(bpy.data.meshes), len(bpy.data.materials), len(bpy.data.objects))
    before = _fingerprint()
    scene_from_blender(bpy.context)
    assert _fingerprint() == before
    assert (len(bpy.data.meshes), len(bpy.data.materials), len(bpy.data.objects)) == counts


def test_linked_colour_is_reported_and_its_default_used(empty_file):
    area_light("key")
    mat = material("textured", "ShaderNodeBsdfDiffuse", Color=(0.2, 0.3, 0.4, 1.0))
    texture = mat.node_tree.nodes.new("ShaderNodeTexChecker")
    mat.node_tree.links.new(texture.outputs["Color"], mat.node_tree.nodes["Diffuse BSDF"].inputs["Color"])
    cube("checkered", mat)
    scene, source_map = scene_from_blender(bpy.context)
    assert any('"textured"' in w and "linked" in w for w in source_map.warnings)
    np.testing.assert_allclose(scene.reflectance[scene.object_ids == 1], np.tile([0.2, 0.3, 0.4], (6, 1)), rtol=1e-6)


# ---------------------------------------------------------------------------------------------------------
# Bad scenes give a clear error naming the culprit


def test_no_light_is_an_error(empty_file):
    cube("lonely box")
    with pytest.raises(SceneError, match="has no light"):
        scene_from_blender(bpy.context)


def test_no_mesh_is_an_error_naming_the_lights(empty_file):
    area_light("only light")
    with pytest.raises(SceneError, match=r'no visible mesh.*"only light"'):
        scene_from_blender(bpy.context)


def test_zero_area_face_names_its_object_and_polygon(empty_file):
    area_light("key")
    cube("fine")
    mesh_object("sliver", [(0, 0, 0), (1, 0, 0), (2, 0, 0), (0, 1, 0)], [(0, 1, 3), (0, 1, 2)])
    with pytest.raises(SceneError, match=r'polygon 1 of mesh "sliver".*zero area'):
        scene_from_blender(bpy.context)


def test_nan_transform_names_its_object(empty_file):
    area_light("key")
    broken = cube("broken")
    broken.location = (float("nan"), 0.0, 0.0)
    with pytest.raises(SceneError, match=r'"broken".*non-finite'):
        scene_from_blender(bpy.context)
