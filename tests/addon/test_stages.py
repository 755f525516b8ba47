"""The stage operators (visrad_addon/stages.py) on the Cornell box sample: each stage alone and in order, Bake,
Write Results, the statistics they leave in the session, and cancelling or failing in the middle of a stage
(the session and the scene stay as they were).

Background mode runs the operators blocking; the modal path (timer steps, Esc) runs the same stage mix-ins
with a stand-in window manager, as tests/addon/test_runner.py does for the runner itself.
"""

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.errors import VisradError  # noqa: E402
from visrad.visrad_addon import runner, stages  # noqa: E402
from visrad.visrad_addon.session import store  # noqa: E402
from visrad.visrad_addon.write_back import RADIANCE_ATTRIBUTE, ROLE_PROPERTY, result_objects  # noqa: E402

from tests.addon.blender_scenes import user_data_fingerprint  # noqa: E402
from tests.addon.test_runner import FakeWindowManager  # noqa: E402

CORNELL = Path(__file__).resolve().parents[2] / "sample_blends" / "cornell_box.blend"
CORNELL_MESHES = {"floor", "ceiling", "back_wall", "right_wall", "left_wall", "short_block", "tall_block"}


@pytest.fixture
def cornell(registered_addon):
    """The Cornell box sample opened (no session yet), Max Iterations 2."""
    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    store.clear()
    bpy.context.scene.visrad.max_iterations = 2
    return bpy.context.scene


def session_solver():
    session = store.get(bpy.context.scene)
    return session, session.state.get(stages.SOLVER) if session is not None else None


def radiance(obj) -> np.ndarray:
    attribute = obj.data.color_attributes[RADIANCE_ATTRIBUTE]
    values = np.empty(4 * len(attribute.data), np.float32)
    attribute.data.foreach_get("color", values)
    return values.reshape(-1, 4)[:, :3]


def test_each_stage_in_order_then_write(cornell):
    user_data = user_data_fingerprint(ROLE_PROPERTY)
    assert not bpy.ops.visrad.write_results.poll(), "nothing to write before a stage ran"

    assert bpy.ops.visrad.build_skeleton() == {"FINISHED"}
    session, solver = session_solver()
    assert solver.facing is not None and solver.lighting is None
    assert session.state[stages.STATS]["skeleton_built"] and not session.state[stages.STATS]["lit"]
    assert not bpy.ops.visrad.write_results.poll()

    assert bpy.ops.visrad.coarse_lighting() == {"FINISHED"}
    _, coarse = session_solver()
    assert coarse.lighting is not None and coarse.iterations == 0 and coarse.facing is solver.facing
    assert bpy.ops.visrad.write_results.poll()

    assert bpy.ops.visrad.refine() == {"FINISHED"}
    session, refined = session_solver()
    stats = session.state[stages.STATS]
    assert refined.iterations == 1 and coarse.iterations == 0, "the stage ran on a copy"
    assert stats["iterations"] == 1 and stats["links"] > 0 and stats["leaf_triangles"] > 32
    assert set(stats["seconds"]) == {"build_skeleton", "coarse_lighting", "refine"}
    assert all(seconds > 0.0 for seconds in stats["seconds"].values()) and stats["peak_bytes"] > 0
    assert result_objects(cornell) == [], "stages other than Bake and Write Results write nothing"

    assert bpy.ops.visrad.write_results() == {"FINISHED"}
    written = {obj.name for obj in result_objects(cornell)}
    assert written == {f"{name}.visrad" for name in CORNELL_MESHES}
    assert session.state[stages.WRITTEN]["triangles"] == sum(
        len(bpy.data.objects[name].data.polygons) for name in written
    )
    for name in written:
        values = radiance(bpy.data.objects[name])
        assert np.isfinite(values).all() and values.max() > 0.0
    assert user_data_fingerprint(ROLE_PROPERTY) == user_data, "the user's data is only read"


def test_bake_runs_every_stage_and_writes(cornell):
    user_data = user_data_fingerprint(ROLE_PROPERTY)
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    session, solver = session_solver()
    assert solver.iterations == 2 or solver.converged
    assert {obj.name for obj in result_objects(cornell)} == {f"{name}.visrad" for name in CORNELL_MESHES}
    assert session.state[stages.STATS]["iterations"] == solver.iterations
    assert user_data_fingerprint(ROLE_PROPERTY) == user_data

    # raising the limit continues the same solution; the same limit again only rewrites the results
    cornell.visrad.max_iterations = 3
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    again, continued = session_solver()
    assert again is session and continued.iterations == 3 and continued.refinement_log[:2] == solver.refinement_log
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    assert session_solver()[1] is continued


