"""core.bvh: structure invariants and traversal against brute force over every box."""

import numpy as np
import pytest

from core.bvh import LEAF_SIZE, STACK_SIZE, build_bvh, build_bvh_from_boxes
from core.errors import SceneError
from core.scene import Scene


def random_boxes(rng, count, size=0.05):
    centre = rng.random((count, 3))
    half = rng.random((count, 3)) * size
    # flat boxes (axis-aligned polygons) are the common case in rooms
    half[rng.random(count) < 0.3, rng.integers(0, 3)] = 0.0
    return centre - half, centre + half


def brute_planes(lo, hi, planes, slack=0.0):
    keep = []
    for i in range(len(lo)):
        inside = True
        for n_x, n_y, n_z, d in planes:
            n = np.array([n_x, n_y, n_z])
            lowest = d + np.sum(n * np.where(n > 0, lo[i], hi[i]))
            if lowest > slack * np.linalg.norm(n):
                inside = False
        if inside:
            keep.append(i)
    return np.array(keep, dtype=np.int64)


def brute_segment(lo, hi, start, end):
    keep = []
    for i in range(len(lo)):
        t0, t1 = 0.0, 1.0
        hit = True
        for k in range(3):
            d = end[k] - start[k]
            if d == 0.0:
                if not lo[i, k] <= start[k] <= hi[i, k]:
                    hit = False
            else:
                a, b = sorted(((lo[i, k] - start[k]) / d, (hi[i, k] - start[k]) / d))
                t0, t1 = max(t0, a), min(t1, b)
        if hit and t0 <= t1:
            keep.append(i)
    return np.array(keep, dtype=np.int64)


def test_structure_invariants():
    rng = np.random.default_rng(0)
    lo, hi = random_boxes(rng, 1500)
    bvh = build_bvh_from_boxes(lo, hi)
    assert sorted(bvh.order.tolist()) == list(range(1500))
    assert bvh.depth + 1 <= STACK_SIZE
    for node in range(bvh.n_nodes):
        child = bvh.node_child[node]
        if child < 0:
            count = bvh.node_count[node]
            assert 1 <= count <= LEAF_SIZE
            members = bvh.order[bvh.node_first[node] : bvh.node_first[node] + count]
            assert np.all(bvh.node_min[node] <= lo[members]) and np.all(hi[members] <= bvh.node_max[node])
        else:
            for c in (child, child + 1):
                assert np.all(bvh.node_min[node] <= bvh.node_min[c])
                assert np.all(bvh.node_max[c] <= bvh.node_max[node])
    leaves = bvh.node_child < 0
    assert bvh.node_count[leaves].sum() == 1500
    assert not any(a.flags.writeable for a in bvh.arrays)


def test_plane_queries_equal_brute_force():
    rng = np.random.default_rng(1)
    lo, hi = random_boxes(rng, 400)
    bvh = build_bvh_from_boxes(lo, hi)
    for trial in range(60):
        count = int(rng.integers(0, 6))
        normals = rng.normal(size=(count, 3)) * rng.uniform(0.1, 10.0, size=(count, 1))
        through = rng.random((count, 3))
        planes = np.column_stack([normals, -np.einsum("ij,ij->i", normals, through)])
        slack = 0.0 if trial % 2 else 0.01
        expected = brute_planes(lo, hi, planes, slack)
        np.testing.assert_array_equal(bvh.query_planes(planes, slack), expected)
    assert len(bvh.query_planes(np.zeros((0, 4)))) == 400


def test_segment_queries_equal_brute_force():
    rng = np.random.default_rng(2)
    lo, hi = random_boxes(rng, 400)
    bvh = build_bvh_from_boxes(lo, hi)
    hits = 0
    for trial in range(300):
        start, end = rng.random(3) * 1.4 - 0.2, rng.random(3) * 1.4 - 0.2
        if trial % 3 == 0:
            end[trial % 9 // 3] = start[trial % 9 // 3]  # axis-parallel segments: zero direction components
        expected = brute_segment(lo, hi, start, end)
        hits += len(expected)
        np.testing.assert_array_equal(bvh.query_segment(start, end), expected)
    assert hits > 150


def test_collect_reports_full_count_when_buffer_is_short():
    from core.bvh import bvh_collect_in_planes

    rng = np.random.default_rng(3)
    lo, hi = random_boxes(rng, 100)
    bvh = build_bvh_from_boxes(lo, hi)
    out = np.full(10, -7, dtype=np.int64)
    count = bvh_collect_in_planes(*bvh.arrays, np.zeros((0, 4)), 0.0, out)
    assert count == 100
    assert len(set(out.tolist())) == 10 and out.min() >= 0


def test_degenerate_inputs():
    same = np.zeros((50, 3))
    bvh = build_bvh_from_boxes(same, same + 1.0)  # identical centroids: median fallback
    assert sorted(bvh.order.tolist()) == list(range(50))
    one = build_bvh_from_boxes(np.zeros((1, 3)), np.ones((1, 3)))
    assert one.n_nodes == 1 and one.query_segment([0.5, 0.5, -1], [0.5, 0.5, 2]).tolist() == [0]


def test_scene_bvh_pads_flat_polygons_by_the_tolerance():
    scene = Scene.from_polygons(
        [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], [[0, 1, 2, 3]], np.full((1, 3), 0.5), np.zeros((1, 3))
    )
    bvh = build_bvh(scene)
    assert bvh.pad == scene.tol.length
    assert bvh.query_segment([0.5, 0.5, 0.0], [0.7, 0.5, 0.0]).tolist() == [0]


@pytest.mark.parametrize(
    "lo, hi, message",
    [
        (np.zeros((2, 2)), np.ones((2, 2)), "box_min"),
        (np.zeros((2, 3)), np.ones((3, 3)), "same shape"),
        (np.ones((2, 3)), np.zeros((2, 3)), "box_min > box_max"),
        (np.full((2, 3), np.nan), np.ones((2, 3)), "non-finite"),
        (np.zeros((0, 3)), np.zeros((0, 3)), "at least one"),
    ],
)
def test_bad_boxes_are_rejected(lo, hi, message):
    with pytest.raises(SceneError, match=message):
        build_bvh_from_boxes(lo, hi)


def test_query_arguments_are_validated():
    bvh = build_bvh_from_boxes(np.zeros((1, 3)), np.ones((1, 3)))
    with pytest.raises(ValueError, match="planes"):
        bvh.query_planes(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="slack"):
        bvh.query_planes(np.zeros((1, 4)), slack=-1.0)
    with pytest.raises(ValueError, match="start"):
        bvh.query_segment([0, 0, np.inf], [1, 1, 1])
