"""Radiosity results -> Blender: a result mesh per receiving object and discontinuity curves.

`write_results(blender_scene, result, scene, source_map)` takes any object with the fields of DESIGN.md
section 3's `Result` (the `RadiosityResult` protocol below; `ResultArrays` is a plain implementation), the core
Scene the result was solved on and the SourceMap convert.py made with it. For every mesh object that owns
result triangles it builds:

* `<name>.visrad` in the collection "VisRad Results": the leaf triangles of that object's polygons, with the
  FLOAT_COLOR POINT attribute `visrad_radiance` = B / pi (exitant radiance, linear, W/(m^2 sr)) set as active
  and render colour, and a material that renders it (an Emission shader of strength 1 fed by the attribute).
  A face's corners are the result vertices in the result's order, so a vertex shared by triangles of one
  polygon is one mesh vertex and colours interpolate across it. Area lights get no result object: they are
  Blender lights, not meshes.
* `<name>.visrad_discontinuities` in the collection "VisRad Discontinuities": one poly spline of two points per
  discontinuity segment inserted on the object's polygons (only for objects that have segments).

Space. Result meshes and curves are in world space with an identity transform: a radiosity solution is the
lighting of the scene as it was converted (instances realised, modifiers applied), so it does not follow the
original object when that is moved later, and nothing depends on the original's transform being invertible.

Sides. A result triangle carries the radiosity of the side it faces: its corners are counter-clockwise seen
from that side (the hierarchy's triangles are counter-clockwise around their polygon's normal, the front).
A polygon of a closed mesh has front triangles only (its back faces the inside and is never seen); so may an
open surface whose back side was not solved, and its faces then show that side's values from both sides. An
open surface solved on both sides comes with a second set of triangles over the same polygon, wound the other
way, on vertices of their own. The result mesh keeps both sets as faces facing away from each other, the
back side's moved behind the front by SIDE_GAP x the scene's diagonal (0.1 mm in a 10 m room), so that
whichever side a ray or the viewport looks at, the nearest face is that side's: renderers need no
transparency trick (coincident faces would leave it to chance which one is hit). Faces of surfaces written on
both sides use the material "VisRad Radiance (front only)", with back-face culling for EEVEE and the
viewport, whose depth buffers cannot separate such a small gap; Cycles needs no culling.

Rendering. Result objects are visible to camera rays only (not to diffuse, glossy, transmission, volume or
shadow rays): the bake already contains the lighting, and emitting it into the scene again would count it
twice. Hide the original objects (or render the results alone) to see the bake. Result objects carry the
custom property `visrad_exclude`, so converting the scene again leaves them out.

Safety. The user's objects, meshes and materials are only read. Writing builds every new datablock first and
links the new collections into the scene; only then are the previous results (the collections marked as the
add-on's, their objects, meshes, curves and materials) removed and the new ones renamed to the plain names.
If building fails, the new datablocks are removed and the previous results stay as they were.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import bpy
import numpy as np

from .convert import EXCLUDE_PROPERTY

RESULTS_COLLECTION = "VisRad Results"
DISCONTINUITIES_COLLECTION = "VisRad Discontinuities"
RADIANCE_ATTRIBUTE = "visrad_radiance"
RESULT_SUFFIX = ".visrad"
DISCONTINUITY_SUFFIX = ".visrad_discontinuities"
RADIANCE_MATERIAL = "VisRad Radiance"
FRONT_ONLY_MATERIAL = "VisRad Radiance (front only)"
# How far behind the front faces the back side of a surface written on both sides is put, relative to the
# scene's bounding-box diagonal: far above float32 resolution (1e-7 relative), far below what can be seen.
SIDE_GAP = 1e-5

# Custom properties that mark what the add-on owns, so that only those datablocks are ever removed.
ROLE_PROPERTY = "visrad_role"
SOURCE_PROPERTY = "visrad_source"
ROLE_RESULTS = "results"
ROLE_DISCONTINUITIES = "discontinuities"
ROLE_RESULT_OBJECT = "result"
ROLE_DISCONTINUITY_OBJECT = "discontinuity curves"
ROLE_MATERIAL = "radiance material"
_COLLECTION_ROLES = (ROLE_RESULTS, ROLE_DISCONTINUITIES)
_OBJECT_ROLES = (ROLE_RESULT_OBJECT, ROLE_DISCONTINUITY_OBJECT)


class RadiosityResult(Protocol):
    """What write_results reads from a solver result (DESIGN.md section 3).

    vertices (N, 3) float: world-space positions; triangles (T, 3) int: vertex ids, counter-clockwise seen
    from the side whose radiosity they carry; triangle_polygon (T,) int: the core Scene polygon of each
    triangle; radiosity (N, 3) float: B in W/m^2 (linear RGB) at each vertex; discontinuities: scene polygon
    -> (M, 2, 3) world-space segments inserted on it.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_polygon: np.ndarray
    radiosity: np.ndarray
    discontinuities: Mapping[int, np.ndarray]


