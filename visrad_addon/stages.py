"""The stage operators: Build Skeleton, Coarse Lighting, Refine, Bake and Write Results.

They are thin. Each reads the scene's settings (`properties.solver_settings`), opens the scene's session
(session.py converts the scene and keeps the solver while the scene and the settings that shape the solution
are unchanged), builds one `core.pipeline.Settings`, drives the solver's stage generators through
`runner.ModalStageOperator` (modal with a progress bar and Esc in the UI, blocking in background mode and in
batch.py) and changes Blender data only once it has finished: Bake and Write Results write the result meshes
(write_back.py), the other stages only change the session. Each operator is one undo step.

What each stage does with the session's solver:

* Build Skeleton starts over: a new solver, global visibility built (the lighting is dropped).
* Coarse Lighting starts the lighting over from the coarse mesh (refinements are dropped), building the
  visibility first when it is missing.
* Refine runs one refinement iteration (and the stages before it when they are missing); nothing to do once
  the solution has converged.
* Bake continues from where the session is: the missing stages, then refinement iterations until the solution
  converges or the scene's Max Iterations is reached, then writes the results.
* Write Results writes the session's current solution.

Transactions. An operator runs its stages on a working copy of the session's solver (a shallow copy with its
own lists and dicts: core's stages build new state and assign it when they complete, they never change the
old state in place), and the copy becomes the session's solver when the operator completes. So Esc, an error,
or Blender cancelling the operator leaves the session as it was before, and the scene untouched. Bake, which
may run for long, commits after each stage it completes: cancelling it keeps the visibility, the coarse
lighting and the refinement iterations finished so far (Write Results writes them) and writes nothing.

Statistics. After each completed stage the session's `state["stats"]` holds the solver's statistics (seconds
per stage spent in the stage's own steps, links, vertices, leaf triangles, iterations, convergence, the
process's peak memory); `state["written"]` describes the last write. The panel and batch.py read them.
"""

from __future__ import annotations

import copy
import time

import bpy

from ..core.errors import SceneError, VisradError
from .properties import solver_settings
from .runner import ModalStageOperator, StageError
from .session import store
from .write_back import write_results

SOLVER = "solver"
STATS = "stats"
WRITTEN = "written"
# core Settings fields the add-on's settings dict carries
_SETTINGS_FIELDS = ("jnd", "max_iterations", "max_bounces", "form_factors", "discontinuities", "source_refinement")
# relative cost of the stages, for one progress bar over several of them (measured on the sample scenes:
# visibility is cheap, a refinement iteration costs several coarse lightings)
_WEIGHTS = {"build_skeleton": 1.0, "coarse_lighting": 3.0, "refine": 10.0}
# Blender scenes (session_uid) with a stage operator running, and which
_running: dict[int, str] = {}


def core_settings(settings: dict):
    """The core.pipeline.Settings of the add-on's settings dict (properties.solver_settings)."""
    from ..core.pipeline import Settings

    return Settings(**{name: settings[name] for name in _SETTINGS_FIELDS})


def solver_stats(solver) -> dict:
    """The solver's statistics (core's `Solver.stats()`) plus which stages are done."""
    stats = solver.stats()
    stats["skeleton_built"] = solver.facing is not None
    stats["lit"] = solver.lighting is not None
    return stats


def has_solution(session) -> bool:
    """Whether the session holds a solver with lighting (something Write Results can write)."""
    solver = session.state.get(SOLVER) if session is not None else None
    return solver is not None and solver.lighting is not None


def running_stage(blender_scene) -> str | None:
    """The label of the stage operator running on `blender_scene`, if any."""
    return _running.get(blender_scene.session_uid)


def _working_copy(solver):
    """A copy of `solver` that a stage can run on without touching the original (see Transactions)."""
    twin = copy.copy(solver)
    for name, value in vars(twin).items():
        if isinstance(value, list | dict | set):
            setattr(twin, name, copy.copy(value))
    return twin


