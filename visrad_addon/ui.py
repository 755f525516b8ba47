"""The "VisRad" tab of the 3D view's sidebar: settings, the converted scene, the stages and their statistics,
the results."""

from __future__ import annotations

import bpy

from .session import store
from .stages import STATS, WRITTEN, running_stage
from .write_back import ROLE_PROPERTY, ROLE_RESULT_OBJECT, result_objects

STAGE_NAMES = {"build_skeleton": "visibility", "coarse_lighting": "coarse", "refine": "refine"}

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
        column.prop(props, "discontinuities")
        refine = column.row()
        refine.enabled = props.form_factors == "EXACT"
        refine.prop(props, "source_refinement")
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


class VISRAD_PT_solve(_VisRadPanel, bpy.types.Panel):
    """One button per stage, Bake, and the statistics of the scene's solution."""

    bl_label = "Solve"
    bl_parent_id = "VISRAD_PT_main"

    def draw(self, context):
        layout = self.layout
        column = layout.column(align=True)
        row = column.row(align=True)
        row.operator("visrad.build_skeleton", icon="OUTLINER_DATA_LIGHTPROBE")
        row.operator("visrad.coarse_lighting", icon="LIGHT_AREA")
        row = column.row(align=True)
        row.operator("visrad.refine", icon="MOD_SUBSURF")
        row.operator("visrad.write_results", icon="EXPORT")
        layout.operator("visrad.bake", icon="RENDER_STILL")
        running = running_stage(context.scene)
        if running is not None:
            layout.label(text=f"{running} is running (Esc cancels it)", icon="TIME")
        session = store.get(context.scene)
        stats = session.state.get(STATS) if session is not None else None
        if stats is None:
            layout.label(text="No solution yet", icon="INFO")
            return
        if session.dirty:
            layout.label(text="The scene changed: the next stage starts over", icon="ERROR")
        for line in stats_lines(stats, session.settings.get("max_iterations")):
            layout.label(text=line)


def stats_lines(stats: dict, max_iterations: int | None = None) -> list[str]:
    """The solution's statistics as the panel shows them."""
    if not stats.get("lit"):
        lines = ["Visibility built, no lighting yet"]
    elif stats["iterations"] == 0 and not stats["converged"]:
        lines = ["Coarse lighting, not refined yet"]
    else:
        limit = f" of {max_iterations}" if max_iterations else ""
        state = "converged" if stats["converged"] else "not converged"
        lines = [f"Refinement: {stats['iterations']}{limit} iterations, {state}"]
    skeleton = stats.get("skeleton")
    if skeleton:
        lines.append(f"Skeleton: {sum(skeleton['nodes'].values()):,} nodes, {sum(skeleton['arcs'].values()):,} arcs")
    if stats.get("discontinuities_available"):
        indirect = stats.get("discontinuities_indirect", 0)
        lines.append(
            f"Discontinuities: {stats['discontinuities_inserted']:,} inserted "
            f"of {stats['discontinuities_available']:,} found" + (f" ({indirect:,} indirect)" if indirect else "")
        )
    if stats.get("lit"):
        lines.append(f"Links: {stats['links']:,}")
        lines.append(f"Vertices: {stats['vertices']:,}, triangles: {stats['leaf_triangles']:,}")
    seconds = stats.get("seconds", {})
    if seconds:
        parts = [f"{STAGE_NAMES.get(name, name)} {value:.2f} s" for name, value in seconds.items()]
        lines.append("Time: " + ", ".join(parts))
    if "peak_bytes" in stats:
        lines.append(f"Peak memory: {stats['peak_bytes'] / 2**20:,.0f} MiB")
    return lines


class VISRAD_PT_results(_VisRadPanel, bpy.types.Panel):
    """The result meshes and discontinuity curves in the scene, and how two-sided surfaces are written."""

    bl_label = "Results"
    bl_parent_id = "VISRAD_PT_main"

    def draw(self, context):
        layout = self.layout
        objects = result_objects(context.scene)
        meshes = sum(obj.get(ROLE_PROPERTY) == ROLE_RESULT_OBJECT for obj in objects)
        layout.label(text=f"{meshes} result meshes, {len(objects) - meshes} curve objects")
        session = store.get(context.scene)
        written = session.state.get(WRITTEN) if session is not None else None
        if written is not None and objects:
            layout.label(text=f"Last written: {written['triangles']:,} triangles, {written['segments']:,} segments")
        column = layout.column(align=True)
        column.label(text="Two-sided surfaces: each solved side", icon="INFO")
        column.label(text="gets faces of its own, facing its way")
        layout.operator("visrad.clear_results", icon="TRASH")


classes = (VISRAD_PT_main, VISRAD_PT_scene, VISRAD_PT_solve, VISRAD_PT_results)

register, unregister = bpy.utils.register_classes_factory(classes)