@dataclass(frozen=True)
class ResultArrays:
    """A plain RadiosityResult (fields as in the protocol), for results not made by the solver."""

    vertices: np.ndarray
    triangles: np.ndarray
    triangle_polygon: np.ndarray
    radiosity: np.ndarray
    discontinuities: Mapping[int, np.ndarray] = field(default_factory=dict)


@dataclass(frozen=True)
class WriteSummary:
    """What write_results made: names of the result objects and curve objects, the counts written, and the
    number of previous result objects it replaced."""

    objects: list[str]
    curves: list[str]
    triangles: int
    segments: int
    replaced: int


@dataclass(frozen=True)
class _Checked:
    vertices: np.ndarray
    triangles: np.ndarray
    triangle_polygon: np.ndarray
    radiosity: np.ndarray
    discontinuities: dict[int, np.ndarray]


def write_results(blender_scene, result: RadiosityResult, scene, source_map) -> WriteSummary:
    """Write `result` (solved on core Scene `scene`, converted with `source_map`) into `blender_scene`,
    replacing its previous results only once the new ones are complete. Raises ValueError naming the field
    and index when the result is malformed or does not belong to `scene`; nothing is changed then."""
    checked = _checked(result, scene)
    receivers = _receivers(checked, scene, source_map)
    built: list = []
    try:
        materials = _Materials(built)
        results = _new_collection(RESULTS_COLLECTION, ROLE_RESULTS, built)
        objects = []
        for source, triangle_ids in receivers:
            obj = _result_object(source, checked, scene, triangle_ids, materials, built)
            results.objects.link(obj)
            objects.append(obj)
        curves = []
        segments = _segments_by_object(checked, scene, source_map)
        if segments:
            discontinuities = _new_collection(DISCONTINUITIES_COLLECTION, ROLE_DISCONTINUITIES, built)
            for source, object_segments in segments:
                curve = _curve_object(source, object_segments, built)
                discontinuities.objects.link(curve)
                curves.append(curve)
        old_collections = _owned_collections(blender_scene)
        for collection, _ in built:
            if isinstance(collection, bpy.types.Collection):
                blender_scene.collection.children.link(collection)
    except BaseException:
        _remove_built(built)
        raise
    replaced = _remove_owned(blender_scene, old_collections)
    for datablock, name in built:
        datablock.name = name
    return WriteSummary(
        objects=[obj.name for obj in objects],
        curves=[curve.name for curve in curves],
        triangles=int(sum(len(ids) for _, ids in receivers)),
        segments=int(sum(len(s) for _, s in segments)),
        replaced=replaced,
    )


def clear_results(blender_scene) -> int:
    """Remove the scene's result and discontinuity collections with their objects, meshes, curves and
    materials; returns the number of objects removed."""
    return _remove_owned(blender_scene, _owned_collections(blender_scene))


def result_objects(blender_scene) -> list:
    """The result and discontinuity objects currently in `blender_scene`'s VisRad collections."""
    return [
        obj
        for collection in _owned_collections(blender_scene)
        for obj in collection.objects
        if obj.get(ROLE_PROPERTY) in _OBJECT_ROLES
    ]


# ---------------------------------------------------------------------------------------------------------
# Input checks