def test_build_skeleton_and_coarse_lighting_start_over(cornell):
    bpy.ops.visrad.refine()
    _, refined = session_solver()
    assert refined.iterations == 1
    bpy.ops.visrad.coarse_lighting()
    _, coarse = session_solver()
    assert coarse is not refined and coarse.iterations == 0 and coarse.lighting is not None
    bpy.ops.visrad.build_skeleton()
    _, skeleton = session_solver()
    assert skeleton.lighting is None and skeleton.facing is not None


def test_a_scene_change_drops_the_solution(cornell):
    bpy.ops.visrad.coarse_lighting()
    _, before = session_solver()
    bpy.data.objects["short_block"].location.z += 0.01
    bpy.context.view_layer.update()
    assert store.get(cornell).dirty
    bpy.ops.visrad.refine()
    session, after = session_solver()
    assert after.scene is not before.scene and after.iterations == 1 and not session.dirty


def test_write_results_refuses_a_stale_solution(cornell):
    bpy.ops.visrad.coarse_lighting()
    cornell.visrad.preset = "CUSTOM"
    cornell.visrad.jnd = 0.05
    with pytest.raises(RuntimeError, match="changed since the solution"):
        bpy.ops.visrad.write_results()
    assert result_objects(cornell) == []


def test_a_scene_without_light_is_reported_by_every_stage(cornell):
    bpy.data.objects.remove(bpy.data.objects["light"])
    for operator in (bpy.ops.visrad.build_skeleton, bpy.ops.visrad.coarse_lighting, bpy.ops.visrad.refine):
        with pytest.raises(RuntimeError, match="has no light"):
            operator()
    with pytest.raises(RuntimeError, match="has no light"):
        bpy.ops.visrad.bake()
    assert store.get(cornell) is None and result_objects(cornell) == []


# ---------------------------------------------------------------------------------------------------------
# Cancelling and failing in the middle of a stage


def probe(stage_class):
    """The stage mix-in as an object the test can drive through invoke / modal (one step per timer event)."""

    class Probe(stage_class):
        slice_seconds = 0.0

        def __init__(self):
            self.reports = []

        def report(self, kind, message):
            self.reports.append((set(kind), message))

    return Probe()


@pytest.fixture
def ui_context(monkeypatch):
    """The real scene and depsgraph with a stand-in window manager; the runner sees a UI session."""
    monkeypatch.setattr(runner, "bpy", SimpleNamespace(app=SimpleNamespace(background=False)))
    return SimpleNamespace(
        scene=bpy.context.scene,
        evaluated_depsgraph_get=bpy.context.evaluated_depsgraph_get,
        window_manager=FakeWindowManager(),
        window=object(),
        workspace=SimpleNamespace(status_text_set=lambda text: None),
    )


def timer(context):
    return SimpleNamespace(type="TIMER", value="NOTHING", timer=context.window_manager.timer)


ESCAPE = SimpleNamespace(type="ESC", value="PRESS", timer=None)


def snapshot(blender_scene) -> dict:
    session = store.get(blender_scene)
    objects = {obj.name: radiance(obj).copy() for obj in result_objects(blender_scene) if obj.type == "MESH"}
    state = dict(session.state) if session is not None else None
    solver = state.get(stages.SOLVER) if state else None
    return {
        "session": session,
        "state": state,
        "solver": None if solver is None else dict(vars(solver)),
        "results": objects,
        "user data": user_data_fingerprint(ROLE_PROPERTY),
    }


def assert_unchanged(before: dict, blender_scene) -> None:
    after = snapshot(blender_scene)
    assert after["session"] is before["session"]
    assert after["state"] == before["state"], "the session keeps the same solver, statistics and write record"
    if before["solver"] is not None:
        solver = vars(after["state"][stages.SOLVER])
        assert solver.keys() == before["solver"].keys()
        for name, value in before["solver"].items():
            assert solver[name] is value or solver[name] == value, f"solver.{name} changed"
    assert after["results"].keys() == before["results"].keys()
    for name, values in before["results"].items():
        np.testing.assert_array_equal(after["results"][name], values)
    assert after["user data"] == before["user data"]
    assert stages.running_stage(blender_scene) is None


