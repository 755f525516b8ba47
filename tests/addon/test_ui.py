"""The sidebar panels draw what exists: every property and operator they show is real, and they show the
session's summary and warnings. Background mode has no region to draw in, so draw() runs on a layout stand-in
that checks each property against the RNA of its owner and each operator against bpy.ops."""

import pytest

bpy = pytest.importorskip("bpy")

from visrad.visrad_addon import stages, ui  # noqa: E402
from visrad.visrad_addon.session import store  # noqa: E402

from tests.addon.blender_scenes import area_light, box, diffuse_material  # noqa: E402

ICONS = {item.identifier for item in bpy.types.UILayout.bl_rna.functions["label"].parameters["icon"].enum_items}


class CheckingLayout:
    """Records labels, properties and operators; rejects names and icons Blender would not find."""

    def __init__(self, record=None):
        self.record = record if record is not None else []
        self.use_property_split = self.use_property_decorate = False
        self.enabled = True

    def column(self, align=False):
        return CheckingLayout(self.record)

    row = column

    def label(self, text="", icon="NONE"):
        assert icon in ICONS, f"no icon {icon!r}"
        self.record.append(("label", text))

    def prop(self, data, name, text=None):
        assert name in data.bl_rna.properties, f"{type(data).__name__} has no property {name!r}"
        self.record.append(("prop", name))

    def operator(self, idname, icon="NONE"):
        assert icon in ICONS, f"no icon {icon!r}"
        category, name = idname.split(".")
        assert hasattr(getattr(bpy.ops, category), name), f"no operator {idname}"
        getattr(getattr(bpy.ops, category), name).get_rna_type()
        self.record.append(("operator", idname))


def draw(panel_class) -> list:
    layout = CheckingLayout()
    panel_class.draw(type("Panel", (), {"layout": layout})(), bpy.context)
    return layout.record


@pytest.fixture
def checked_scene(registered_addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    area_light("Light", size=0.5, power=50.0, location=(0.0, 0.0, 2.0))
    obj = box("Box", (-0.2, -0.2, 0.0), (0.2, 0.2, 0.4), diffuse_material("grey", (0.5, 0.5, 0.5)))
    bpy.context.view_layer.objects.active = obj
    store.clear()
    return obj


def test_settings_panel_shows_every_setting(checked_scene):
    shown = {name for kind, name in draw(ui.VISRAD_PT_main) if kind == "prop"}
    assert shown == {"preset", "jnd", "max_iterations", "form_factors", "rays", "discontinuities", "max_bounces"}


def test_scene_panel_before_and_after_check_scene(checked_scene):
    before = draw(ui.VISRAD_PT_scene)
    assert ("label", "Not checked yet") in before
    assert ("operator", "visrad.check_scene") in before and ("prop", "visrad_exclude") in before

    for index in range(12):
        bpy.data.objects.new(f"Lamp {index}", bpy.data.lights.new(f"Lamp {index}", "POINT"))
        bpy.context.scene.collection.objects.link(bpy.data.objects[f"Lamp {index}"])
    bpy.ops.visrad.check_scene()
    after = draw(ui.VISRAD_PT_scene)
    labels = [text for kind, text in after if kind == "label"]
    assert store.get(bpy.context.scene).summary in labels
    warnings = [text for text in labels if "point light" in text]
    assert len(warnings) == ui.MAX_WARNINGS_SHOWN
    assert "... and 4 more (see the Info editor)" in labels


def test_results_panel_counts_and_clears(checked_scene):
    record = draw(ui.VISRAD_PT_results)
    assert ("label", "0 result meshes, 0 curve objects") in record
    assert ("operator", "visrad.clear_results") in record


def test_solve_panel_has_every_stage_and_shows_the_statistics(checked_scene):
    record = draw(ui.VISRAD_PT_solve)
    operators = [name for kind, name in record if kind == "operator"]
    assert operators == [
        "visrad.build_skeleton",
        "visrad.coarse_lighting",
        "visrad.refine",
        "visrad.write_results",
        "visrad.bake",
    ]
    assert ("label", "No solution yet") in record

    bpy.context.scene.visrad.max_iterations = 1
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    labels = [text for kind, text in draw(ui.VISRAD_PT_solve) if kind == "label"]
    stats = store.get(bpy.context.scene).state[stages.STATS]
    state = "converged" if stats["converged"] else "not converged"
    assert labels[0] == f"Refinement: {stats['iterations']} of 1 iterations, {state}"
    assert f"Links: {stats['links']:,}" in labels
    skeleton = stats["skeleton"]
    nodes, arcs = sum(skeleton["nodes"].values()), sum(skeleton["arcs"].values())
    assert nodes > 0 and arcs > 0
    assert f"Skeleton: {nodes:,} nodes, {arcs:,} arcs" in labels
    assert f"Vertices: {stats['vertices']:,}, triangles: {stats['leaf_triangles']:,}" in labels
    assert any(text.startswith("Time: visibility ") and "coarse" in text and "refine" in text for text in labels)
    assert any(text.startswith("Peak memory: ") and text.endswith(" MiB") for text in labels)
    results = [text for kind, text in draw(ui.VISRAD_PT_results) if kind == "label"]
    assert "1 result meshes, 0 curve objects" in results
    assert any(text.startswith("Last written: ") for text in results)


def test_solve_panel_before_lighting_and_while_a_stage_runs(checked_scene, monkeypatch):
    bpy.ops.visrad.build_skeleton()
    labels = [text for kind, text in draw(ui.VISRAD_PT_solve) if kind == "label"]
    assert labels[0] == "Visibility built, no lighting yet"
    monkeypatch.setitem(stages._running, bpy.context.scene.session_uid, "Bake")
    labels = [text for kind, text in draw(ui.VISRAD_PT_solve) if kind == "label"]
    assert "Bake is running (Esc cancels it)" in labels
    assert not bpy.ops.visrad.refine.poll()
