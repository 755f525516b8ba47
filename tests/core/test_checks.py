"""The refinement test's sample form factors (core/pipeline/checks.py): computing each distinct sample point once
(edge midpoints shared by two leaves) gives exactly what linking every leaf's samples alone gives."""

import numpy as np

from core.pipeline import Settings, Solver, checks
from core.pipeline.links import BACK, FRONT, compute_links
from tests.core.test_pipeline import _light_box_plane_scene


def _naive_sampled(leaf_checks, mesh, scene, solver):
    """(2 T S, 2 P) dense: each leaf side's samples linked alone to the sources live at that leaf."""
    samples = checks.sample_points(mesh)
    out = np.zeros(leaf_checks.sampled.shape)
    for leaf in range(len(mesh.triangles)):
        polygon = mesh.triangle_polygon[leaf]
        for side in (FRONT, BACK) if scene.two_sided[polygon] else (FRONT,):
            links = compute_links(
                scene, solver.bvh, samples[leaf], np.full(checks.N_SAMPLES, polygon), np.full(checks.N_SAMPLES, side),
                solver.facing, solver.settings, np.repeat(samples[leaf, :1], checks.N_SAMPLES, axis=0),
                np.repeat(leaf_checks.live[leaf][None], checks.N_SAMPLES, axis=0),
            )  # fmt: skip
            out[(2 * leaf + side) * checks.N_SAMPLES + links.point, links.column] = links.form_factor
    return out


def test_shared_samples_computed_once_equal_every_leaf_sampled_alone(monkeypatch):
    scene = _light_box_plane_scene()
    solver = Solver(scene, Settings(max_iterations=1))
    solver.solve()
    mesh = solver.lighting.hierarchy.export_leaves()
    rng = np.random.default_rng(5)
    # live sources differing between neighbours here and there, so that a shared midpoint serves two masks
    live = (rng.random(scene.n_polygons) < 0.7)[None, :] ^ (rng.random((len(mesh.triangles), scene.n_polygons)) < 0.1)
    fresh = checks.LeafChecks.fresh(mesh.triangles, live)
    pairs = []
    linked = checks.compute_links

    def counting(*args, **kwargs):
        links = linked(*args, **kwargs)
        pairs.append(int(kwargs["wanted"].sum()))
        return links

    monkeypatch.setattr(checks, "_CHUNK_LEAVES", 256)
    monkeypatch.setattr(checks, "compute_links", counting)
    done = checks.complete_steps(fresh, mesh, scene, solver.bvh, solver.facing, solver.settings)
    fractions = []
    while True:
        try:
            fractions.append(next(done))
        except StopIteration as stop:
            completed = stop.value
            break
    assert len(fractions) > 1 and fractions[-1] == 1.0
    assert completed.known.all()
    expected = _naive_sampled(fresh, mesh, scene, solver)
    np.testing.assert_array_equal(completed.sampled.toarray(), expected)
    # back sides of the two-sided plane were sampled too
    assert (expected.reshape(len(mesh.triangles), 2, checks.N_SAMPLES, -1)[:, BACK] != 0).any()
    # the shared midpoints were linked once: fewer (point, source) pairs than the leaves' samples ask for
    two_sided = scene.two_sided[mesh.triangle_polygon]
    asked = checks.N_SAMPLES * (live.sum(axis=1) * (1 + two_sided)).sum()
    assert sum(pairs) < 0.8 * asked