@pytest.mark.parametrize(
    ("stage_class", "steps"),
    [(stages.RefineStage, 2), (stages.CoarseLightingStage, 3), (stages.BakeStage, 3), (stages.BuildSkeletonStage, 1)],
    ids=["refine", "coarse lighting", "bake", "build skeleton"],
)
def test_esc_in_the_middle_of_a_stage_leaves_session_and_scene_as_before(cornell, ui_context, stage_class, steps):
    bpy.ops.visrad.bake()  # a solution and results to keep
    cornell.visrad.max_iterations = 4
    before = snapshot(cornell)
    operator = probe(stage_class)
    assert operator.invoke(ui_context, None) == {"RUNNING_MODAL"}
    assert stages.running_stage(cornell) == stage_class.bl_label
    for _ in range(steps):
        assert operator.modal(ui_context, timer(ui_context)) == {"RUNNING_MODAL"}
    assert 0.0 < operator._runner.fraction < 1.0, "cancelled in the middle"
    assert operator.modal(ui_context, ESCAPE) == {"CANCELLED"}
    assert ({"WARNING"}, f"{stage_class.bl_label} cancelled") in operator.reports
    assert_unchanged(before, cornell)


def test_esc_on_a_fresh_scene_keeps_no_solver(cornell, ui_context):
    operator = probe(stages.CoarseLightingStage)
    operator.invoke(ui_context, None)
    weights = stages._WEIGHTS
    visibility = weights["build_skeleton"] / (weights["build_skeleton"] + weights["coarse_lighting"])
    for _ in range(10_000):  # until the visibility is done and the lighting has started
        operator.modal(ui_context, timer(ui_context))
        if operator._runner.fraction > visibility:
            break
    assert visibility < operator._runner.fraction < 1.0
    operator.modal(ui_context, ESCAPE)
    session = store.get(cornell)
    assert stages.SOLVER not in session.state and result_objects(cornell) == []
    assert stages.running_stage(cornell) is None


def test_a_modal_bake_commits_finished_stages_and_writes_at_the_end(cornell, ui_context):
    operator = probe(stages.BakeStage)
    operator.invoke(ui_context, None)
    weights = stages._WEIGHTS
    coarse_done = (weights["build_skeleton"] + weights["coarse_lighting"]) / (
        weights["build_skeleton"] + weights["coarse_lighting"] + 2 * weights["refine"]
    )
    results, checked = [], 0
    while not results or results[-1] == {"RUNNING_MODAL"}:
        results.append(operator.modal(ui_context, timer(ui_context)))
        if results[-1] == {"RUNNING_MODAL"} and operator._runner.fraction > coarse_done:
            checked += 1
            assert store.get(cornell).state[stages.SOLVER].lighting is not None, "coarse lighting committed"
            assert result_objects(cornell) == [], "nothing written before the bake ends"
    assert results[-1] == {"FINISHED"} and checked >= 2
    assert {obj.name for obj in result_objects(cornell)} == {f"{name}.visrad" for name in CORNELL_MESHES}
    assert any(kind == {"INFO"} and message.startswith("Bake: ") for kind, message in operator.reports)


def test_a_stage_that_fails_midway_is_reported_and_changes_nothing(cornell, monkeypatch):
    bpy.ops.visrad.bake()
    before = snapshot(cornell)

    def broken(self):
        yield 0.1
        raise VisradError("the test broke refinement")

    solver_class = type(before["state"][stages.SOLVER])
    monkeypatch.setattr(solver_class, "refine_steps", broken)
    cornell.visrad.max_iterations = 3
    with pytest.raises(RuntimeError, match="Refine failed: VisradError: the test broke refinement"):
        bpy.ops.visrad.refine()
    assert_unchanged(before, cornell)
    with pytest.raises(RuntimeError, match="Bake failed"):
        bpy.ops.visrad.bake()
    assert_unchanged(before, cornell)
    monkeypatch.undo()
    assert bpy.ops.visrad.refine() == {"FINISHED"}, "a failure leaves no stage marked as running"
