"""Generate the sample .blend files from bench/scenes.py, reproducibly, with the bpy module.

    .venv/bin/python sample_blends/generate.py [--output-dir sample_blends] [names ...]

Builds cornell_box.blend, desk.blend, many_lights.blend, indirect_bedroom.blend and village.blend: one Blender
object per scene object (named after SceneSpec.object_names, its origin at the centre of its bounding box),
one Diffuse BSDF material per distinct reflectance, a camera looking into the scene, Cycles as the render
engine and a black world (radiosity ignores world light, so the renders compare like for like).

Lights. The scene's lights are one-sided emitting quads:
* Cornell box, Desk, Many Lights, Indirect bedroom: each light quad becomes a rectangular AREA light of the
  same size and place, facing the same way, with normalize on, colour C = E / max(E) and power
  P = max(E) * A, so that Cycles' exitance C * P / A equals the spec's E (DESIGN.md section 2). A Cycles light
  reflects nothing, so the converted polygon has reflectance 0 where the spec gives the light's housing.
* Village: the 30 m sky quad becomes a mesh with an Emission shader (colour E / max(E), strength
  max(E) / pi, so pi * C * S = E). Mesh emission is two-sided in Cycles; the back side faces the empty sky,
  so the scene's light is unchanged. This sample tests the mesh-emission path of the add-on.

Running the script twice gives the same geometry, materials and lights (nothing random, fixed names).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import bpy
import numpy as np
from mathutils import Matrix, Vector

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.scenes import LIGHT, SCENES, SceneSpec  # noqa: E402

# sample file name -> (bench scene, how its lights are made, camera location, camera target, lens mm)
SAMPLES = {
    "cornell_box": ("cornell-box", "area", (-0.278, -0.8, 0.273), (-0.278, 0.28, 0.273), 35.0),
    "desk": ("desk", "area", (5.6, 0.3, 1.7), (1.8, 4.2, 0.8), 18.0),
    "many_lights": ("many-lights", "area", (5.6, 0.3, 1.7), (1.8, 4.2, 0.8), 18.0),
    "indirect_bedroom": ("indirect-bedroom", "area", (4.3, 0.2, 1.8), (1.5, 3.5, 0.4), 18.0),
    "village": ("village", "mesh", (0.0, -55.0, 30.0), (0.0, 0.0, 0.0), 35.0),
}


def reset_file() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    scene.cycles.samples = 128
    scene.render.resolution_x, scene.render.resolution_y = 800, 600
    world = bpy.data.worlds.new("black world")
    world.color = (0.0, 0.0, 0.0)
    background = world.node_tree.nodes.get("Background") if world.node_tree else None
    if background is not None:
        background.inputs["Strength"].default_value = 0.0
    scene.world = world


def diffuse_material(rho) -> bpy.types.Material:
    """The Diffuse BSDF material of reflectance rho (3,), shared by every polygon with that reflectance."""
    name = "diffuse {:.3f} {:.3f} {:.3f}".format(*rho)
    material = bpy.data.materials.get(name)
    if material is not None:
        return material
    material = bpy.data.materials.new(name)
    material.diffuse_color = (*rho, 1.0)
    _shader_material(material, "ShaderNodeBsdfDiffuse", {"Color": (*rho, 1.0)})
    return material


def emission_material(name: str, colour, strength: float) -> bpy.types.Material:
    material = bpy.data.materials.new(name)
    _shader_material(material, "ShaderNodeEmission", {"Color": (*colour, 1.0), "Strength": strength})
    return material


def _shader_material(material, shader_type: str, inputs: dict) -> None:
    tree = material.node_tree
    for node in list(tree.nodes):
        tree.nodes.remove(node)
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    shader = tree.nodes.new(shader_type)
    shader.location = (-250, 0)
    for key, value in inputs.items():
        shader.inputs[key].default_value = value
    tree.links.new(shader.outputs[0], output.inputs["Surface"])


def object_arrays(spec: SceneSpec, object_id: int):
    """(vertices (k, 3) float64, polygons as local index lists, reflectance (p, 3)) of one object."""
    polygon_ids = spec.object_polygons(object_id)
    used = np.unique(np.concatenate([spec.polygons[i] for i in polygon_ids]))
    local = {int(v): k for k, v in enumerate(used)}
    polygons = [[local[v] for v in spec.polygons[i]] for i in polygon_ids]
    return spec.vertices[used], polygons, spec.reflectance[polygon_ids]


def add_mesh_object(name: str, vertices: np.ndarray, polygons, materials) -> bpy.types.Object:
    """A mesh object with its origin at the centre of its bounding box; materials: one per polygon."""
    centre = (vertices.min(axis=0) + vertices.max(axis=0)) / 2
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata((vertices - centre).tolist(), [], polygons)
    slots = list(dict.fromkeys(materials))
    for material in slots:
        mesh.materials.append(material)
    mesh.polygons.foreach_set("material_index", [slots.index(m) for m in materials])
    mesh.validate()
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = centre.tolist()
    bpy.context.scene.collection.objects.link(obj)
    return obj


def add_area_light(name: str, corners: np.ndarray, exitance: np.ndarray) -> bpy.types.Object:
    """A rectangular area light covering the quad `corners` (4, 3), emitting to the side its counter-clockwise
    order faces, with exitance (3,) W/m^2."""
    centre = corners.mean(axis=0)
    along_u = corners[1] - corners[0]
    along_v = corners[3] - corners[0]
    normal = np.cross(along_u, along_v)
    normal /= np.linalg.norm(normal)
    # the light emits along its local -Z: local Z = -normal, local X = along_u, Y completes a right-hand frame
    x_axis = along_u / np.linalg.norm(along_u)
    z_axis = -normal
    y_axis = np.cross(z_axis, x_axis)
    width, height = float(np.linalg.norm(along_u)), float(np.linalg.norm(along_v))
    light = bpy.data.lights.new(name, "AREA")
    light.shape = "RECTANGLE"
    light.size, light.size_y = width, height
    peak = float(exitance.max())
    light.color = (exitance / peak).tolist()
    light.energy = peak * width * height
    obj = bpy.data.objects.new(name, light)
    rotation = Matrix([x_axis.tolist(), y_axis.tolist(), z_axis.tolist()]).transposed()
    obj.matrix_world = Matrix.Translation(Vector(centre.tolist())) @ rotation.to_4x4()
    bpy.context.scene.collection.objects.link(obj)
    return obj


def add_camera(location, target, lens: float) -> None:
    camera = bpy.data.objects.new("camera", bpy.data.cameras.new("camera"))
    camera.data.lens = lens
    camera.location = location
    direction = Vector(target) - Vector(location)
    camera.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    bpy.context.scene.collection.objects.link(camera)
    bpy.context.scene.camera = camera


def build(sample: str) -> None:
    scene_name, light_mode, camera_location, camera_target, lens = SAMPLES[sample]
    spec = SCENES[scene_name]()
    reset_file()
    bpy.context.scene.name = sample
    for object_id, name in enumerate(spec.object_names):
        vertices, polygons, reflectance = object_arrays(spec, object_id)
        if spec.object_kinds[object_id] == LIGHT:
            exitance = spec.emission[spec.object_polygons(object_id)[0]]
            if light_mode == "area":
                add_area_light(name, vertices[polygons[0]], exitance)
            else:
                peak = float(exitance.max())
                material = emission_material(f"{name} emission", exitance / peak, peak / math.pi)
                add_mesh_object(name, vertices, polygons, [material])
            continue
        add_mesh_object(name, vertices, polygons, [diffuse_material(tuple(rho)) for rho in reflectance.tolist()])
    add_camera(camera_location, camera_target, lens)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="Generate the sample .blend files from bench/scenes.py")
    parser.add_argument(
        "names", nargs="*", metavar="NAME", help=f"samples to build (default all): {', '.join(SAMPLES)}"
    )
    parser.add_argument("--output-dir", type=Path, default=Path(__file__).resolve().parent)
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names) - set(SAMPLES))
    if unknown:
        parser.error(f"unknown sample {', '.join(unknown)}; choose from {', '.join(SAMPLES)}")
    args.output_dir.mkdir(parents=True, exist_ok=True)
    for sample in args.names or SAMPLES:
        build(sample)
        path = args.output_dir / f"{sample}.blend"
        bpy.ops.wm.save_as_mainfile(filepath=str(path), compress=True)
        print(f"wrote {path} ({path.stat().st_size / 1024:.0f} KiB)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
