"""The "VisRad" tab of the 3D view's sidebar: settings, the converted scene, the results."""

from __future__ import annotations

import bpy

from .session import store
from .write_back import ROLE_PROPERTY, ROLE_RESULT_OBJECT, result_objects

MAX_WARNINGS_SHOWN = 8


class _VisRadPanel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "VisRad"


class VISRAD_PT_main(_VisRadPanel, bpy.types.Panel):
    """Solver settings of the scene."""

    bl_label = "VisRad"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        props = context.scene.visrad
        layout.prop(props, "preset")
        column = layout.column()
        column.enabled = props.preset == "CUSTOM"
        column.prop(props, "jnd")
        column.prop(props, "max_iterations")
        column.prop(props, "form_factors")
        row = column.row()
        row.enabled = props.form_factors == "RAYS"
        row.prop(props, "rays")
        layout.prop(props, "max_bounces")


class VISRAD_PT_scene(_VisRadPanel, bpy.types.Panel):
    """What the solver will see: the converted scene's counts and the conversion's warnings."""

    bl_label = "Scene"
    bl_parent_id = "VISRAD_PT_main"

    def draw(self, context):
        layout = self.layout
        session = store.get(context.scene)
        if session is None:
            layout.label(text="Not checked yet", icon="INFO")
        else:
            if session.dirty:
                layout.label(text="The scene changed since the check", icon="ERROR")
            layout.label(text=session.summary)
            warnings = session.source_map.warnings
            for warning in warnings[:MAX_WARNINGS_SHOWN]:
                layout.label(text=warning, icon="ERROR")
            if len(warnings) > MAX_WARNINGS_SHOWN:
                layout.label(text=f"... and {len(warnings) - MAX_WARNINGS_SHOWN} more (see the Info editor)")
        layout.operator("visrad.check_scene", icon="VIEWZOOM")
        obj = context.object
        if obj is not None and obj.get(ROLE_PROPERTY) is None:
            layout.prop(obj, "visrad_exclude", text=f'Exclude "{obj.name}"')


class VISRAD_PT_results(_VisRadPanel, bpy.types.Panel):
    """The result meshes and discontinuity curves in the scene, and how two-sided surfaces are written."""

    bl_label = "Results"
    bl_parent_id = "VISRAD_PT_main"

    def draw(self, context):
        layout = self.layout
        objects = result_objects(context.scene)
        meshes = sum(obj.get(ROLE_PROPERTY) == ROLE_RESULT_OBJECT for obj in objects)
        layout.label(text=f"{meshes} result meshes, {len(objects) - meshes} curve objects")
        column = layout.column(align=True)
        column.label(text="Two-sided surfaces: each solved side", icon="INFO")
        column.label(text="gets faces of its own, facing its way")
        layout.operator("visrad.clear_results", icon="TRASH")


classes = (VISRAD_PT_main, VISRAD_PT_scene, VISRAD_PT_results)

register, unregister = bpy.utils.register_classes_factory(classes)
