"""State kept between the stage operators, one session per Blender scene, dropped when the scene changes.

A stage operator (build skeleton, coarse lighting, refine, write) continues the work of the previous one, so
the converted core Scene, its SourceMap, the solver and its result have to live somewhere between operator
calls. They cannot live in the .blend file (numpy arrays, numba structures), so they live in this module, keyed
by the Blender scene's `session_uid` (stable for the scene while Blender runs, unlike its name).

A session is valid for one *fingerprint*: a hash of the converted Scene's arrays (vertices, polygons,
reflectance, emission, sides, object ids), the names of the converted objects and the solver settings that
shape the solution (JND, bounces, form factors). Any change of geometry, transforms, materials, lights,
exclusion or those settings changes it. `max_iterations` only says when a bake stops and the preset name only
what the panel shows, so they are left out: raising the iteration limit continues the same solution.
`SessionStore.open` converts the scene, compares fingerprints and returns the existing session only when they
are equal, else a fresh one: stale state can never be used (also after an undo). The depsgraph handler only
marks sessions `dirty` (cheap), which the panel shows ("The scene changed since the check") without converting
the scene at every redraw.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .convert import SourceMap, scene_from_blender
from .write_back import ROLE_PROPERTY

# settings that do not change the solution: the session keeps its solver when only these change
_STOPPING_SETTINGS = frozenset({"max_iterations", "preset"})
_FINGERPRINT_ARRAYS = (
    "vertices",
    "polygon_offsets",
    "polygon_vertex_ids",
    "source_polygon",
    "reflectance",
    "emission",
    "two_sided",
    "object_ids",
)


def fingerprint(scene, source_map: SourceMap, settings: dict) -> str:
    """A hex digest that changes whenever the converted scene or a setting that shapes the solution changes."""
    digest = hashlib.sha256()
    for name in _FINGERPRINT_ARRAYS:
        array = np.ascontiguousarray(getattr(scene, name))
        digest.update(f"{name}:{array.dtype.str}:{array.shape};".encode())
        digest.update(array.tobytes())
    digest.update(repr([source.name for source in source_map.objects]).encode())
    digest.update(repr(sorted((k, v) for k, v in settings.items() if k not in _STOPPING_SETTINGS)).encode())
    return digest.hexdigest()


@dataclass
class Session:
    """What the stages of one Blender scene share.

    scene, source_map: the conversion the stages work on; settings: the solver keyword arguments of the latest
    `open` (those that shape the solution have not changed since the session was made); key: its fingerprint;
    layout: the objects and collections of the Blender scene then (for the depsgraph handler); state: what the
    stages store (solver, statistics, what was written), by name; dirty: the depsgraph handler saw a change
    that can alter the conversion (a hint for the panel: the next `open` decides by fingerprint).
    """

    scene: object
    source_map: SourceMap
    settings: dict
    key: str
    layout: tuple
    state: dict = field(default_factory=dict)
    dirty: bool = False

    @property
    def summary(self) -> str:
        """One line: polygons, objects and lights of the conversion."""
        source_map = self.source_map
        meshes = sum(source.kind == "mesh" for source in source_map.objects)
        area_lights = sum(source.kind == "area light" for source in source_map.objects)
        emitting = len(self.scene.lights)
        return (
            f"{len(source_map.polygon_object)} polygons ({self.scene.n_polygons} convex), {meshes} objects, "
            f"{area_lights} area lights, {emitting} emitting polygons"
        )


class SessionStore:
    """Sessions by Blender scene (its session_uid)."""

    def __init__(self):
        self._sessions: dict[int, Session] = {}

    def get(self, blender_scene) -> Session | None:
        """The scene's current session without checking it (for drawing the panel)."""
        return self._sessions.get(blender_scene.session_uid)

    def open(self, context, settings: dict) -> Session:
        """The session of context.scene for `settings`: the existing one if the converted scene and the
        settings are unchanged, else a new one (the old state is dropped). Conversion errors propagate
        (core.errors.SceneError naming the culprit) and drop the old session."""
        blender_scene = context.scene
        uid = blender_scene.session_uid
        try:
            scene, source_map = scene_from_blender(context)
        except Exception:
            self._sessions.pop(uid, None)
            raise
        key = fingerprint(scene, source_map, settings)
        session = self._sessions.get(uid)
        if session is not None and session.key == key:
            session.dirty = False
            session.settings = dict(settings)
            session.layout = _layout_signature(blender_scene)
            return session
        session = Session(scene, source_map, dict(settings), key, _layout_signature(blender_scene))
        self._sessions[uid] = session
        return session

    def clear(self) -> None:
        self._sessions.clear()


store = SessionStore()


def _layout_signature(blender_scene) -> tuple:
    """Which objects and collections the scene has and which are hidden from render (the add-on's own left
    out): what a Collection or Scene update may have changed, compared instead of converting again."""
    objects = sorted((o.name, o.hide_render) for o in blender_scene.objects if o.get(ROLE_PROPERTY) is None)
    collections = sorted(
        (c.name, c.hide_render) for c in blender_scene.collection.children_recursive if c.get(ROLE_PROPERTY) is None
    )
    return tuple(objects), tuple(collections)


def _changes_conversion(datablock, update) -> bool:
    """Whether a depsgraph update of one of the user's datablocks can change the converted scene. Objects
    also get shading updates when something else in the scene changes (e.g. results are written): only
    their geometry and transform count."""
    if isinstance(datablock, bpy.types.Object):
        return update.is_updated_geometry or update.is_updated_transform
    if isinstance(datablock, bpy.types.Material | bpy.types.Light | bpy.types.NodeTree):
        return update.is_updated_shading or update.is_updated_geometry
    return update.is_updated_geometry and not isinstance(datablock, bpy.types.Collection | bpy.types.Scene)


@persistent
def _on_depsgraph_update(blender_scene, depsgraph) -> None:
    session = store.get(blender_scene)
    if session is None or session.dirty:
        return
    layout_changed = False
    for update in depsgraph.updates:
        datablock = update.id.original
        # the add-on's own results change the depsgraph too, but conversion leaves them out; a material's
        # embedded node tree is reported with its material
        if datablock.get(ROLE_PROPERTY) is not None or datablock.is_embedded_data:
            continue
        if _changes_conversion(datablock, update):
            session.dirty = True
            return
        layout_changed |= isinstance(datablock, bpy.types.Collection | bpy.types.Scene)
    if layout_changed and _layout_signature(blender_scene) != session.layout:
        session.dirty = True


@persistent
def _on_load(*_args) -> None:
    """A newly loaded file has new scenes: nothing of the previous file's sessions applies."""
    store.clear()


def register() -> None:
    bpy.app.handlers.depsgraph_update_post.append(_on_depsgraph_update)
    bpy.app.handlers.load_pre.append(_on_load)


def unregister() -> None:
    for handlers, handler in (
        (bpy.app.handlers.depsgraph_update_post, _on_depsgraph_update),
        (bpy.app.handlers.load_pre, _on_load),
    ):
        if handler in handlers:
            handlers.remove(handler)
    store.clear()
