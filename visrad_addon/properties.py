"""Scene-level solver settings (`Scene.visrad`) and the per-object exclusion toggle (`Object.visrad_exclude`).

`solver_settings(props)` turns the settings into the one plain dict of keyword arguments the stage operators
give to core (the fields of DESIGN.md section 3's `Settings`); the session fingerprint includes it, so changing
a setting invalidates the session.
"""

from __future__ import annotations

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from .convert import EXCLUDE_PROPERTY

# Starting points, to be tuned with the solver's benchmarks: Accurate is the 1999 paper's mode (exact
# form factors from the visibility skeleton), Fast its ray-cast alternative.
PRESETS = {
    "ACCURATE": {"jnd": 0.02, "max_iterations": 10, "form_factors": "EXACT", "rays": 16, "discontinuities": True,
                 "source_refinement": False},
    "FAST": {"jnd": 0.05, "max_iterations": 4, "form_factors": "RAYS", "rays": 16, "discontinuities": False,
             "source_refinement": False},
}


def _apply_preset(self, _context) -> None:
    for name, value in PRESETS.get(self.preset, {}).items():
        setattr(self, name, value)


class VisRadSettings(bpy.types.PropertyGroup):
    """Solver settings of one scene."""

    preset: EnumProperty(
        name="Preset",
        description="Settings for a speed / accuracy trade-off; Custom unlocks every setting",
        items=(
            ("ACCURATE", "Accurate", "Exact form factors from global visibility, fine refinement"),
            ("FAST", "Fast", "Jittered ray-cast form factors, coarser refinement"),
            ("CUSTOM", "Custom", "Choose every setting"),
        ),
        default="ACCURATE",
        update=_apply_preset,
    )
    jnd: FloatProperty(
        name="JND",
        description="Just noticeable difference: refinement stops where the change of radiance it would make is "
        "below this fraction of the local radiance",
        default=0.02,
        min=1e-4,
        max=1.0,
        precision=3,
    )
    max_iterations: IntProperty(
        name="Max Iterations",
        description="Most refinement iterations of a bake",
        default=10,
        min=1,
        soft_max=50,
    )
    max_bounces: IntProperty(
        name="Max Bounces",
        description="Light bounces to compute: 1 is direct light only, 0 is full global illumination",
        default=0,
        min=0,
        soft_max=16,
    )
    form_factors: EnumProperty(
        name="Form Factors",
        description="How form factors between surfaces are computed",
        items=(
            ("EXACT", "Exact", "Exact occluded point-to-polygon form factors (global visibility)"),
            ("RAYS", "Rays", "Jittered ray casting, noisy but faster"),
        ),
        default="EXACT",
    )
    rays: IntProperty(
        name="Rays",
        description="Jittered rays per form factor",
        default=16,
        min=1,
        soft_max=1024,
    )
    discontinuities: BoolProperty(
        name="Discontinuities",
        description="Build the visibility skeleton of the lights and mesh along the shadow boundaries that "
        "matter (from the third refinement on); off refines at the worst samples only",
        default=True,
    )
    source_refinement: BoolProperty(
        name="Refine Sources",
        description="Gather reflected light from the parts of each surface where its radiance varies, not from "
        "its average: much more accurate indirect light near bright spots and corners, many more links (exact "
        "form factors only)",
        default=False,
    )


def solver_settings(props: VisRadSettings) -> dict:
    """The settings as core's keyword arguments: jnd, max_iterations, max_bounces (None = full global
    illumination), form_factors ('exact' or a ray count), preset ('accurate', 'fast' or 'custom')."""
    return {
        "preset": props.preset.lower(),
        # Blender stores floats in single precision: 0.02 reads back as 0.0199999995
        "jnd": float(f"{props.jnd:.7g}"),
        "max_iterations": int(props.max_iterations),
        "max_bounces": None if props.max_bounces == 0 else int(props.max_bounces),
        "form_factors": "exact" if props.form_factors == "EXACT" else int(props.rays),
        "discontinuities": bool(props.discontinuities),
        "source_refinement": bool(props.source_refinement),
    }


def _get_exclude(obj) -> bool:
    return bool(obj.get(EXCLUDE_PROPERTY, False))


def _set_exclude(obj, value: bool) -> None:
    obj[EXCLUDE_PROPERTY] = bool(value)


def _exclusion_changed(obj, _context) -> None:
    # a custom property change does not reach the depsgraph by itself; the session handler listens there
    obj.update_tag()


classes = (VisRadSettings,)


def register() -> None:
    for cls in classes:
        bpy.utils.register_class(cls)
    bpy.types.Scene.visrad = PointerProperty(type=VisRadSettings)
    # Backed by the custom property convert.py reads, so the exclusion also works (and survives) without the
    # add-on: since Blender 5.0 add-on properties are no longer stored as custom properties.
    bpy.types.Object.visrad_exclude = BoolProperty(
        name="Exclude from VisRad",
        description="Leave this object out of the radiosity solution (it neither receives nor blocks light)",
        get=_get_exclude,
        set=_set_exclude,
        update=_exclusion_changed,
    )


def unregister() -> None:
    del bpy.types.Object.visrad_exclude
    del bpy.types.Scene.visrad
    for cls in reversed(classes):
        bpy.utils.unregister_class(cls)
