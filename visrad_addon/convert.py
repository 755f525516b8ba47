"""Blender scene -> core.Scene, with a SourceMap that leads every polygon and vertex back to Blender.

`scene_from_blender(context_or_depsgraph)` reads the evaluated scene (modifiers applied, instances realised)
in world space and never writes to the user's objects, meshes or materials: meshes come from the evaluated
objects' temporary `to_mesh()` copies, which are freed at once.

What is read (DESIGN.md section 2 gives the units):

* Meshes (and curves, surfaces, text, metaballs: whatever `to_mesh()` turns into polygons). Polygons are kept
  as they are (planar n-gons stay polygons; core splits non-planar or non-convex ones). An object is one-sided
  when its evaluated mesh is closed (every edge shared by exactly two polygons), two-sided otherwise, like
  `Scene.from_polygons`' own rule: a closed mesh's back sides face its inside.
* Materials, from the node tree's active output: Diffuse BSDF "Color" and Principled BSDF "Base Color" give
  the reflectance; an Emission shader (Color C, Strength S) or the Principled "Emission Color" x "Emission
  Strength" give exitance E = pi * C * S, emitted from both sides of an open surface as Cycles does. Add and
  Mix shaders combine their inputs. Linked inputs (textures) are out of scope: the socket's own default value
  is used and a warning says so. No material means Blender's default grey 0.8.
* Area lights (square, rectangle, disk, ellipse) become one emitting polygon facing the light's local -Z,
  reflectance 0 (a Cycles light reflects nothing), exitance E = C * P * 2^exposure / A with A the light's
  world-space area, or C * P * 2^exposure when `normalize` is off. Disks and ellipses become regular
  DISK_SIDES-gons of the same area. Point, spot and sun lights cannot become polygons: they are listed in
  `SourceMap.warnings` and `SourceMap.unsupported_lights`, never silently dropped.
* Left out: objects whose custom property `visrad_exclude` is true (an ID property, so it works with or
  without the add-on registered; a registered `Object.visrad_exclude` BoolProperty reads the same storage),
  objects hidden from render (`hide_render`, or all their collections hidden from render or excluded from
  the view layer). The depsgraph the caller passes decides modifier levels: `context.evaluated_depsgraph_get()`
  evaluates them at viewport settings.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from ..core.errors import SceneError
from ..core.scene import Scene

EXCLUDE_PROPERTY = "visrad_exclude"
DISK_SIDES = 32
MESH_TYPES = frozenset({"MESH", "CURVE", "SURFACE", "FONT", "META"})
AREA_SHAPES = frozenset({"SQUARE", "RECTANGLE", "DISK", "ELLIPSE"})
DEFAULT_REFLECTANCE = (0.8, 0.8, 0.8)  # what Cycles renders for a surface without a material
# core requires reflectance < 1; a white Blender colour (1.0) is brought just below
MAX_REFLECTANCE = 0.999


@dataclass(frozen=True)
class SourceObject:
    """One Blender object (or one realised instance) that contributed polygons.

    name: the object's name, or "instancer/instanced[k]" for the k-th instance an instancer makes;
    object_name: name of the Blender object whose geometry it is; kind: "mesh" or "area light";
    matrix_world: (4, 4) float64 world transform used.
    """

    name: str
    object_name: str
    kind: str
    matrix_world: np.ndarray


@dataclass
class SourceMap:
    """Where every polygon and vertex of the converted core.Scene comes from.

    objects: the contributing objects; their index is the Scene's object id.
    polygon_object (P,) int64: object of each input polygon (scene.source_polygon indexes these arrays);
    polygon_index (P,) int64: polygon index in that object's evaluated mesh (-1 for a light's polygon);
    vertex_object (V,) int64, vertex_index (V,) int64: object and evaluated-mesh vertex index of each scene
    vertex (-1 for a light's corners).
    warnings: readable messages about what was approximated or left out.
    unsupported_lights: names of the point, spot and sun lights that were not converted.
    excluded: names of the objects left out (visrad_exclude or hidden from render).
    """

    objects: list[SourceObject]
    polygon_object: np.ndarray
    polygon_index: np.ndarray
    vertex_object: np.ndarray
    vertex_index: np.ndarray
    warnings: list[str] = field(default_factory=list)
    unsupported_lights: list[str] = field(default_factory=list)
    excluded: list[str] = field(default_factory=list)

    def describe_polygon(self, polygon: int) -> str:
        """'polygon k of object "name"' for input polygon `polygon`."""
        source = self.objects[self.polygon_object[polygon]]
        index = self.polygon_index[polygon]
        where = f"polygon {index} of " if index >= 0 else ""
        return f'{where}{source.kind} "{source.name}"'


@dataclass
class _Part:
    """Polygons of one source object in world space, before assembly. vertices (k, 3) float64;
    polygons: index arrays into vertices; reflectance, emission (p, 3) float64; mesh_polygon (p,) int64;
    mesh_vertex (k,) int64; two_sided (p,) bool."""

    source: SourceObject
    vertices: np.ndarray
    polygons: list[np.ndarray]
    reflectance: np.ndarray
    emission: np.ndarray
    two_sided: np.ndarray
    mesh_polygon: np.ndarray
    mesh_vertex: np.ndarray


def scene_from_blender(context_or_depsgraph) -> tuple[Scene, SourceMap]:
    """Convert the evaluated Blender scene to a validated core.Scene and its SourceMap.

    context_or_depsgraph: a bpy Context (its evaluated depsgraph is used) or a Depsgraph.
    Raises SceneError naming the object when the scene has no mesh, no light, or a polygon or transform core
    rejects (zero area, NaN or infinite coordinates, ...).
    """
    depsgraph = _depsgraph(context_or_depsgraph)
    rendered_collections = _rendered_collections(depsgraph.view_layer)
    materials = _MaterialReader()
    parts: list[_Part] = []
    warnings: list[str] = []
    unsupported: list[str] = []
    excluded: list[str] = []
    instance_counts: dict[str, int] = {}

    for instance in depsgraph.object_instances:
        evaluated = instance.object
        if evaluated.type not in MESH_TYPES and evaluated.type != "LIGHT":
            continue
        owner = instance.parent if instance.is_instance else evaluated
        if not instance.is_instance and not instance.show_self:
            continue
        if _is_excluded(owner.original) or _is_excluded(evaluated.original):
            excluded.append(owner.name)
            continue
        if _hidden_from_render(owner.original, rendered_collections):
            excluded.append(owner.name)
            continue
        name = evaluated.name
        if instance.is_instance:
            count = instance_counts.get(owner.name, 0)
            instance_counts[owner.name] = count + 1
            name = f"{owner.name}/{evaluated.name}[{count}]"
        matrix = np.array(instance.matrix_world, dtype=np.float64)
        if not np.isfinite(matrix).all():
            raise SceneError(f'object "{name}" has a non-finite world transform (NaN or infinite): {matrix.tolist()}')

        if evaluated.type == "LIGHT":
            part = _light_part(evaluated, name, matrix, warnings, unsupported)
        else:
            part = _mesh_part(evaluated, name, matrix, materials, warnings)
        if part is not None:
            parts.append(part)

    warnings.extend(materials.warnings)
    warnings.extend(_world_warnings(depsgraph.scene))
    scene_name = depsgraph.scene.name
    if not any(part.source.kind == "mesh" for part in parts):
        lights = ", ".join(f'"{p.source.name}"' for p in parts) or "none"
        raise SceneError(f'scene "{scene_name}" has no visible mesh with polygons to light (area lights: {lights})')
    if not any(part.emission.max(initial=0.0) > 0.0 for part in parts):
        reason = (
            f"; point, spot and sun lights are not supported: {', '.join(repr(n) for n in unsupported)}"
            if unsupported
            else ""
        )
        raise SceneError(
            f'scene "{scene_name}" has no light: add an area light or an emitting material '
            f"(Emission shader or Principled emission strength > 0){reason}"
        )
    return _assemble(parts, warnings, unsupported, excluded)


def _depsgraph(context_or_depsgraph):
    if hasattr(context_or_depsgraph, "evaluated_depsgraph_get"):
        return context_or_depsgraph.evaluated_depsgraph_get()
    if hasattr(context_or_depsgraph, "object_instances"):
        return context_or_depsgraph
    raise TypeError(f"expected a bpy Context or Depsgraph, got {type(context_or_depsgraph).__name__}")


def _is_excluded(obj) -> bool:
    return bool(obj.get(EXCLUDE_PROPERTY, False))


def _rendered_collections(view_layer) -> set:
    """Collections whose objects render: reachable from the scene collection through layer collections that
    are neither excluded from the view layer nor hidden from render."""
    rendered = set()
    stack = [view_layer.layer_collection]
    while stack:
        layer = stack.pop()
        if layer.exclude or layer.collection.hide_render:
            continue
        rendered.add(layer.collection.name_full)
        stack.extend(layer.children)
    return rendered


def _hidden_from_render(obj, rendered_collections: set) -> bool:
    if obj.hide_render:
        return True
    return not any(collection.name_full in rendered_collections for collection in obj.users_collection)


def _mesh_part(evaluated, name: str, matrix: np.ndarray, materials: _MaterialReader, warnings: list[str]):
    """The polygons of one evaluated mesh-like object in world space, or None (with a warning) if it has none."""
    mesh = evaluated.to_mesh()
    try:
        n_vertices, n_polygons, n_loops = len(mesh.vertices), len(mesh.polygons), len(mesh.loops)
        if n_polygons == 0:
            warnings.append(f'object "{name}" has no polygons (only vertices or edges): left out')
            return None
        local = np.empty(n_vertices * 3, dtype=np.float32)
        mesh.vertices.foreach_get("co", local)
        loop_start = np.empty(n_polygons, dtype=np.int32)
        mesh.polygons.foreach_get("loop_start", loop_start)
        material_index = np.empty(n_polygons, dtype=np.int32)
        mesh.polygons.foreach_get("material_index", material_index)
        loop_vertex = np.empty(n_loops, dtype=np.int32)
        mesh.loops.foreach_get("vertex_index", loop_vertex)
        slot_materials = [slot.material for slot in evaluated.material_slots]
    finally:
        evaluated.to_mesh_clear()

    points = local.reshape(-1, 3).astype(np.float64) @ matrix[:3, :3].T + matrix[:3, 3]
    if not np.isfinite(points).all():
        bad = int(np.flatnonzero(~np.isfinite(points).all(axis=1))[0])
        raise SceneError(f'object "{name}": vertex {bad} has a non-finite world position {points[bad].tolist()}')
    loops = np.split(loop_vertex.astype(np.int64), loop_start[1:])
    if np.linalg.det(matrix[:3, :3]) < 0.0:
        # a mirroring transform turns counter-clockwise loops clockwise; Cycles keeps the mirrored normals
        loops = [loop[::-1] for loop in loops]

    reflectance = np.empty((n_polygons, 3))
    emission = np.empty((n_polygons, 3))
    for index in np.unique(material_index):
        material = slot_materials[index] if 0 <= index < len(slot_materials) else None
        rho, exitance = materials.read(material, name)
        reflectance[material_index == index] = rho
        emission[material_index == index] = exitance

    source = SourceObject(name, evaluated.original.name, "mesh", matrix)
    two_sided = np.full(n_polygons, not _is_closed(loops), dtype=bool)
    return _Part(
        source,
        points,
        loops,
        reflectance,
        emission,
        two_sided,
        np.arange(n_polygons, dtype=np.int64),
        np.arange(n_vertices, dtype=np.int64),
    )


def _is_closed(loops: list[np.ndarray]) -> bool:
    """Whether every edge of the polygons is used exactly twice, in opposite directions."""
    starts = np.concatenate(loops)
    ends = np.concatenate([np.roll(loop, -1) for loop in loops])
    directed, counts = np.unique(np.stack([starts, ends], axis=1), axis=0, return_counts=True)
    if (counts != 1).any():
        return False
    reverse = {tuple(edge) for edge in directed.tolist()}
    return all((b, a) in reverse for a, b in directed.tolist())


def _light_part(evaluated, name: str, matrix: np.ndarray, warnings: list[str], unsupported: list[str]):
    """An area light as one emitting polygon (one-sided, facing local -Z), or None for other light types."""
    light = evaluated.data
    if light.type != "AREA":
        unsupported.append(name)
        warnings.append(
            f'{light.type.lower()} light "{name}" is not supported (only area lights become emitting polygons): '
            "it is left out; replace it with an area light or an emitting mesh"
        )
        return None
    if light.shape not in AREA_SHAPES:
        raise SceneError(f'area light "{name}" has unknown shape {light.shape!r}')
    if getattr(light, "use_temperature", False):
        warnings.append(f'area light "{name}" uses a colour temperature: only its colour is used')
    if getattr(light, "use_nodes", False) and light.node_tree is not None:
        warnings.append(f'area light "{name}" has a node tree: it is ignored, colour x power is used')
    if not math.isclose(getattr(light, "spread", math.pi), math.pi, rel_tol=1e-6):
        warnings.append(f'area light "{name}" has a spread below 180 degrees: it is treated as a diffuse emitter')

    width = light.size
    height = light.size if light.shape in ("SQUARE", "DISK") else light.size_y
    if light.shape in ("SQUARE", "RECTANGLE"):
        local = 0.5 * np.array([[-width, -height], [-width, height], [width, height], [width, -height]])
    else:
        # circumradius factor of the regular polygon with the disk's area: (n/2) R^2 sin(2 pi/n) = pi r^2
        angles = -2.0 * math.pi * np.arange(DISK_SIDES) / DISK_SIDES
        factor = math.sqrt(2.0 * math.pi / (DISK_SIDES * math.sin(2.0 * math.pi / DISK_SIDES)))
        local = 0.5 * factor * np.stack([width * np.cos(angles), height * np.sin(angles)], axis=1)
    # the clockwise order seen from +Z makes the polygon face local -Z, the direction the light emits
    corners = np.column_stack([local, np.zeros(len(local))]) @ matrix[:3, :3].T + matrix[:3, 3]
    loop = np.arange(len(corners), dtype=np.int64)
    if np.linalg.det(matrix[:3, :3]) < 0.0:
        loop = loop[::-1]

    scale_x, scale_y = np.linalg.norm(matrix[:3, 0]), np.linalg.norm(matrix[:3, 1])
    area = width * height * scale_x * scale_y * (math.pi / 4.0 if light.shape in ("DISK", "ELLIPSE") else 1.0)
    power = np.array(light.color[:3], dtype=np.float64) * light.energy * 2.0**light.exposure
    normalize = getattr(light, "normalize", True)
    if normalize and not area > 0.0:
        raise SceneError(f'area light "{name}" has zero area (size {width} x {height}, scale {scale_x} x {scale_y})')
    exitance = power / area if normalize else power
    source = SourceObject(name, evaluated.original.name, "area light", matrix)
    return _Part(
        source,
        corners,
        [loop],
        np.zeros((1, 3)),
        exitance[None, :],
        np.zeros(1, dtype=bool),
        np.full(1, -1, dtype=np.int64),
        np.full(len(corners), -1, dtype=np.int64),
    )


class _MaterialReader:
    """Reflectance and exitance of materials from their node trees, cached per material, with warnings."""

    def __init__(self):
        self.warnings: list[str] = []
        self._cache: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def read(self, material, object_name: str) -> tuple[np.ndarray, np.ndarray]:
        """(reflectance (3,), exitance (3,) W/m^2) of `material` (None: Blender's default surface)."""
        if material is None:
            return np.array(DEFAULT_REFLECTANCE), np.zeros(3)
        key = material.name_full
        if key not in self._cache:
            self._cache[key] = self._evaluate(material)
        return self._cache[key]

    def _evaluate(self, material) -> tuple[np.ndarray, np.ndarray]:
        name = material.name_full
        tree = material.node_tree
        if tree is None:
            self.warnings.append(f'material "{name}" has no node tree: its viewport colour is used as reflectance')
            return self._clamped(name, np.array(material.diffuse_color[:3], dtype=np.float64)), np.zeros(3)
        output = _active_output(tree)
        if output is None or not output.inputs["Surface"].is_linked:
            self.warnings.append(f'material "{name}" has no surface shader: it is black')
            return np.zeros(3), np.zeros(3)
        rho, radiance = self._shader(name, _linked_node(output.inputs["Surface"]))
        return self._clamped(name, rho), math.pi * radiance

    def _shader(self, name: str, node) -> tuple[np.ndarray, np.ndarray]:
        """(reflectance (3,), emitted radiance C*S (3,)) of the shader `node` outputs."""
        if node is None:
            return np.zeros(3), np.zeros(3)
        kind = node.bl_idname
        if kind == "ShaderNodeBsdfDiffuse":
            return self._colour(name, node, "Color"), np.zeros(3)
        if kind == "ShaderNodeBsdfPrincipled":
            rho = self._colour(name, node, "Base Color")
            radiance = self._colour(name, node, "Emission Color") * self._number(name, node, "Emission Strength")
            return rho, radiance
        if kind == "ShaderNodeEmission":
            return np.zeros(3), self._colour(name, node, "Color") * self._number(name, node, "Strength")
        if kind == "ShaderNodeAddShader":
            (rho_a, l_a), (rho_b, l_b) = (self._shader(name, _linked_node(s)) for s in node.inputs[:2])
            return rho_a + rho_b, l_a + l_b
        if kind == "ShaderNodeMixShader":
            fac = min(max(self._number(name, node, 0), 0.0), 1.0)
            (rho_a, l_a), (rho_b, l_b) = (self._shader(name, _linked_node(s)) for s in node.inputs[1:3])
            return (1.0 - fac) * rho_a + fac * rho_b, (1.0 - fac) * l_a + fac * l_b
        self.warnings.append(
            f'material "{name}": shader node "{node.name}" ({kind}) is not supported: '
            f"reflectance {DEFAULT_REFLECTANCE[0]} grey, no emission"
        )
        return np.array(DEFAULT_REFLECTANCE), np.zeros(3)

    def _socket(self, name: str, node, key):
        socket = node.inputs[key]
        if socket.is_linked:
            self.warnings.append(
                f'material "{name}": input "{socket.name}" of "{node.name}" is linked (textures are not '
                f"supported): its own value {_plain(socket.default_value)} is used"
            )
        return socket.default_value

    def _colour(self, name: str, node, key) -> np.ndarray:
        return np.array(self._socket(name, node, key)[:3], dtype=np.float64)

    def _number(self, name: str, node, key) -> float:
        return float(self._socket(name, node, key))

    def _clamped(self, name: str, rho: np.ndarray) -> np.ndarray:
        clamped = np.clip(rho, 0.0, MAX_REFLECTANCE)
        if not np.array_equal(clamped, rho):
            self.warnings.append(
                f'material "{name}": reflectance {rho.tolist()} brought into [0, {MAX_REFLECTANCE}] '
                "(radiosity needs every surface to absorb some light)"
            )
        return clamped


def _plain(value):
    return [round(float(v), 6) for v in value] if hasattr(value, "__len__") else round(float(value), 6)


def _active_output(tree):
    """The material output node Cycles renders with: the active one targeting Cycles or all engines."""
    outputs = [node for node in tree.nodes if node.bl_idname == "ShaderNodeOutputMaterial"]
    for node in outputs:
        if node.is_active_output and node.target in ("ALL", "CYCLES"):
            return node
    return next((node for node in outputs if node.target in ("ALL", "CYCLES")), None)


def _linked_node(socket):
    """The node feeding `socket`, through reroutes; None when nothing (or nothing enabled) is linked."""
    while socket.is_linked:
        link = socket.links[0]
        if not link.is_valid or link.is_muted:
            return None
        node = link.from_node
        if node.bl_idname != "NodeReroute":
            return node
        socket = node.inputs[0]
    return None


def _world_warnings(scene) -> list[str]:
    """A warning when the world emits light: radiosity ignores it (only polygons emit)."""
    world = scene.world
    if world is None or world.node_tree is None:
        return []
    output = _active_output_world(world.node_tree)
    node = _linked_node(output.inputs["Surface"]) if output is not None else None
    if node is None or node.bl_idname != "ShaderNodeBackground":
        return []
    colour = np.array(node.inputs["Color"].default_value[:3]) * float(node.inputs["Strength"].default_value)
    if node.inputs["Color"].is_linked or colour.max() > 0.0:
        return [f'world "{world.name}" emits light: radiosity ignores world lighting (only surfaces emit)']
    return []


def _active_output_world(tree):
    outputs = [node for node in tree.nodes if node.bl_idname == "ShaderNodeOutputWorld"]
    return next((node for node in outputs if node.is_active_output), outputs[0] if outputs else None)


_POLYGON_MENTION = re.compile(r"\bpolygon (\d+)")
_VERTEX_MENTION = re.compile(r"\bvertex (\d+)")


def _assemble(parts: list[_Part], warnings, unsupported, excluded) -> tuple[Scene, SourceMap]:
    vertex_offsets = np.cumsum([0] + [len(part.vertices) for part in parts])
    polygons = [loop + offset for part, offset in zip(parts, vertex_offsets, strict=False) for loop in part.polygons]
    source_map = SourceMap(
        objects=[part.source for part in parts],
        polygon_object=np.concatenate([np.full(len(p.polygons), i, dtype=np.int64) for i, p in enumerate(parts)]),
        polygon_index=np.concatenate([part.mesh_polygon for part in parts]),
        vertex_object=np.concatenate([np.full(len(p.vertices), i, dtype=np.int64) for i, p in enumerate(parts)]),
        vertex_index=np.concatenate([part.mesh_vertex for part in parts]),
        warnings=warnings,
        unsupported_lights=unsupported,
        excluded=excluded,
    )
    try:
        scene = Scene.from_polygons(
            np.concatenate([part.vertices for part in parts]),
            polygons,
            np.concatenate([part.reflectance for part in parts]),
            np.concatenate([part.emission for part in parts]),
            object_ids=source_map.polygon_object,
            two_sided=np.concatenate([part.two_sided for part in parts]),
        )
    except SceneError as error:
        raise SceneError(_name_culprit(str(error), source_map)) from None
    return scene, source_map


def _name_culprit(message: str, source_map: SourceMap) -> str:
    """core's message with the Blender object (and mesh polygon or vertex) its polygon or vertex number means."""
    polygon = _POLYGON_MENTION.search(message)
    if polygon is not None and int(polygon.group(1)) < len(source_map.polygon_object):
        return f"{source_map.describe_polygon(int(polygon.group(1)))}: {message}"
    vertex = _VERTEX_MENTION.search(message)
    if vertex is not None and int(vertex.group(1)) < len(source_map.vertex_object):
        index = int(vertex.group(1))
        source = source_map.objects[source_map.vertex_object[index]]
        return f'vertex {source_map.vertex_index[index]} of {source.kind} "{source.name}": {message}'
    return message
