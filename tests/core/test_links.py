"""Links (core/pipeline/links.py): which polygon sides can exchange light, computed in chunks, against a
naive pairwise reference; a scene too large for the machine's memory is refused with a clear error."""

import numpy as np
import pytest

from bench.scenes import closed_furnished_room
from core.errors import VisradError
from core.pipeline import Solver, links
from core.scene import Scene


def _room(two_sided_panel: bool) -> Scene:
    spec = closed_furnished_room(3, n_boxes=5)
    vertices = np.concatenate([spec.vertices, [[1.0, 1.0, 1.0], [1.5, 1.0, 1.2], [1.5, 1.6, 1.2], [1.0, 1.6, 1.0]]])
    count = len(vertices)
    polygons = list(spec.polygons) + [[count - 4, count - 3, count - 2, count - 1]]
    ids = np.concatenate([spec.object_ids, [spec.object_ids.max() + 1]])
    n = len(polygons)
    return Scene.from_polygons(vertices, polygons, np.full((n, 3), 0.5), np.zeros((n, 3)), object_ids=ids,
                               two_sided=None if two_sided_panel else np.zeros(n, bool))  # fmt: skip


def _naive_facing(scene):
    eps = scene.tol.length
    count = scene.n_polygons
    out = np.zeros((count, 2, count), bool)
    for p in range(count):
        for q in range(count):
            if p == q:
                continue
            q_heights = scene.polygon(q) @ scene.normals[p] + scene.plane_offsets[p]
            p_heights = scene.polygon(p) @ scene.normals[q] + scene.plane_offsets[q]
            radiates = (p_heights > eps).any() or (scene.two_sided[q] and (p_heights < -eps).any())
            out[p, 0, q] = (q_heights > eps).any() and radiates
            out[p, 1, q] = scene.two_sided[p] and (q_heights < -eps).any() and radiates
    return out


@pytest.mark.parametrize("two_sided_panel", [True, False])
def test_facing_sources_in_chunks_equal_the_naive_pairs(monkeypatch, two_sided_panel):
    scene = _room(two_sided_panel)
    monkeypatch.setattr(links, "_HEIGHTS_PER_CHUNK", 7 * scene.n_polygons)
    facing = links.facing_sources(scene)
    np.testing.assert_array_equal(facing, _naive_facing(scene))
    assert facing[:, 1, :].any() == bool(scene.two_sided.any())


def test_a_scene_too_large_for_the_memory_is_refused_before_allocating(monkeypatch):
    scene = _room(True)
    monkeypatch.setattr(links, "_available_memory", lambda: 3 * scene.n_polygons**2)
    message = rf"pairs of the scene's {scene.n_polygons} polygons need about 0 MiB and 0 MiB"
    with pytest.raises(VisradError, match=message):
        Solver(scene).build_skeleton()
    monkeypatch.setattr(links, "_available_memory", lambda: None)
    assert links.facing_sources(scene).shape == (scene.n_polygons, 2, scene.n_polygons)


def test_pair_shafts_compute_each_pair_once_and_find_it_again(monkeypatch):
    """PairShafts.lookup: every (receiver, source) gets the blocker list shaft_blockers gives that pair alone,
    across calls that share pairs, and a pair is computed once."""
    from core.visibility import scene_bvh, shaft_blockers

    scene = _room(True)
    shafts = links.PairShafts(scene, scene_bvh(scene))
    computed = []
    original = links.shaft_blockers

    def counting(scene_, receivers, sources, bvh):
        computed.extend(zip(receivers.tolist(), sources.tolist(), strict=True))
        return original(scene_, receivers, sources, bvh)

    monkeypatch.setattr(links, "shaft_blockers", counting)
    rng = np.random.default_rng(3)
    first = rng.integers(0, scene.n_polygons, (2, 40))
    second = rng.integers(0, scene.n_polygons, (2, 40))
    for receivers, sources in (first, second, np.concatenate([second, first], axis=1)):
        found = shafts.lookup(receivers, sources)
        for r, q, k in zip(receivers, sources, found, strict=True):
            alone = shaft_blockers(scene, [r], [q])
            np.testing.assert_array_equal(shafts.lists.blockers(int(k)), alone.blockers(0))
    assert len(computed) == len(set(computed)) == len(shafts)
    assert len(shafts) == len(set(zip(*np.concatenate([first, second], axis=1).tolist(), strict=True)))


def test_pair_shafts_leave_pairs_to_the_bvh_beyond_their_budget():
    """Once the lists hold `budget` polygon ids, new pairs get -1 (the BVH) and the form factors stay exact."""
    from core.pipeline import Settings
    from core.visibility import scene_bvh

    scene = _room(True)
    shafts = links.PairShafts(scene, scene_bvh(scene), budget=1)
    first = shafts.lookup([0, 1, 2], [5, 5, 5])
    assert (first >= 0).all() and len(shafts.lists.ids) >= 1
    later = shafts.lookup([3, 0], [5, 5])
    assert later[0] == -1 and later[1] == first[0]
    facing = links.facing_sources(scene)
    points = np.array([scene.centroids[p] for p in range(4)])
    polygons = np.arange(4)
    sides = np.zeros(4, dtype=np.int64)
    settings = Settings()
    limited = links.compute_links(scene, shafts.bvh, points, polygons, sides, facing, settings, shafts=shafts)
    everything = links.compute_links(scene, shafts.bvh, points, polygons, sides, facing, settings)
    np.testing.assert_array_equal(limited.column, everything.column)
    np.testing.assert_allclose(limited.form_factor, everything.form_factor, rtol=0, atol=1e-12)
