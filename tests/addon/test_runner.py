"""visrad_addon.runner: stages as generators of progress fractions, blocking and modal."""

import time
from types import SimpleNamespace

import pytest

bpy = pytest.importorskip("bpy")

from visrad.visrad_addon import runner  # noqa: E402
from visrad.visrad_addon.runner import ModalStageOperator, StageError, StageRunner  # noqa: E402


class Journal:
    """A dummy stage of `steps` steps that records what happened to it."""

    def __init__(self, steps: int = 5, fail_at: int | None = None, pause: float = 0.0):
        self.steps, self.fail_at, self.pause = steps, fail_at, pause
        self.done: list[int] = []
        self.closed = False
        self.finished = False

    def stage(self):
        try:
            for step in range(self.steps):
                if step == self.fail_at:
                    raise ValueError(f"step {step} is broken")
                time.sleep(self.pause)
                self.done.append(step)
                yield (step + 1) / self.steps
            self.finished = True
        except GeneratorExit:
            self.closed = True
            raise


def test_blocking_run_reports_every_fraction_and_finishes():
    journal = Journal(4)
    seen = []
    stage_runner = StageRunner(journal.stage(), "dummy")
    stage_runner.run(seen.append)
    assert journal.done == [0, 1, 2, 3] and journal.finished and not journal.closed
    assert seen == [0.25, 0.5, 0.75, 1.0, 1.0]
    assert stage_runner.finished and stage_runner.fraction == 1.0


def test_cancel_closes_the_generator_where_it_is_paused():
    journal = Journal(10)
    stage_runner = StageRunner(journal.stage())
    assert stage_runner.step(0.0) is False
    stage_runner.cancel()
    assert journal.closed and journal.done == [0] and not journal.finished
    assert stage_runner.cancelled and stage_runner.step(1.0) is False


def test_a_failing_stage_propagates_its_error():
    journal = Journal(5, fail_at=2)
    with pytest.raises(ValueError, match="step 2 is broken"):
        StageRunner(journal.stage()).run()
    assert journal.done == [0, 1]


def test_an_interrupt_during_a_blocking_run_closes_the_stage():
    journal = Journal(10)

    def interrupt(fraction):
        if fraction >= 0.3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        StageRunner(journal.stage()).run(interrupt)
    assert journal.closed and journal.done == [0, 1, 2]


def test_a_fraction_outside_0_1_names_the_stage_and_closes_it():
    closed = []

    def overshooting():
        try:
            yield 0.5
            yield 1.5
        finally:
            closed.append(True)

    with pytest.raises(ValueError, match=r"overshoot yielded the progress fraction 1\.5"):
        StageRunner(overshooting(), "overshoot").run()
    assert closed == [True]


def test_a_step_lasts_about_its_time_slice():
    journal = Journal(100, pause=0.01)
    stage_runner = StageRunner(journal.stage())
    assert stage_runner.step(0.05) is False
    assert 3 <= len(journal.done) <= 10
    assert stage_runner.fraction == len(journal.done) / 100


# ---------------------------------------------------------------------------------------------------------
# The operator mix-in


class VISRAD_OT_test_stage(ModalStageOperator, bpy.types.Operator):
    """A stage operator for the tests: runs the Journal held by the class."""

    bl_idname = "visrad.test_stage"
    bl_label = "Test Stage"

    journal: Journal = None
    refuse = False
    cancelled_calls = 0

    def stage_start(self, context):
        if VISRAD_OT_test_stage.refuse:
            raise StageError("the test stage refuses to start: nothing to do")
        return VISRAD_OT_test_stage.journal.stage()

    def stage_finish(self, context):
        context.scene["visrad_test_finished"] = len(VISRAD_OT_test_stage.journal.done)
        return f"did {len(VISRAD_OT_test_stage.journal.done)} steps"

    def stage_cancelled(self, context):
        VISRAD_OT_test_stage.cancelled_calls += 1


@pytest.fixture
def test_stage():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.utils.register_class(VISRAD_OT_test_stage)
    VISRAD_OT_test_stage.journal, VISRAD_OT_test_stage.refuse, VISRAD_OT_test_stage.cancelled_calls = (
        Journal(6),
        False,
        0,
    )
    yield VISRAD_OT_test_stage
    bpy.utils.unregister_class(VISRAD_OT_test_stage)


@pytest.mark.parametrize("mode", ["EXEC_DEFAULT", "INVOKE_DEFAULT"])
def test_in_background_the_operator_runs_the_stage_blocking(test_stage, mode):
    assert bpy.app.background
    assert bpy.ops.visrad.test_stage(mode) == {"FINISHED"}
    assert test_stage.journal.finished and bpy.context.scene["visrad_test_finished"] == 6
    assert test_stage.cancelled_calls == 0


