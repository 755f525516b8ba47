"""Small Blender scenes for the add-on tests, and a fingerprint of the user's data.

Requires the bpy module; import it after `pytest.importorskip("bpy")`.
"""

from __future__ import annotations

import hashlib

import bpy
import numpy as np

CUBE_QUADS = ((0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5))


def diffuse_material(name: str, colour) -> bpy.types.Material:
    """A material whose surface is one Diffuse BSDF of `colour` (RGB), as the Cycles comparisons need."""
    material = bpy.data.materials.new(name)
    tree = material.node_tree
    tree.nodes.clear()
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    diffuse = tree.nodes.new("ShaderNodeBsdfDiffuse")
    diffuse.inputs["Color"].default_value = (*colour, 1.0)
    tree.links.new(diffuse.outputs["BSDF"], output.inputs["Surface"])
    return material


def mesh_object(name: str, vertices, polygons, material=None) -> bpy.types.Object:
    """A mesh object from vertex positions and polygon loops, linked to the scene collection."""
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(map(float, v)) for v in vertices], [], [tuple(p) for p in polygons])
    if material is not None:
        mesh.materials.append(material)
    obj = bpy.data.objects.new(name, mesh)
    bpy.context.scene.collection.objects.link(obj)
    return obj


def box(name: str, low, high, material=None) -> bpy.types.Object:
    """A closed axis-aligned box from corner `low` to corner `high`, faces outwards."""
    low, high = np.asarray(low, float), np.asarray(high, float)
    corners = [low + (high - low) * (x, y, z) for z in (0, 1) for y in (0, 1) for x in (0, 1)]
    return mesh_object(name, corners, CUBE_QUADS, material)


def grid(name: str, corner, u, v, divisions: int, material=None) -> bpy.types.Object:
    """An open quad grid of divisions x divisions faces spanning corner + s u + t v, facing u x v."""
    corner, u, v = (np.asarray(a, float) for a in (corner, u, v))
    steps = np.linspace(0.0, 1.0, divisions + 1)
    vertices = [corner + s * u + t * v for t in steps for s in steps]
    row = divisions + 1
    quads = [
        (j * row + i, j * row + i + 1, (j + 1) * row + i + 1, (j + 1) * row + i)
        for j in range(divisions)
        for i in range(divisions)
    ]
    return mesh_object(name, vertices, quads, material)


def area_light(name: str, size: float, power: float, location, rotation=(0.0, 0.0, 0.0)) -> bpy.types.Object:
    """A square area light (facing its local -Z) linked to the scene collection."""
    light = bpy.data.lights.new(name, "AREA")
    light.shape, light.size, light.energy = "SQUARE", size, power
    obj = bpy.data.objects.new(name, light)
    obj.location, obj.rotation_euler = location, rotation
    bpy.context.scene.collection.objects.link(obj)
    return obj


# ---------------------------------------------------------------------------------------------------------
# Fingerprint of everything the user owns

_DATA = ("objects", "meshes", "materials", "lights", "curves", "collections", "node_groups", "worlds", "images")
# Bookkeeping that Blender itself changes while it works, not the user's data; use_nodes is deprecated (always
# on since Blender 5.0) and warns when read.
_SKIP = {"rna_type", "tag", "is_evaluated", "original", "session_uid", "is_runtime_data", "is_missing", "use_nodes"}


def user_data_fingerprint(owned_marker: str) -> dict[str, str]:
    """{"objects/Name": digest, ...} over every property (RNA properties, recursively into non-ID structs and
    collections; custom properties) of every datablock of the kinds in _DATA that does not carry the custom
    property `owned_marker` (the add-on's own datablocks)."""
    prints = {}
    for kind in _DATA:
        for datablock in getattr(bpy.data, kind):
            if datablock.get(owned_marker) is not None:
                continue
            digest = hashlib.sha256()
            _dump(datablock, digest, set(), top=True)
            for key in sorted(datablock.keys()):
                digest.update(f"[{key}]={_plain(datablock[key])}".encode())
            prints[f"{kind}/{datablock.name}"] = digest.hexdigest()
    return prints


def _dump(struct, digest, seen: set, top: bool = False) -> None:
    pointer = struct.as_pointer()
    if pointer in seen:
        return
    seen.add(pointer)
    for prop in struct.bl_rna.properties:
        name = prop.identifier
        if name in _SKIP:
            continue
        try:
            value = getattr(struct, name)
        except (AttributeError, RuntimeError, TypeError):
            continue
        if prop.type == "POINTER":
            if value is None:
                digest.update(f"{name}=None;".encode())
            elif isinstance(value, bpy.types.ID) and not (value.is_embedded_data and top):
                digest.update(f"{name}->{value.name};".encode())
            else:
                _dump(value, digest, seen)
        elif prop.type == "COLLECTION":
            digest.update(f"{name}#{len(value)};".encode())
            for item in value:
                if isinstance(item, bpy.types.ID):
                    digest.update(f"{name}->{item.name};".encode())
                else:
                    _dump(item, digest, seen)
        else:
            digest.update(f"{name}={_plain(value)};".encode())


def _plain(value):
    if hasattr(value, "to_list"):
        return value.to_list()
    if isinstance(value, str | int | float | bool | set | type(None)):
        return sorted(value) if isinstance(value, set) else value
    try:
        return [_plain(v) for v in value]
    except TypeError:
        return repr(value)
