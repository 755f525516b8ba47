"""The operators that need no solver: check the scene (conversion summary and warnings) and clear results.

Operators stay thin: they read the scene's settings, call convert / session / write_back, and report.
The stage operators (build skeleton, coarse lighting, refine, bake, write results) are in stages.py.
"""

from __future__ import annotations

import bpy

from ..core.errors import SceneError
from .properties import solver_settings
from .session import store
from .write_back import clear_results, result_objects


class VISRAD_OT_check_scene(bpy.types.Operator):
    """Convert the scene the way the solver reads it: polygon and light counts, and what is left out"""

    bl_idname = "visrad.check_scene"
    bl_label = "Check Scene"
    bl_options = {"REGISTER"}

    def execute(self, context):
        try:
            session = store.open(context, solver_settings(context.scene.visrad))
        except SceneError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        warnings = session.source_map.warnings
        for warning in warnings:
            self.report({"WARNING"}, warning)
        self.report({"INFO"}, f"{session.summary}; {len(warnings)} warnings")
        return {"FINISHED"}


class VISRAD_OT_clear_results(bpy.types.Operator):
    """Remove the VisRad result meshes, discontinuity curves, their collections and materials"""

    bl_idname = "visrad.clear_results"
    bl_label = "Clear Results"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not result_objects(context.scene):
            cls.poll_message_set("The scene has no VisRad results")
            return False
        return True

    def execute(self, context):
        removed = clear_results(context.scene)
        self.report({"INFO"}, f"Removed {removed} VisRad result objects")
        return {"FINISHED"}


classes = (VISRAD_OT_check_scene, VISRAD_OT_clear_results)

register, unregister = bpy.utils.register_classes_factory(classes)