def _write(context, session) -> str:
    """Write the session's solution into the scene; returns what was written, as a sentence."""
    started = time.perf_counter()
    result = session.state[SOLVER].result()
    try:
        summary = write_results(context.scene, result, session.scene, session.source_map)
    except ValueError as error:
        raise StageError(f"the result could not be written: {error}") from None
    seconds = time.perf_counter() - started
    session.state[WRITTEN] = {
        "objects": summary.objects,
        "curves": summary.curves,
        "triangles": summary.triangles,
        "segments": summary.segments,
        "replaced": summary.replaced,
        "seconds": seconds,
    }
    return (
        f"wrote {len(summary.objects)} result meshes ({summary.triangles:,} triangles) and "
        f"{len(summary.curves)} discontinuity curve objects in {seconds:.2f} s"
    )


class SolverStage(ModalStageOperator):
    """What a stage operator does, without Blender's operator type (the operators below add it; tests drive
    these mix-ins directly). `plan(solver, settings)` lists the solver stages to run, in order (names of
    _WEIGHTS); a "refine" entry is skipped once the solver has converged. `fresh(solver)` says whether to
    start from a new solver. `writes`: write the results when the stages are done. `commit_each_stage`:
    commit every completed stage to the session (Bake), else only the whole plan."""

    bl_options = {"REGISTER", "UNDO"}
    writes = False
    commit_each_stage = False

    @classmethod
    def poll(cls, context):
        label = running_stage(context.scene)
        if label is not None:
            cls.poll_message_set(f"{label} is running (Esc cancels it)")
            return False
        return True

    def fresh(self, solver) -> bool:
        return False

    def plan(self, solver, settings: dict) -> list[str]:
        raise NotImplementedError

    def stage_start(self, context):
        blender_scene = context.scene
        if running_stage(blender_scene) is not None:
            raise StageError(f"{running_stage(blender_scene)} is running: wait for it or press Esc")
        settings = solver_settings(blender_scene.visrad)
        try:
            session = store.open(context, settings)
        except SceneError as error:
            raise StageError(str(error)) from None
        solver = session.state.get(SOLVER)
        if solver is None or self.fresh(solver):
            from ..core.pipeline import Solver

            try:
                solver = Solver(session.scene, core_settings(settings))
            except VisradError as error:
                raise StageError(str(error)) from None
        self._session = session
        self._uid = blender_scene.session_uid
        self._started = time.perf_counter()
        _running[self._uid] = self.bl_label
        return self._drive(session, solver, self.plan(solver, settings))

    def _drive(self, session, solver, plan: list[str]):
        """Run the planned stages on working copies, committing each completed one; yields the fraction."""
        total = sum(_WEIGHTS[name] for name in plan) or 1.0
        before = 0.0
        for name in plan:
            weight = _WEIGHTS[name] / total
            if name == "refine" and (solver.converged or solver.stopped is not None):
                before += weight
                continue
            working = _working_copy(solver)
            steps = getattr(working, f"{name}_steps")()
            elapsed = 0.0
            try:
                while True:
                    resumed = time.perf_counter()
                    try:
                        fraction = next(steps)
                    except StopIteration:
                        elapsed += time.perf_counter() - resumed
                        break
                    elapsed += time.perf_counter() - resumed
                    yield min(1.0, before + weight * min(max(float(fraction), 0.0), 1.0))
            finally:
                steps.close()
            working.stage_seconds[name] = working.stage_seconds.get(name, 0.0) + elapsed
            solver = working
            if self.commit_each_stage:
                self._commit(session, solver)
            before += weight
        self._commit(session, solver)
        yield 1.0

    @staticmethod
    def _commit(session, solver) -> None:
        if session.state.get(SOLVER) is not solver:
            session.state[SOLVER] = solver
            session.state[STATS] = solver_stats(solver)

    def stage_finish(self, context) -> str:
        try:
            session = self._session
            solver = session.state[SOLVER]
            seconds = time.perf_counter() - self._started
            message = f"{self.bl_label}: {self.describe(solver)} ({seconds:.1f} s)"
            if self.writes:
                if session.dirty:
                    message += "; the scene changed meanwhile: the results show it as it was when the bake started"
                message += "; " + _write(context, session)
            return message
        finally:
            _running.pop(self._uid, None)

    def stage_cancelled(self, context) -> None:
        _running.pop(self._uid, None)

    def describe(self, solver) -> str:
        stats = solver_stats(solver)
        if not stats["lit"]:
            return "visibility built"
        counts = f"{stats['leaf_triangles']:,} triangles, {stats['links']:,} links"
        if solver.iterations == 0 and not solver.converged:
            return f"coarse lighting, {counts}"
        iterations = f"{solver.iterations} refinement iteration{'' if solver.iterations == 1 else 's'}"
        state = "converged" if solver.converged else "not converged"
        if solver.stopped is not None:
            state = f"refinement stopped: {solver.stopped}"
        return f"{iterations} ({state}), {counts}"