def _checked(result: RadiosityResult, scene) -> _Checked:
    vertices = _float_array(result.vertices, "vertices", (-1, 3))
    radiosity = _float_array(result.radiosity, "radiosity", (len(vertices), 3))
    triangles = np.asarray(result.triangles)
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not np.issubdtype(triangles.dtype, np.integer):
        raise ValueError(f"result.triangles must be a (T, 3) integer array, got {triangles.dtype} {triangles.shape}")
    triangles = triangles.astype(np.int64)
    bad = np.flatnonzero(((triangles < 0) | (triangles >= len(vertices))).any(axis=1))
    if len(bad):
        raise ValueError(
            f"result.triangles[{bad[0]}] = {triangles[bad[0]].tolist()} uses a vertex outside 0..{len(vertices) - 1}"
        )
    repeated = np.flatnonzero((triangles == np.roll(triangles, 1, axis=1)).any(axis=1))
    if len(repeated):
        raise ValueError(f"result.triangles[{repeated[0]}] = {triangles[repeated[0]].tolist()} repeats a vertex")
    polygons = np.asarray(result.triangle_polygon)
    if polygons.shape != (len(triangles),) or not np.issubdtype(polygons.dtype, np.integer):
        raise ValueError(
            f"result.triangle_polygon must be a ({len(triangles)},) integer array, "
            f"got {polygons.dtype} {polygons.shape}"
        )
    polygons = polygons.astype(np.int64)
    outside = np.flatnonzero((polygons < 0) | (polygons >= scene.n_polygons))
    if len(outside):
        raise ValueError(
            f"result.triangle_polygon[{outside[0]}] = {polygons[outside[0]]} is not a polygon of the scene "
            f"(0..{scene.n_polygons - 1}): the result was solved on another scene"
        )
    discontinuities = {}
    for polygon, segments in dict(result.discontinuities).items():
        if not 0 <= int(polygon) < scene.n_polygons:
            raise ValueError(f"result.discontinuities has polygon {polygon}, not a polygon of the scene")
        discontinuities[int(polygon)] = _float_array(segments, f"discontinuities[{polygon}]", (-1, 2, 3))
    return _Checked(vertices, triangles, polygons, radiosity, discontinuities)


