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


def test_points_on_samples_take_the_samples_links():
    """links_at_samples: edge midpoints and centroids of checked leaves get exactly the links compute_links
    gives them (restricted to the wanted sources, each source once for a midpoint shared by two leaves); points
    that are no sample, points of unchecked leaves and points wanting a source that is not live are not found."""
    from core.pipeline.interpolation import locate

    scene = _light_box_plane_scene()
    solver = Solver(scene, Settings(max_iterations=1))
    solver.solve()
    mesh = solver.lighting.hierarchy.export_leaves()
    rng = np.random.default_rng(11)
    count = len(mesh.triangles)
    live = rng.random((count, scene.n_polygons)) < 0.8
    known = rng.random(count) < 0.9
    done = checks.complete_steps(
        checks.LeafChecks.fresh(mesh.triangles, live), mesh, scene, solver.bvh, solver.facing, solver.settings
    )
    while True:
        try:
            next(done)
        except StopIteration as stop:
            completed = stop.value
            break
    leaf_checks = checks.LeafChecks(completed.corners, completed.live, completed.sampled, known)
    samples = checks.sample_points(mesh)
    chosen = rng.choice(count, 150, replace=False)
    picks = rng.integers(0, checks.N_SAMPLES, 150)
    weights = rng.dirichlet([3.0, 3.0, 3.0], size=40)
    others = rng.choice(count, 40, replace=False)
    points = np.concatenate([
        samples[chosen, picks], np.einsum("nk,nkc->nc", weights, mesh.vertices[mesh.triangles[others]])
    ])  # fmt: skip
    polygons = mesh.triangle_polygon[np.concatenate([chosen, others])]
    sides = np.where(scene.two_sided[polygons] & (rng.random(len(points)) < 0.5), BACK, FRONT)
    best, other, _ = locate(mesh.vertices, mesh.triangles, mesh.triangle_polygon, points, polygons)
    leaves = np.column_stack([best, other])
    wanted = live[best] & (rng.random((len(points), scene.n_polygons)) < 0.7)
    wanted[-20:-10] = True  # some wanting every source: found only where all are live
    found, links = checks.links_at_samples(leaf_checks, mesh, points, sides, leaves, wanted, scene.tol.length)
    holders = [known[b] and (o < 0 or known[o]) for b, o in zip(best, other, strict=True)]
    covered = ~(wanted & ~(live[best] | np.where((other >= 0)[:, None], live[np.maximum(other, 0)], False))).any(1)
    expected_found = np.array(holders) & covered
    expected_found[len(chosen):] = False
    np.testing.assert_array_equal(found, expected_found)
    assert found.sum() > 100 and (other[found] >= 0).any()
    reference = compute_links(
        scene, solver.bvh, points[found], polygons[found], sides[found], solver.facing, solver.settings,
        samples[best[found], 0], wanted[found],
    )  # fmt: skip
    ours = np.zeros((len(points), 2 * scene.n_polygons))
    ours[links.point, links.column] = links.form_factor
    theirs = np.zeros_like(ours)
    theirs[np.flatnonzero(found)[reference.point], reference.column] = reference.form_factor
    assert len(np.unique(links.point * ours.shape[1] + links.column)) == len(links)
    np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12)