def _missing(solver) -> list[str]:
    """The stages `solver` needs before it can refine."""
    plan = []
    if solver.facing is None:
        plan.append("build_skeleton")
    if solver.lighting is None:
        plan.append("coarse_lighting")
    return plan


class BuildSkeletonStage(SolverStage):
    bl_label = "Build Skeleton"

    def fresh(self, solver) -> bool:
        return True

    def plan(self, solver, settings):
        return ["build_skeleton"]


class CoarseLightingStage(SolverStage):
    bl_label = "Coarse Lighting"

    def fresh(self, solver) -> bool:
        return solver.lighting is not None

    def plan(self, solver, settings):
        return [*(["build_skeleton"] if solver.facing is None else []), "coarse_lighting"]


class RefineStage(SolverStage):
    bl_label = "Refine"

    def plan(self, solver, settings):
        return [*_missing(solver), "refine"]


class BakeStage(SolverStage):
    bl_label = "Bake"
    writes = True
    commit_each_stage = True

    def plan(self, solver, settings):
        return [*_missing(solver), *["refine"] * max(0, settings["max_iterations"] - solver.iterations)]


class VISRAD_OT_build_skeleton(BuildSkeletonStage, bpy.types.Operator):
    """Start over: compute the scene's global visibility (which surfaces can exchange light)"""

    bl_idname = "visrad.build_skeleton"


class VISRAD_OT_coarse_lighting(CoarseLightingStage, bpy.types.Operator):
    """Light the coarse mesh (the scene's polygons): exact form factors from every corner to every source it
    sees. Starts the lighting over; builds the visibility first when needed"""

    bl_idname = "visrad.coarse_lighting"


class VISRAD_OT_refine(RefineStage, bpy.types.Operator):
    """One refinement iteration: subdivide where the lighting error is perceptible, link the new vertices,
    solve again (runs the earlier stages first when needed)"""

    bl_idname = "visrad.refine"


class VISRAD_OT_bake(BakeStage, bpy.types.Operator):
    """Every stage: visibility, coarse lighting, refinement until converged or Max Iterations, then write the
    result meshes"""

    bl_idname = "visrad.bake"


class VISRAD_OT_write_results(bpy.types.Operator):
    """Write the current solution as result meshes with the visrad_radiance attribute (replaces the previous
    results once the new ones are complete)"""

    bl_idname = "visrad.write_results"
    bl_label = "Write Results"
    bl_options = {"REGISTER", "UNDO"}

    @classmethod
    def poll(cls, context):
        if not has_solution(store.get(context.scene)):
            cls.poll_message_set("No solution yet: run Coarse Lighting, Refine or Bake first")
            return False
        return True

    def execute(self, context):
        try:
            session = store.open(context, solver_settings(context.scene.visrad))
        except SceneError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        if not has_solution(session):
            self.report({"ERROR"}, "The scene or the settings changed since the solution: run the stages again")
            return {"CANCELLED"}
        try:
            message = _write(context, session)
        except StageError as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        self.report({"INFO"}, f"Write Results: {message}")
        return {"FINISHED"}


classes = (
    VISRAD_OT_build_skeleton,
    VISRAD_OT_coarse_lighting,
    VISRAD_OT_refine,
    VISRAD_OT_bake,
    VISRAD_OT_write_results,
)

register, unregister = bpy.utils.register_classes_factory(classes)
