"""The solver: seed 000 Fig. 7 — visibility, coarse lighting, then iterations of subdivision, link refinement
and gathering at the vertices of the hierarchical triangulations, with push-pull between them.

Unknowns. Radiosity is gathered at hierarchy vertices, one value per side (rows 2 v + side). Each polygon side
radiates, as a source, the pull of its vertex values (area-weighted average over its leaf triangles, section
3.2): X = A B with A the pull matrix (columns 2 p + side). A row gathers B_r = E_r + rho_r sum_links F X_col.
Full global illumination solves (I - A R F) X = A E exactly (a linear system in polygon sides, small); k bounces
apply the gather k times from X = E. Gathering at every vertex from every source it sees makes the lazy-wavelet
Delta B of eq. 1 the difference between a vertex's gathered value and the interpolation of its ancestors', so
push (section 3.2) reconstructs the gathered values exactly at the vertices and linearly inside the leaves.

Refinement (sections 6.2-6.4). After each solve every leaf triangle is tested: the exact radiosity at its
centroid and edge midpoints against the linear interpolation of its corners, the difference tone-mapped with
Ward's factor (perception.py). Leaves whose error is perceptible are subdivided: with a regular grid (plus the
maxima of the important light transfers, section 6.3) during the first `regular_levels` iterations, then by
inserting the worst sample. Stages are generators yielding their progress; the state they change is replaced
only when a stage completes, so a cancelled stage leaves the solver as it was.
"""

from __future__ import annotations

import copy
import resource
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import LinearOperator, gmres, splu

from ..errors import CancelledError, VisradError
from ..hierarchy import Hierarchy
from ..skeleton import Skeleton
from ..visibility import scene_bvh
from .checks import LeafChecks, carry, complete_steps, links_at_samples, measure
from .contact import contact_regions, covered_fraction, inside_regions
from .discontinuities import ReceiverEvents, clip_to_convex, crossing, event_variation, receiver_events
from .interpolation import locate
from .links import BACK, FRONT, LinkSet, PairShafts, _inside_limit, compute_links, facing_sources
from .maxima import transfer_maxima
from .oracle import exact_transfers
from .perception import LUMINANCE_WEIGHTS, radiosity_threshold
from .result import Result
from .settings import Settings
from .sources import element_pull, element_variation, fold_to_polygons, refine_sources

Progress = Callable[[str, float], None]
# receiver points linked per chunk: progress and cancel get a say this often
_LINK_CHUNK = 2048
# what the transfers a refined vertex inherits instead of linking may cost together (oracle.py): half the JND, so
# that what the refinement test checks exactly still decides, and at most a fraction of the local radiosity, so
# that the energy balance holds where the JND is a large part of the radiosity (dim scenes)
_INHERIT_JND = 0.5
_INHERIT_RELATIVE = 0.002
# the error a link to a source's average may carry before the source is refined for it, in JND: gathered from many
# sources, the errors of their averages stay below what the refinement test can see
_SOURCE_JND = 0.25
# the largest radiosity system solved by sparse LU; larger ones (source refinement) by GMRES
_DIRECT_SOLVE_COLUMNS = 4096
# reflectors whose visual events are meshed too, and the least power (a fraction of the emitters') they radiate
_INDIRECT_SOURCES = 2
_INDIRECT_POWER = 0.05
# most visual events inserted into one receiver polygon per refinement iteration, highest Delta B first
_EVENTS_PER_POLYGON = 64
Cancel = Callable[[], bool]


@dataclass
class _Lighting:
    """What gathering produced: the hierarchy, links of its vertex sides, and the solution."""

    hierarchy: Hierarchy
    links: LinkSet  # point = row 2 v + side
    radiosity: np.ndarray  # (2 N, 3) rows 2 v + side
    sources: np.ndarray  # (2 P, 3) radiosity each polygon side radiates (the pull X)
    threshold: float
    checks: LeafChecks | None = None  # of the hierarchy's leaves, once a refinement test ran


