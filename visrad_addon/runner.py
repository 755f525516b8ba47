"""Long stages as generators of progress fractions, run blocking in background mode or modally in the UI.

A stage is any iterator of floats in [0, 1] (typically a generator): each `next()` does a bounded piece of
work and yields how far the stage is. The same stage object runs

* blocking, `StageRunner(stage).run()`, when Blender runs in background mode (`blender -b`, the bpy module,
  batch.py): there is no event loop to return to;
* in slices on a modal operator's timer in the UI (`ModalStageOperator`): each timer event advances the stage
  for about `slice_seconds`, the progress bar and the status bar follow, and Esc cancels.

Cancelling closes the generator (`close()` raises GeneratorExit at the `yield` it is paused at), so a stage
written with try/finally, or one that only commits its state between yields, leaves everything consistent.
This is how Blender's own extension manager (bl_pkg) runs its long commands.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable, Iterable, Iterator

import bpy


class StageError(RuntimeError):
    """A stage could not start or failed with a message meant for the user (no traceback is shown)."""


class StageRunner:
    """Drives one stage: `step()` for a time slice, `run()` to the end, `cancel()` to stop and close it.

    fraction: the last fraction the stage yielded (0 before the first); finished / cancelled: its state.
    """

    def __init__(self, stage: Iterable[float], name: str = "stage"):
        self.name = name
        self._stage: Iterator[float] = iter(stage)
        self.fraction = 0.0
        self.finished = False
        self.cancelled = False

    def step(self, seconds: float) -> bool:
        """Advance the stage for about `seconds` (at least one step); True once it has finished."""
        if self.finished or self.cancelled:
            return self.finished
        deadline = time.perf_counter() + seconds
        while True:
            try:
                fraction = next(self._stage)
            except StopIteration:
                self.finished = True
                self.fraction = 1.0
                return True
            except BaseException:
                self.cancelled = True
                raise
            self.fraction = self._checked(fraction)
            if time.perf_counter() >= deadline:
                return False

    def run(self, progress: Callable[[float], None] | None = None) -> None:
        """Run the stage to its end, calling `progress(fraction)` after each step. An exception (a failing
        stage, a KeyboardInterrupt, an exception from `progress`) closes the stage and propagates."""
        try:
            while not self.step(0.0):
                if progress is not None:
                    progress(self.fraction)
        except BaseException:
            self.cancel()
            raise
        if progress is not None:
            progress(1.0)

    def cancel(self) -> None:
        """Stop the stage: close it so that it can leave a consistent state. Harmless once it has ended."""
        if self.finished:
            return
        self.cancelled = True
        close = getattr(self._stage, "close", None)
        if close is not None:
            close()

    def _checked(self, fraction) -> float:
        value = float(fraction)
        if not 0.0 <= value <= 1.0:
            self.cancel()
            raise ValueError(f"{self.name} yielded the progress fraction {fraction!r}, outside [0, 1]")
        return value


class ModalStageOperator:
    """Mix-in for a bpy.types.Operator that runs one stage (subclass it together with bpy.types.Operator).

    Subclasses define `stage_start(context)`, which reads the operator's properties and returns the stage
    (an iterator of fractions; raise StageError with a readable message if it cannot start), and
    `stage_finish(context)`, which commits the finished stage's outcome (e.g. writes the results) and may
    return a message to report. `stage_cancelled(context)` runs after a cancel or a failure.

    invoke() runs the stage modally in the UI and blocking in background mode; execute() (scripts, bpy.ops
    from Python without 'INVOKE_DEFAULT') always runs it blocking. One undo step is pushed when the operator
    finishes: keep 'UNDO' in bl_options and change Blender data only in stage_finish.
    """

    bl_options = {"REGISTER", "UNDO"}
    timer_interval = 0.05
    slice_seconds = 0.05

    def stage_start(self, context) -> Iterable[float]:
        raise NotImplementedError(f"{type(self).__name__} must define stage_start()")

    def stage_finish(self, context) -> str | None:
        raise NotImplementedError(f"{type(self).__name__} must define stage_finish()")

    def stage_cancelled(self, context) -> None:
        """Called after the stage was cancelled or failed; nothing to undo by default."""

    # -- operator API ---------------------------------------------------------------------------------------

    def execute(self, context):
        runner = self._start(context)
        if runner is None:
            return {"CANCELLED"}
        printer = _ProgressPrinter(self.bl_label) if bpy.app.background else None
        try:
            runner.run(printer)
        except Exception as error:
            return self._failed(context, error)
        return self._finish(context)

    def invoke(self, context, event):
        if bpy.app.background:
            return self.execute(context)
        self._runner = self._start(context)
        if self._runner is None:
            return {"CANCELLED"}
        window_manager = context.window_manager
        self._timer = window_manager.event_timer_add(self.timer_interval, window=context.window)
        window_manager.progress_begin(0.0, 1.0)
        window_manager.modal_handler_add(self)
        self._show_status(context)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._runner.cancel()
            self._end_modal(context)
            self.stage_cancelled(context)
            self.report({"WARNING"}, f"{self.bl_label} cancelled")
            return {"CANCELLED"}
        if event.type != "TIMER" or event.timer is not self._timer:
            return {"PASS_THROUGH"}
        try:
            finished = self._runner.step(self.slice_seconds)
        except Exception as error:
            self._end_modal(context)
            return self._failed(context, error)
        if not finished:
            context.window_manager.progress_update(self._runner.fraction)
            self._show_status(context)
            return {"RUNNING_MODAL"}
        self._end_modal(context)
        return self._finish(context)

    def cancel(self, context):
        """Blender cancels a running modal operator (e.g. a file is loaded or the window closes)."""
        self._runner.cancel()
        self._end_modal(context)
        self.stage_cancelled(context)

    # -- internals ------------------------------------------------------------------------------------------

    def _start(self, context) -> StageRunner | None:
        try:
            return StageRunner(self.stage_start(context), self.bl_label)
        except StageError as error:
            self.report({"ERROR"}, str(error))
            return None

    def _finish(self, context):
        try:
            message = self.stage_finish(context)
        except StageError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if message:
            self.report({"INFO"}, message)
        return {"FINISHED"}

    def _failed(self, context, error: Exception):
        self.stage_cancelled(context)
        detail = str(error) if isinstance(error, StageError) else f"{type(error).__name__}: {error}"
        self.report({"ERROR"}, f"{self.bl_label} failed: {detail}")
        return {"CANCELLED"}

    def _show_status(self, context) -> None:
        percent = math.floor(100.0 * self._runner.fraction)
        context.workspace.status_text_set(f"{self.bl_label}: {percent}%  (Esc to cancel)")

    def _end_modal(self, context) -> None:
        window_manager = context.window_manager
        window_manager.event_timer_remove(self._timer)
        window_manager.progress_end()
        context.workspace.status_text_set(None)


class _ProgressPrinter:
    """Prints a stage's progress to stderr every 10 % in background mode, where there is no progress bar."""

    def __init__(self, label: str):
        self.label = label
        self.printed = -1

    def __call__(self, fraction: float) -> None:
        tenth = math.floor(10.0 * fraction)
        if tenth > self.printed:
            self.printed = tenth
            print(f"{self.label}: {10 * tenth}%", file=sys.stderr, flush=True)
