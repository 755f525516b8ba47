"""State kept between the stage operators, one session per Blender scene, dropped when the scene changes.

A stage operator (build skeleton, coarse lighting, refine, write) continues the work of the previous one, so
the converted core Scene, its SourceMap, the solver and its result have to live somewhere between operator
calls. They cannot live in the .blend file (numpy arrays, numba structures), so they live in this module, keyed
by the Blender scene's `session_uid` (stable for the scene while Blender runs, unlike its name).

A session is valid for one *fingerprint*: a hash of the converted Scene's arrays (vertices, polygons,
reflectance, emission, sides, object ids), the names of the converted objects and the solver settings. Any
change of geometry, transforms, materials, lights, exclusion or settings changes it. `SessionStore.open`
converts the scene, compares fingerprints and returns the existing session only when they are equal, else a
fresh one: stale state can never be used. The depsgraph handler only marks sessions `dirty` (cheap), which
the panel shows as "out of date" without converting the scene at every redraw.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field

import bpy
import numpy as np
from bpy.app.handlers import persistent

from .convert import SourceMap, scene_from_blender
from .write_back import ROLE_PROPERTY

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
    """A hex digest that changes whenever the converted scene or the solver settings change."""
    digest = hashlib.sha256()
    for name in _FINGERPRINT_ARRAYS:
        array = np.ascontiguousarray(getattr(scene, name))
        digest.update(f"{name}:{array.dtype.str}:{array.shape};".encode())
        digest.update(array.tobytes())
    digest.update(repr([source.name for source in source_map.objects]).encode())
    digest.update(repr(sorted(settings.items())).encode())
    return digest.hexdigest()


@dataclass
class Session:
    """What the stages of one Blender scene share.

    scene, source_map: the conversion the stages work on; settings: the solver keyword arguments it was made
    with; key: its fingerprint; state: what the stages store (solver, result, statistics), by name;
    dirty: something in Blender changed since the conversion (the next `open` decides if it matters).
    """

    scene: object
    source_map: SourceMap
    settings: dict
    key: str
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
            return session
        session = Session(scene, source_map, dict(settings), key)
        self._sessions[uid] = session
        return session

    def discard(self, blender_scene) -> None:
        self._sessions.pop(blender_scene.session_uid, None)

    def clear(self) -> None:
        self._sessions.clear()

    def mark_dirty(self, blender_scene) -> None:
        session = self._sessions.get(blender_scene.session_uid)
        if session is not None:
            session.dirty = True


store = SessionStore()

# What a depsgraph update must touch to possibly change the converted scene: geometry, transforms, materials
# (shading) and lights; selection or viewport-only changes arrive as updates too and are ignored.
_RELEVANT_TYPES = (bpy.types.Object, bpy.types.Mesh, bpy.types.Material, bpy.types.Light, bpy.types.Collection)


@persistent
def _on_depsgraph_update(blender_scene, depsgraph) -> None:
    if store.get(blender_scene) is None:
        return
    for update in depsgraph.updates:
        datablock = update.id.original
        # the add-on's own results change the depsgraph too, but conversion leaves them out
        if not isinstance(datablock, _RELEVANT_TYPES) or datablock.get(ROLE_PROPERTY) is not None:
            continue
        changed = update.is_updated_geometry or update.is_updated_transform or update.is_updated_shading
        if changed or isinstance(datablock, bpy.types.Collection):
            store.mark_dirty(blender_scene)
            return


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