class Solver:
    """Visibility-driven hierarchical radiosity on a core.scene.Scene (DESIGN.md section 3).

    Each stage is callable alone and in order: build_skeleton(), coarse_lighting(), refine(iterations);
    solve() runs what has not run yet and returns the Result. The *_steps() generators are the same stages
    yielding their fraction done (the add-on drives them on a timer); progress(stage, fraction) and cancel()
    are optional callables, and a cancelled stage raises CancelledError leaving the last consistent state.
    """

    def __init__(self, scene, settings: Settings | None = None, progress: Progress | None = None,
                 cancel: Cancel | None = None):  # fmt: skip
        self.scene = scene
        self.settings = settings if settings is not None else Settings()
        if not isinstance(self.settings, Settings):
            raise VisradError(f"settings must be a core.pipeline.Settings, got {type(self.settings).__name__}")
        self.progress = progress
        self.cancel = cancel
        self.bvh = None
        self.shafts: PairShafts | None = None
        self.facing = None
        self.contacts: dict = {}
        self.hidden_polygons = np.zeros(scene.n_polygons, dtype=bool)
        self.skeleton: Skeleton | None = None
        self.lighting: _Lighting | None = None
        self.discontinuities: dict[int, list[np.ndarray]] = {}
        self._inserted_events: set[tuple[int, int]] = set()
        self._rejected_events: set[tuple[int, int]] = set()
        self._events: dict[int, ReceiverEvents] = {}
        # the reflectors whose visual events are inserted too (indirect shadows), chosen at the first
        # discontinuity iteration; None before
        self.indirect_sources: np.ndarray | None = None
        self._indirect_inserted: set[tuple[int, int]] = set()
        self.iterations = 0
        self.converged = False
        # why refinement stopped before converging (a hierarchy defect), or None
        self.stopped: str | None = None
        self.stage_seconds: dict[str, float] = {}
        self.refinement_log: list[dict] = []
        self._reflectance = np.repeat(scene.reflectance, 2, axis=0)
        emission = np.repeat(scene.emission, 2, axis=0)
        emission[1::2] *= scene.two_sided[:, None]
        self._emission = emission  # (2 P, 3) per polygon side
        self._emitters = (scene.emission > 0.0).any(axis=1)

    # ------------------------------------------------------------------ stages

    def build_skeleton(self) -> Solver:
        """Global visibility: the BVH and which polygon sides can exchange light at all."""
        return self._run("build_skeleton", self.build_skeleton_steps())

    def coarse_lighting(self) -> Solver:
        """Links from every polygon corner to every source it sees (exact form factors) and the solution."""
        return self._run("coarse_lighting", self.coarse_lighting_steps())

    def refine(self, iterations: int = 1) -> bool:
        """Run refinement iterations (subdivide, link, gather); True when converged (nothing perceptible)."""
        for _ in range(iterations):
            if self.converged or self.stopped is not None:
                break
            self._run("refine", self.refine_steps())
        return self.converged

    def solve(self) -> Result:
        """Every stage not run yet, then refinement up to Settings.max_iterations; the Result."""
        if self.facing is None:
            self.build_skeleton()
        if self.lighting is None:
            self.coarse_lighting()
        self.refine(max(0, self.settings.max_iterations - self.iterations))
        return self.result()

    def build_skeleton_steps(self):
        facing = facing_sources(self.scene)
        self.bvh = scene_bvh(self.scene)
        self.shafts = PairShafts(self.scene, self.bvh)
        yield 0.05
        emitters = np.flatnonzero(self._emitters)
        skeleton = None
        if self.settings.discontinuities and len(emitters):
            skeleton = Skeleton(self.scene)
            for fraction in skeleton.build_steps(emitters, self.cancel):
                yield 0.05 + 0.9 * fraction
        contacts = contact_regions(self.scene)
        uncovered = (1.0 - covered_fraction(self.scene, contacts)) * self.scene.areas
        longest = np.array([_longest_side(self.scene.polygon(p)) for p in range(self.scene.n_polygons)])
        hidden = uncovered <= self.scene.tol.snap * longest
        facing[hidden] = False
        facing[:, :, hidden] = False
        self.facing, self.contacts, self.hidden_polygons = facing, contacts, hidden
        self.skeleton = skeleton
        self._events = {}
        yield 1.0

    def coarse_lighting_steps(self):
        if self.facing is None:
            yield from self.build_skeleton_steps()
        hierarchy = Hierarchy.from_scene(self.scene, grid=self.settings.grid)
        partial = [p for p in self.contacts if not self.hidden_polygons[p]]
        for polygon in partial:
            for piece in self.contacts[polygon]:
                hierarchy.insert_segments(polygon, np.stack([piece, np.roll(piece, -1, axis=0)], axis=1))
        if partial:
            hierarchy.complete_step()
        parts: list[LinkSet] = []
        for fraction in self._link_new_vertices(hierarchy, parts, 0):
            yield 0.9 * fraction
        self.lighting = self._gathered(hierarchy, LinkSet.concatenate(parts))
        yield 1.0

    def refine_steps(self):
        if self.lighting is None:
            yield from self.coarse_lighting_steps()
        if self.stopped is not None:
            yield 1.0
            return
        state = self.lighting
        hierarchy = copy.deepcopy(state.hierarchy)
        mesh = hierarchy.export_leaves()
        checks = state.checks
        if checks is None:
            checks = LeafChecks.fresh(mesh.triangles, self._exact_transfers(state, mesh))
        sampling = complete_steps(checks, mesh, self.scene, self.bvh, self.facing, self.settings, self.shafts)
        while True:
            try:
                yield 0.3 * next(sampling)
            except StopIteration as done:
                checks = done.value
                break
        gather = self._gather_matrix(state.links, len(state.radiosity), state.hierarchy)
        visible = self._visible_triangles(mesh)
        errors, worst, per_source = measure(
            checks, mesh, gather, state.sources, self.scene.reflectance, self.scene.two_sided, visible
        )
        exact = self._exact_transfers(state, mesh, checks.live, per_source)
        yield 0.3
        bad = errors >= state.threshold
        refined = np.unique(mesh.triangle_element[bad])
        record = {"iteration": self.iterations + 1, "leaves": len(mesh.triangles), "refined": len(refined)}
        if not len(refined):
            self.converged = True
            self.refinement_log.append(record)
            yield 1.0
            return
        regular = self.iterations < self.settings.regular_levels
        rejected = []
        if regular:
            if self.iterations == 0:
                record["maxima"] = self._insert_maxima(
                    hierarchy, state, np.unique(hierarchy.element_polygon()[refined])
                )
            hierarchy.queue_regular_grid(refined)
            hierarchy.complete_step()
        else:
            if self.skeleton is not None and self.indirect_sources is None:
                chosen = self._important_reflectors(state)
                for fraction in self.skeleton.build_steps(chosen, self.cancel):
                    yield 0.3 + 0.05 * fraction
                self.indirect_sources = chosen
                record["indirect_sources"] = len(chosen)
            covered, inserted = self._insert_discontinuities(hierarchy, state, mesh, bad)
            self._insert_worst_samples(hierarchy, mesh, bad & ~covered, worst)
            try:
                hierarchy.complete_step()
            except (VisradError, RuntimeError) as error:
                # The triangulations could not take this step (a hierarchy defect, see the strict xfails of
                # tests/core/test_hierarchy.py). With discontinuities, the iteration refines at the worst samples
                # instead and the events are not tried again; without, refinement stops at the last consistent
                # state. Either way the refinement log says so.
                record["rejection"] = str(error).splitlines()[0]
                if not inserted:
                    self.stopped = record["rejection"]
                    self.refinement_log.append(record)
                    yield 1.0
                    return
                record["discontinuities_rejected"] = len(inserted)
                rejected = [(polygon, piece) for polygon, piece, _ in inserted]
                inserted = []
                hierarchy = copy.deepcopy(state.hierarchy)
                self._insert_worst_samples(hierarchy, mesh, bad, worst)
                hierarchy.complete_step()
            record["discontinuities"] = len(inserted)
        yield 0.4
        parts = [state.links]
        for fraction in self._link_refined_vertices(hierarchy, state, mesh, exact, parts, checks, record):
            yield 0.4 + 0.5 * fraction
        checks = carry(checks, mesh, exact, hierarchy.export_leaves(), self._emitters)
        lighting = self._gathered(hierarchy, LinkSet.concatenate(parts), checks)
        if self.settings.exact and self.settings.source_refinement:
            links, record["source_links_refined"] = self._refine_sources(lighting)
            if record["source_links_refined"]:
                lighting = self._gathered(hierarchy, links, checks)
        self.lighting = lighting
        self._rejected_events.update(rejected)
        if not regular:
            for polygon, piece, segment in inserted:
                self._inserted_events.add((polygon, piece))
                events = self._events[polygon]
                # a piece where an emitter's trace and a reflector's coincide (a contact line) is a direct event
                if not self._emitters[events.emitter[events.group == piece]].any():
                    self._indirect_inserted.add((polygon, piece))
                self.discontinuities.setdefault(polygon, []).append(segment)
        self.iterations += 1
        record["vertices"] = hierarchy.vertex_count
        self.refinement_log.append(record)
        yield 1.0

    # ------------------------------------------------------------------ result

    def result(self) -> Result:
        """The current solution as a Result (leaf triangles per side, radiosity per vertex side, stats)."""
        if self.lighting is None:
            raise VisradError("no lighting yet: run coarse_lighting() (or solve()) first")
        state = self.lighting
        mesh = state.hierarchy.export_leaves()
        corners = mesh.vertices[mesh.triangles]
        facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        # needles that the triangulation's integer rounding left without area (or turned over) carry nothing, and
        # their orientation (how the add-on tells the two sides apart) would be rounding noise
        has_area = np.einsum("ij,ij->i", facing, self.scene.normals[mesh.triangle_polygon]) > self.scene.tol.area
        shown = self._visible_triangles(mesh) & has_area
        front_tri, front_poly = mesh.triangles[shown], mesh.triangle_polygon[shown]
        used = np.unique(front_tri)
        remap = np.full(state.hierarchy.vertex_count, -1, dtype=np.int64)
        remap[used] = np.arange(len(used))
        two_sided_tri = self.scene.two_sided[front_poly]
        back_used = np.unique(front_tri[two_sided_tri])
        back_remap = np.full(state.hierarchy.vertex_count, -1, dtype=np.int64)
        back_remap[back_used] = len(used) + np.arange(len(back_used))
        back_triangles = back_remap[front_tri[two_sided_tri][:, ::-1]]
        triangles = np.concatenate([remap[front_tri], back_triangles])
        polygons = np.concatenate([front_poly, front_poly[two_sided_tri]])
        sides = np.concatenate([np.zeros(len(front_tri), np.int8), np.ones(len(back_triangles), np.int8)])
        vertices = np.concatenate([mesh.vertices[used], mesh.vertices[back_used]])
        radiosity = np.concatenate([state.radiosity[2 * used], state.radiosity[2 * back_used + 1]])
        return Result(
            vertices=vertices,
            triangles=triangles,
            triangle_polygon=polygons,
            triangle_side=sides,
            radiosity=radiosity,
            discontinuities={polygon: np.array(segments) for polygon, segments in self.discontinuities.items()},
            stats=self.stats(),
        )

    def stats(self) -> dict:
        state = self.lighting
        out = {
            "seconds": dict(self.stage_seconds),
            "iterations": self.iterations,
            "converged": self.converged,
            "stopped": self.stopped,
            "refinement": list(self.refinement_log),
            "peak_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024,
            "polygons": self.scene.n_polygons,
            "discontinuities_inserted": len(self._inserted_events),
            "discontinuities_indirect": len(self._indirect_inserted),
            "discontinuities_rejected": len(self._rejected_events),
            "discontinuities_available": sum(len(events.pieces) for events in self._events.values()),
        }
        if self.shafts is not None and len(self.shafts):
            lengths = np.diff(self.shafts.lists.offsets)
            out["blocker_lists"] = {
                "pairs": len(lengths),
                "unoccluded": int(np.count_nonzero(lengths == 0)),
                "mean_blockers": float(lengths.mean()),
            }
        if self.skeleton is not None:
            skeleton = self.skeleton.stats
            out["skeleton"] = {key: skeleton[key] for key in ("nodes", "arcs", "seconds", "bytes")}
        if state is not None:
            out["links"] = len(state.links)
            out["vertices"] = state.hierarchy.vertex_count
            out["triangles"] = len(state.hierarchy.leaves())
            out["leaf_triangles"] = len(state.hierarchy.export_leaves().triangles)
        return out

    # ------------------------------------------------------------------ internals

    def _run(self, name: str, steps):
        started = time.perf_counter()
        for fraction in steps:
            if self.cancel is not None and self.cancel():
                raise CancelledError(f"{name} cancelled")
            if self.progress is not None:
                self.progress(name, float(fraction))
        self.stage_seconds[name] = self.stage_seconds.get(name, 0.0) + time.perf_counter() - started
        return self

    def _vertex_sides(self, hierarchy: Hierarchy, first: int) -> tuple:
        """Rows 2 v + side of vertices first.. and their polygons: front always, back on two-sided polygons."""
        vertex = np.arange(first, hierarchy.vertex_count)
        polygon = hierarchy.vertex_polygon()[vertex]
        back = self.scene.two_sided[polygon]
        rows = np.concatenate([2 * vertex, 2 * vertex[back] + 1])
        order = np.argsort(rows)
        polygons = np.concatenate([polygon, polygon[back]])[order]
        return rows[order], polygons

    def _link_new_vertices(self, hierarchy: Hierarchy, parts: list, first: int):
        """Append to `parts` the LinkSets (point = row) of the vertices first.., in chunks; yield the fraction."""
        rows, polygons = self._vertex_sides(hierarchy, first)
        positions = hierarchy.vertex_positions()[rows // 2]
        interior = self._vertex_interiors(hierarchy)[rows // 2]
        for start in range(0, len(rows), _LINK_CHUNK):
            stop = min(start + _LINK_CHUNK, len(rows))
            new = compute_links(
                self.scene, self.bvh, positions[start:stop], polygons[start:stop], rows[start:stop] % 2,
                self.facing, self.settings, interior[start:stop], shafts=self.shafts,
            )  # fmt: skip
            parts.append(LinkSet(rows[start:stop][new.point], new.column, new.form_factor))
            yield stop / len(rows)

    def _link_refined_vertices(
        self, hierarchy: Hierarchy, state: _Lighting, old_mesh, exact, parts: list, checks: LeafChecks, record: dict
    ):
        """Append to `parts` the links of the vertices refinement created (section 4.2, lazily): exact links to
        the sources `exact` (T, P) marks for the old leaf each vertex was inserted in (both leaves for a vertex on
        their shared edge), and for every other source the barycentric combination of that leaf's corners'
        effective form factors. A vertex inserted at a sample of its leaves (an edge midpoint of the regular
        grid, a worst sample) takes the sample's exact links from `checks` (the checks of old_mesh's leaves);
        `record` (the iteration's log) gets how many did. Yields the fraction done."""
        first = len(state.radiosity) // 2
        rows, polygons = self._vertex_sides(hierarchy, first)
        if not len(rows):
            yield 1.0
            return
        vertex = rows // 2
        side = rows % 2
        positions = hierarchy.vertex_positions()[vertex]
        interior = self._vertex_interiors(hierarchy)[vertex]
        best, other, weights = locate(
            old_mesh.vertices, old_mesh.triangles, old_mesh.triangle_polygon, positions, polygons
        )
        wanted = exact[best] | np.where((other >= 0)[:, None], exact[np.maximum(other, 0)], False)
        corners = 2 * old_mesh.triangles[best] + side[:, None]
        spread = sp.csr_matrix(
            (weights.ravel(), (np.repeat(np.arange(len(rows)), 3), corners.ravel())),
            shape=(len(rows), len(state.radiosity)),
        )
        inherited = (spread @ self._gather_matrix(state.links, len(state.radiosity), state.hierarchy)).tocoo()
        keep = ~wanted[inherited.row, inherited.col // 2] & (inherited.data != 0.0)
        parts.append(LinkSet(rows[inherited.row[keep]], inherited.col[keep].astype(np.int64), inherited.data[keep]))
        found, reused = links_at_samples(
            checks, old_mesh, positions, side, np.column_stack([best, other]), wanted, self.scene.tol.length
        )
        # a sample was evaluated at the point itself unless the point touches another polygon's plane
        evaluated = _inside_limit(self.scene, positions, polygons, side, self.facing, interior)
        found &= (evaluated == positions).all(axis=1)
        reused = _select_points(reused, found)
        parts.append(LinkSet(rows[reused.point], reused.column, reused.form_factor))
        record["linked_vertex_sides"] = len(rows)
        record["from_samples"] = int(found.sum())
        todo = np.flatnonzero(~found)
        for start in range(0, len(todo), _LINK_CHUNK):
            chunk = todo[start : start + _LINK_CHUNK]
            new = compute_links(
                self.scene, self.bvh, evaluated[chunk], polygons[chunk], side[chunk], self.facing, self.settings,
                wanted=wanted[chunk], evaluated=True, shafts=self.shafts,
            )  # fmt: skip
            parts.append(LinkSet(rows[chunk][new.point], new.column, new.form_factor))
            yield (start + len(chunk)) / len(todo)
        yield 1.0

    def _exact_transfers(self, state: _Lighting, mesh, live=None, measured=None) -> np.ndarray:
        """(T, P) bool: the sources each leaf triangle's new vertices and samples link exactly (oracle.py)."""
        corners = mesh.vertices[mesh.triangles]
        centres = corners.mean(axis=1)
        radii = np.linalg.norm(corners - centres[:, None], axis=2).max(axis=1)
        return exact_transfers(
            centres, radii, self.scene.reflectance[mesh.triangle_polygon], self.scene, state.sources, self._emitters,
            self._inherit_allowance(state, mesh), live, measured,
        )  # fmt: skip

    def _inherit_allowance(self, state: _Lighting, mesh) -> np.ndarray:
        """(T,) the luminance-weighted radiosity error the transfers inherited in each leaf may add up to."""
        luminance = (state.radiosity @ LUMINANCE_WEIGHTS).reshape(-1, 2).max(axis=1)
        local = luminance[mesh.triangles].mean(axis=1)
        return np.minimum(_INHERIT_JND * state.threshold, _INHERIT_RELATIVE * local)

    def _gather_matrix(self, links: LinkSet, n_rows: int, hierarchy: Hierarchy):
        """(n_rows, 2 P) sparse effective form factors of the links, per polygon side (element links added up)."""
        links = fold_to_polygons(links, hierarchy.element_polygon())
        shape = (n_rows, 2 * self.scene.n_polygons)
        return sp.csr_matrix((links.form_factor, (links.point, links.column)), shape=shape)

    def _vertex_interiors(self, hierarchy: Hierarchy) -> np.ndarray:
        """(N, 3): for every vertex the centroid of a visible leaf triangle around it (of any, when none is)."""
        mesh = hierarchy.export_leaves()
        centroids = mesh.vertices[mesh.triangles].mean(axis=1)
        interior = self.scene.centroids[hierarchy.vertex_polygon()].copy()
        visible = self._visible_triangles(mesh)
        for chosen in (~visible, visible):
            for k in range(3):
                interior[mesh.triangles[chosen, k]] = centroids[chosen]
        return interior

    def _gathered(self, hierarchy: Hierarchy, links: LinkSet, checks: LeafChecks | None = None) -> _Lighting:
        """Solve for the radiosity at every vertex side given the links (to polygon sides and, after source
        refinement, to element sides: each radiates the pull of its leaves)."""
        n_rows = 2 * hierarchy.vertex_count
        polygon_columns = 2 * self.scene.n_polygons
        elements = np.unique(links.column[links.column >= polygon_columns] // 2)
        columns = np.concatenate([np.arange(polygon_columns), (2 * elements[:, None] + [FRONT, BACK]).ravel()])
        n_cols = len(columns)
        gather = sp.csr_matrix(
            (links.form_factor, (links.point, np.searchsorted(columns, links.column))), shape=(n_rows, n_cols)
        )
        pull = self._pull_matrix(hierarchy, n_rows, polygon_columns)
        column_emission = self._emission
        if len(elements):
            mesh = hierarchy.export_leaves()
            below = element_pull(
                mesh, self._visible_triangles(mesh), hierarchy.element_parent(), self.scene.n_polygons, elements,
                n_rows,
            )  # fmt: skip
            pull = sp.vstack([pull, below]).tocsr()
            column_polygon = hierarchy.element_polygon()[columns // 2]
            column_emission = self._emission[2 * column_polygon + columns % 2]
        row_polygon = np.repeat(hierarchy.vertex_polygon(), 2)
        rho = self.scene.reflectance[row_polygon]
        emission = self._emission[2 * row_polygon + np.tile([FRONT, BACK], hierarchy.vertex_count)]
        bounces = self.settings.max_bounces
        sources = np.empty((n_cols, 3))
        if bounces is None:
            for c in range(3):
                sources[:, c] = _solve_columns(pull, sp.diags(rho[:, c]) @ gather, pull @ emission[:, c])
        else:
            sources = column_emission.copy()
            for _ in range(bounces - 1):
                sources = pull @ (emission + rho * (gather @ sources))
        radiosity = emission + rho * (gather @ sources)
        if bounces is None:
            sources = pull @ radiosity
        average = (pull @ radiosity)[:polygon_columns:2]
        areas = self.scene.areas
        adaptation = (areas[:, None] * average).sum(axis=0) / areas.sum()
        threshold = radiosity_threshold(adaptation, self.settings)
        return _Lighting(hierarchy, links, radiosity, sources[:polygon_columns], threshold, checks)

    def _refine_sources(self, state: _Lighting) -> tuple:
        """The links of `state` with the sources too uneven for their average refined (sources.py): (links,
        number of polygon links refined)."""
        hierarchy = state.hierarchy
        mesh = hierarchy.export_leaves()
        variation = element_variation(
            mesh, self._visible_triangles(mesh), state.radiosity, hierarchy.element_parent(), self.scene.n_polygons
        )
        folded = fold_to_polygons(state.links, hierarchy.element_polygon())
        merged = sp.csr_matrix(
            (folded.form_factor, (folded.point, folded.column)),
            shape=(len(state.radiosity), 2 * self.scene.n_polygons),
        ).tocoo()
        links = LinkSet(merged.row.astype(np.int64), merged.col.astype(np.int64), merged.data)
        row_polygon = np.repeat(hierarchy.vertex_polygon(), 2)
        rho = self.scene.reflectance[row_polygon] @ LUMINANCE_WEIGHTS
        with np.errstate(divide="ignore"):
            limits = np.where(rho > 0.0, _SOURCE_JND * state.threshold / rho, np.inf)
        return refine_sources(
            self.scene, self.bvh, hierarchy, links, np.repeat(hierarchy.vertex_positions(), 2, axis=0), row_polygon,
            np.repeat(self._vertex_interiors(hierarchy), 2, axis=0), self.facing, variation, limits,
        )  # fmt: skip

    def _pull_matrix(self, hierarchy: Hierarchy, n_rows: int, n_cols: int):
        """(2 P, 2 N) sparse: each polygon side's area-weighted average of its leaf triangles' vertex means."""
        mesh = hierarchy.export_leaves()
        shown = self._visible_triangles(mesh)
        mesh_triangles, mesh_polygon = mesh.triangles[shown], mesh.triangle_polygon[shown]
        corners = mesh.vertices[mesh_triangles]
        area = 0.5 * np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
        total = np.zeros(self.scene.n_polygons)
        np.add.at(total, mesh_polygon, area)
        weight = np.repeat(area / (3.0 * total[mesh_polygon]), 3)
        vertex = mesh_triangles.ravel()
        polygon = np.repeat(mesh_polygon, 3)
        rows = np.concatenate([2 * polygon, 2 * polygon + 1])
        cols = np.concatenate([2 * vertex, 2 * vertex + 1])
        return sp.csr_matrix((np.concatenate([weight, weight]), (rows, cols)), shape=(n_cols, n_rows))

    def _visible_triangles(self, mesh) -> np.ndarray:
        """(T,) bool: leaf triangles not hidden by contact (their polygon covered, or inside a contact piece)."""
        shown = ~self.hidden_polygons[mesh.triangle_polygon]
        if self.contacts:
            centroids = mesh.vertices[mesh.triangles].mean(axis=1)
            shown &= ~inside_regions(centroids, mesh.triangle_polygon, self.scene, self.contacts)
        return shown

    def _insert_worst_samples(self, hierarchy: Hierarchy, mesh, leaves: np.ndarray, worst: np.ndarray) -> None:
        """Queue into each leaf of `leaves` (T,) bool its worst sample (T, 3) (the radiometric refinement)."""
        for triangle in np.flatnonzero(leaves):
            element = int(mesh.triangle_element[triangle])
            polygon = int(mesh.triangle_polygon[triangle])
            point = hierarchy.frames.to_2d(polygon, worst[triangle][None, :])
            hierarchy.insert_into_element(element, point, np.zeros((0, 2, 2)))

    def _insert_discontinuities(self, hierarchy: Hierarchy, state: _Lighting, mesh, bad: np.ndarray) -> tuple:
        """Queue the ranked visual events of the emitters (section 6.4) onto the polygons of the leaves that
        need refining: on each polygon the pieces of events (collinear traces merged) not inserted yet that cross
        such a leaf and whose largest Delta B on it is perceptible, highest first. Returns ((T,) bool the leaves
        an inserted piece crosses, [(polygon, piece, (2, 3) the piece clipped to the polygon)])."""
        covered = np.zeros(len(mesh.triangles), dtype=bool)
        inserted = []
        if self.skeleton is None:
            return covered, inserted
        corners = mesh.vertices[mesh.triangles]
        sizes = np.linalg.norm(corners - np.roll(corners, 1, axis=1), axis=2).max(axis=1)
        to_2d = hierarchy.frames.to_2d
        for polygon in np.unique(mesh.triangle_polygon[bad]).tolist():
            events = self._receiver_events(polygon)
            if not len(events):
                continue
            leaves = np.flatnonzero(bad & (mesh.triangle_polygon == polygon))
            meets = crossing(
                to_2d(polygon, events.pieces.reshape(-1, 3)).reshape(-1, 2, 2),
                to_2d(polygon, corners[leaves].reshape(-1, 3)).reshape(-1, 3, 2),
                self.scene.tol.length,
            )
            tried = self._inserted_events | self._rejected_events
            fresh = np.array([(polygon, g) not in tried for g in range(len(events.pieces))])
            candidates = np.flatnonzero(meets.any(axis=1) & fresh)
            if not len(candidates):
                continue
            piece_size = np.zeros(len(events.pieces))
            piece_size[candidates] = [sizes[leaves[meets[g]]].max() for g in candidates]
            which = np.flatnonzero(np.isin(events.group, candidates))
            size = piece_size[events.group[which]]
            variation = event_variation(events, which, self.scene, polygon, state.sources, size)
            delta = np.zeros(len(events.pieces))
            np.maximum.at(delta, events.group[which], variation)
            order = candidates[np.argsort(-delta[candidates], kind="stable")]
            ranked = order[delta[order] >= state.threshold][:_EVENTS_PER_POLYGON]
            outline = self.scene.polygon(polygon)
            for piece in ranked.tolist():
                segment = clip_to_convex(events.pieces[piece], outline, self.scene.normals[polygon])
                if segment is None:
                    continue
                hierarchy.insert_segments(polygon, segment[None])
                covered[leaves[meets[piece]]] = True
                inserted.append((polygon, piece, segment))
        return covered, inserted

    def _receiver_events(self, polygon: int) -> ReceiverEvents:
        """The visual events of the emitters and of the indirect sources on `polygon`, from the skeleton,
        computed once per polygon (the indirect sources are chosen before the first call)."""
        if polygon not in self._events:
            sources = np.flatnonzero(self._emitters)
            if self.indirect_sources is not None:
                sources = np.concatenate([sources, self.indirect_sources])
            self._events[polygon] = receiver_events(self.skeleton, self.scene, polygon, sources)
        return self._events[polygon]

    def _important_reflectors(self, state: _Lighting) -> np.ndarray:
        """The non-emitting polygons radiating the most light (luminance-weighted radiosity x area), at most
        _INDIRECT_SOURCES of them and each at least _INDIRECT_POWER of what the emitters emit: the secondary
        sources whose shadows (indirect shadows, seed 000 section 7.2) are worth meshing."""
        radiated = (state.sources @ LUMINANCE_WEIGHTS).reshape(-1, 2).max(axis=1) * self.scene.areas
        emitted = radiated[self._emitters].sum()
        radiated[self._emitters] = 0.0
        order = np.argsort(-radiated, kind="stable")[:_INDIRECT_SOURCES]
        return order[radiated[order] >= _INDIRECT_POWER * emitted].astype(np.int64)

    def _insert_maxima(self, hierarchy: Hierarchy, state: _Lighting, polygons: np.ndarray) -> int:
        """Queue the maxima of the important unoccluded transfers onto the polygons being refined (6.3)."""
        inserted = 0
        for polygon, points in transfer_maxima(self.scene, state.sources, state.threshold, polygons, self.settings):
            hierarchy.insert_points(polygon, points)
            inserted += len(points)
        return inserted


def _select_points(links: LinkSet, chosen: np.ndarray) -> LinkSet:
    """The links whose point is chosen (N,) bool."""
    keep = chosen[links.point]
    return LinkSet(links.point[keep], links.column[keep], links.form_factor[keep])


def _solve_columns(pull, reflected_gather, emitted: np.ndarray) -> np.ndarray:
    """X solving (I - pull R G) X = pull E for the radiosity X each column radiates, given pull (C, 2 N),
    R G (2 N, C) and pull E (C,): directly when the columns are polygon sides only (a small system), else by
    GMRES on the operator (the system of element columns is large and only its products are cheap)."""
    size = pull.shape[0]
    if size <= _DIRECT_SOLVE_COLUMNS:
        return splu(sp.identity(size, format="csc") - (pull @ reflected_gather).tocsc()).solve(emitted)
    system = LinearOperator((size, size), matvec=lambda x: x - pull @ (reflected_gather @ x), dtype=np.float64)
    solution, info = gmres(system, emitted, rtol=1e-12, atol=0.0, restart=60, maxiter=200)
    if info != 0:
        raise VisradError(f"the radiosity system of {size} sources did not converge (GMRES info {info})")
    return solution


def _longest_side(corners: np.ndarray) -> float:
    return float(np.max(np.linalg.norm(np.roll(corners, -1, axis=0) - corners, axis=1)))