def test_a_failing_stage_is_reported_by_the_operator_and_commits_nothing(test_stage):
    test_stage.journal = Journal(6, fail_at=3)
    with pytest.raises(RuntimeError, match="Test Stage failed: ValueError: step 3 is broken"):
        bpy.ops.visrad.test_stage()
    assert "visrad_test_finished" not in bpy.context.scene
    assert test_stage.cancelled_calls == 1


def test_a_stage_that_cannot_start_gives_its_message(test_stage):
    test_stage.refuse = True
    with pytest.raises(RuntimeError, match="refuses to start: nothing to do"):
        bpy.ops.visrad.test_stage()
    assert test_stage.journal.done == []


class FakeWindowManager:
    """Records the progress and timer calls the modal path makes."""

    def __init__(self):
        self.calls = []
        self.timer = object()

    def event_timer_add(self, interval, window=None):
        self.calls.append("timer_add")
        return self.timer

    def event_timer_remove(self, timer):
        assert timer is self.timer
        self.calls.append("timer_remove")

    def modal_handler_add(self, operator):
        self.calls.append("modal_handler_add")

    def progress_begin(self, low, high):
        self.calls.append(("progress_begin", low, high))

    def progress_update(self, value):
        self.calls.append(("progress_update", value))

    def progress_end(self):
        self.calls.append("progress_end")


class ModalProbe(ModalStageOperator):
    """The mix-in without Blender's operator machinery, so that its modal path can run in background mode."""

    bl_label = "Probe"
    slice_seconds = 0.0

    def __init__(self, journal):
        self.journal = journal
        self.reports = []
        self.finished_calls = 0
        self.cancelled_calls = 0

    def report(self, kind, message):
        self.reports.append((set(kind), message))

    def stage_start(self, context):
        return self.journal.stage()

    def stage_finish(self, context):
        self.finished_calls += 1

    def stage_cancelled(self, context):
        self.cancelled_calls += 1


@pytest.fixture
def ui_context(monkeypatch):
    """A context with a window manager and a status bar, and bpy.app.background seen as False by the runner."""
    monkeypatch.setattr(runner, "bpy", SimpleNamespace(app=SimpleNamespace(background=False)))
    status = []
    workspace = SimpleNamespace(status_text_set=status.append)
    return SimpleNamespace(window_manager=FakeWindowManager(), window=object(), workspace=workspace, status=status)


def timer_event(context):
    return SimpleNamespace(type="TIMER", value="NOTHING", timer=context.window_manager.timer)


def test_modal_run_steps_on_timer_events_with_progress_and_status(ui_context):
    journal = Journal(3)
    probe = ModalProbe(journal)
    assert probe.invoke(ui_context, None) == {"RUNNING_MODAL"}
    assert journal.done == []
    mouse = SimpleNamespace(type="MOUSEMOVE", value="NOTHING", timer=None)
    assert probe.modal(ui_context, mouse) == {"PASS_THROUGH"}
    results = [probe.modal(ui_context, timer_event(ui_context)) for _ in range(4)]
    assert results == [{"RUNNING_MODAL"}] * 3 + [{"FINISHED"}]
    assert journal.finished and probe.finished_calls == 1 and probe.cancelled_calls == 0
    calls = ui_context.window_manager.calls
    assert calls[:3] == ["timer_add", ("progress_begin", 0.0, 1.0), "modal_handler_add"]
    updates = [value for call, *value in (c for c in calls if isinstance(c, tuple)) if call == "progress_update"]
    assert updates == [[1 / 3], [2 / 3], [1.0]]
    assert calls[-2:] == ["timer_remove", "progress_end"]
    assert ui_context.status[0] == "Probe: 0%  (Esc to cancel)" and ui_context.status[-1] is None
    assert "Probe: 66%  (Esc to cancel)" in ui_context.status


def test_esc_cancels_the_modal_run_and_closes_the_stage(ui_context):
    journal = Journal(10)
    probe = ModalProbe(journal)
    probe.invoke(ui_context, None)
    assert probe.modal(ui_context, timer_event(ui_context)) == {"RUNNING_MODAL"}
    escape = SimpleNamespace(type="ESC", value="PRESS", timer=None)
    assert probe.modal(ui_context, escape) == {"CANCELLED"}
    assert journal.closed and journal.done == [0] and not journal.finished
    assert probe.finished_calls == 0 and probe.cancelled_calls == 1
    assert ui_context.window_manager.calls[-2:] == ["timer_remove", "progress_end"]
    assert ui_context.status[-1] is None
    assert ({"WARNING"}, "Probe cancelled") in probe.reports