def _float_array(values, name: str, shape: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    expected = tuple(array.shape[0] if size == -1 and array.ndim else size for size in shape)
    if array.shape != expected:
        wanted = " x ".join("any" if size == -1 else str(size) for size in shape)
        raise ValueError(f"result.{name} must have shape ({wanted}), got {array.shape}")
    if not np.isfinite(array).all():
        row = int(np.flatnonzero(~np.isfinite(array.reshape(len(array), -1)).all(axis=1))[0])
        raise ValueError(f"result.{name}[{row}] is not finite: {array[row].tolist()}")
    return array


def _receivers(checked: _Checked, scene, source_map) -> list[tuple[object, np.ndarray]]:
    """(SourceObject, its triangle ids) for every mesh object owning triangles, in source-map order."""
    owner = _polygon_owner(scene, source_map)[checked.triangle_polygon]
    order = np.argsort(owner, kind="stable")
    starts = np.searchsorted(owner[order], np.arange(len(source_map.objects) + 1))
    receivers = []
    for index, source in enumerate(source_map.objects):
        ids = order[starts[index] : starts[index + 1]]
        if source.kind == "mesh" and len(ids):
            receivers.append((source, ids))
    return receivers


def _polygon_owner(scene, source_map) -> np.ndarray:
    """(P,) source-map object index of every core Scene polygon (split pieces map to their input polygon)."""
    return np.asarray(source_map.polygon_object)[np.asarray(scene.source_polygon)]


def _segments_by_object(checked: _Checked, scene, source_map) -> list[tuple[object, np.ndarray]]:
    owner = _polygon_owner(scene, source_map)
    grouped: dict[int, list[np.ndarray]] = {}
    for polygon, segments in sorted(checked.discontinuities.items()):
        if len(segments):
            grouped.setdefault(int(owner[polygon]), []).append(segments)
    return [
        (source_map.objects[index], np.concatenate(grouped[index]))
        for index in sorted(grouped)
        if source_map.objects[index].kind == "mesh"
    ]


# ---------------------------------------------------------------------------------------------------------
# Building. Every datablock made is appended to `built` at once with the name it will get, so that a failure
# can remove it, and so that it can be renamed once the previous results (which hold the names) are gone.


def _named(datablock, name: str, role: str, built: list):
    built.append((datablock, name))
    datablock[ROLE_PROPERTY] = role
    return datablock


def _new_collection(name: str, role: str, built: list):
    return _named(bpy.data.collections.new(name), name, role, built)


def _result_object(source, checked: _Checked, scene, triangle_ids: np.ndarray, materials: _Materials, built: list):
    """The result mesh object of one receiver: its triangles, the radiance attribute and the materials."""
    triangles = checked.triangles[triangle_ids]
    polygons = checked.triangle_polygon[triangle_ids]
    used, corners = np.unique(triangles, return_inverse=True)
    corners = corners.reshape(-1, 3)
    name = f"{source.name}{RESULT_SUFFIX}"
    positions = checked.vertices[used].copy()
    back, both_sides = _sides(checked.vertices, triangles, polygons, scene.normals)
    moved = back & both_sides
    if moved.any():
        shared = np.intersect1d(corners[moved], corners[~moved])
        if len(shared):
            raise ValueError(
                f"result vertex {used[shared[0]]} is used by triangles of both sides of a surface: each side "
                "needs vertices of its own"
            )
        direction = np.zeros_like(positions)
        direction[corners[moved].ravel()] = np.repeat(scene.normals[polygons[moved]], 3, axis=0)
        positions -= SIDE_GAP * scene.diagonal * direction

    mesh = _named(bpy.data.meshes.new(name), name, ROLE_RESULT_OBJECT, built)
    mesh.vertices.add(len(used))
    mesh.vertices.foreach_set("co", positions.astype(np.float32).ravel())
    mesh.loops.add(3 * len(corners))
    mesh.loops.foreach_set("vertex_index", corners.astype(np.int32).ravel())
    mesh.polygons.add(len(corners))
    mesh.polygons.foreach_set("loop_start", np.arange(0, 3 * len(corners), 3, dtype=np.int32))

    mesh.materials.append(materials.radiance)
    if both_sides.any():
        mesh.materials.append(materials.front_only)
        mesh.polygons.foreach_set("material_index", both_sides.astype(np.int32))
    mesh.update(calc_edges=True)

    radiance = np.ones((len(used), 4), dtype=np.float32)
    radiance[:, :3] = checked.radiosity[used] / math.pi
    attribute = mesh.color_attributes.new(RADIANCE_ATTRIBUTE, "FLOAT_COLOR", "POINT")
    attribute.data.foreach_set("color", radiance.ravel())
    mesh.color_attributes.active_color = attribute
    mesh.color_attributes.render_color_index = mesh.color_attributes.active_color_index

    obj = _named(bpy.data.objects.new(name, mesh), name, ROLE_RESULT_OBJECT, built)
    _mark_owned_object(obj, source.name)
    for ray in ("diffuse", "glossy", "transmission", "volume_scatter", "shadow"):
        setattr(obj, f"visible_{ray}", False)
    return obj


def _sides(vertices, triangles, polygons, normals) -> tuple[np.ndarray, np.ndarray]:
    """(back (T,) bool: the triangle faces against its polygon's normal, both_sides (T,) bool: its polygon has
    triangles facing both ways)."""
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    back = np.einsum("ij,ij->i", np.cross(b - a, c - a), normals[polygons]) < 0.0
    count = int(polygons.max()) + 1
    has_front = np.bincount(polygons[~back], minlength=count) > 0
    has_back = np.bincount(polygons[back], minlength=count) > 0
    return back, (has_front & has_back)[polygons]


def _curve_object(source, segments: np.ndarray, built: list):
    """A curve object with one two-point poly spline per segment (M, 2, 3), world space."""
    name = f"{source.name}{DISCONTINUITY_SUFFIX}"
    curve = _named(bpy.data.curves.new(name, "CURVE"), name, ROLE_DISCONTINUITY_OBJECT, built)
    curve.dimensions = "3D"
    points = np.ones((len(segments), 2, 4), dtype=np.float32)
    points[:, :, :3] = segments
    for segment in points:
        spline = curve.splines.new("POLY")
        spline.points.add(1)
        spline.points.foreach_set("co", segment.ravel())
    obj = _named(bpy.data.objects.new(name, curve), name, ROLE_DISCONTINUITY_OBJECT, built)
    _mark_owned_object(obj, source.name)
    return obj


def _mark_owned_object(obj, source_name: str) -> None:
    obj[SOURCE_PROPERTY] = source_name
    obj[EXCLUDE_PROPERTY] = True


class _Materials:
    """The two radiance materials, made on first use."""

    def __init__(self, built: list):
        self._built = built
        self._radiance = None
        self._front_only = None

    @property
    def radiance(self):
        if self._radiance is None:
            self._radiance = _radiance_material(RADIANCE_MATERIAL, front_only=False, built=self._built)
        return self._radiance

    @property
    def front_only(self):
        if self._front_only is None:
            self._front_only = _radiance_material(FRONT_ONLY_MATERIAL, front_only=True, built=self._built)
        return self._front_only


def _radiance_material(name: str, front_only: bool, built: list):
    """Emission of strength 1 coloured by the radiance attribute; with front_only, back faces are culled in
    EEVEE and the viewport."""
    material = _named(bpy.data.materials.new(name), name, ROLE_MATERIAL, built)
    if bpy.app.version < (5, 0, 0):
        # node trees are always used from Blender 5.0 on, where the switch is deprecated
        material.use_nodes = True
    tree = material.node_tree
    tree.nodes.clear()
    attribute = tree.nodes.new("ShaderNodeAttribute")
    attribute.attribute_type = "GEOMETRY"
    attribute.attribute_name = RADIANCE_ATTRIBUTE
    emission = tree.nodes.new("ShaderNodeEmission")
    emission.inputs["Strength"].default_value = 1.0
    output = tree.nodes.new("ShaderNodeOutputMaterial")
    tree.links.new(attribute.outputs["Color"], emission.inputs["Color"])
    tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    attribute.location, emission.location, output.location = (-400, 0), (-150, 0), (100, 0)
    material.use_backface_culling = front_only
    return material


# ---------------------------------------------------------------------------------------------------------
# Removal


def _owned_collections(blender_scene) -> list:
    return [c for c in blender_scene.collection.children if c.get(ROLE_PROPERTY) in _COLLECTION_ROLES]


def _remove_owned(blender_scene, collections: list) -> int:
    """Remove `collections` (the add-on's) with the objects and data the add-on made; anything of the user's
    found inside them is moved to the scene's own collection first. Returns the number of objects removed."""
    removed = 0
    data_blocks, materials = [], []
    for collection in collections:
        for child in list(collection.children):
            blender_scene.collection.children.link(child)
        for obj in list(collection.objects):
            if obj.get(ROLE_PROPERTY) not in _OBJECT_ROLES:
                if len(obj.users_collection) == 1:
                    blender_scene.collection.objects.link(obj)
                continue
            if obj.data is not None:
                data_blocks.append(obj.data)
                materials.extend(m for m in getattr(obj.data, "materials", []) if m is not None)
            bpy.data.objects.remove(obj)
            removed += 1
        bpy.data.collections.remove(collection)
    for data in data_blocks:
        if data.users == 0 and data.get(ROLE_PROPERTY) in _OBJECT_ROLES:
            _remove_datablock(data)
    for material in {m.name_full: m for m in materials}.values():
        if material.users == 0 and material.get(ROLE_PROPERTY) == ROLE_MATERIAL:
            bpy.data.materials.remove(material)
    return removed


def _remove_built(built: list) -> None:
    """Remove the datablocks of a write that failed, objects first (they use the others)."""
    for datablock, _ in sorted(built, key=lambda pair: not isinstance(pair[0], bpy.types.Object)):
        _remove_datablock(datablock)


def _remove_datablock(datablock) -> None:
    owners = {
        bpy.types.Object: bpy.data.objects,
        bpy.types.Mesh: bpy.data.meshes,
        bpy.types.Curve: bpy.data.curves,
        bpy.types.Material: bpy.data.materials,
        bpy.types.Collection: bpy.data.collections,
    }
    for kind, owner in owners.items():
        if isinstance(datablock, kind):
            owner.remove(datablock)
            return
    raise TypeError(f"cannot remove {type(datablock).__name__} {datablock.name!r}")
