"""core.raycast: against the naive references on random scenes, hand-built grazing cases, scale invariance,
and jittered form factors against closed forms."""

import numpy as np
import pytest

from core.bvh import build_bvh
from core.raycast import (
    CONTACT_EDGE,
    CONTACT_INTERIOR,
    CONTACT_NONE,
    CONTACT_SLIDING,
    CONTACT_VERTEX,
    batch_segment_contacts,
    first_hits,
    jittered_form_factors,
    segment_contacts,
    segments_occluded,
)
from core.scene import Scene
from tests.core.naive_raycast import naive_first_hits, naive_segments_occluded, parallel_rectangle_ff


def make_scene(vertices, polygons):
    count = len(polygons)
    return Scene.from_polygons(np.asarray(vertices, float), polygons, np.full((count, 3), 0.5), np.zeros((count, 3)))


def random_scene(rng, count=40):
    vertices, polygons = [], []
    for _ in range(count):
        centre = rng.random(3)
        axes = rng.normal(size=(2, 3)) * 0.15
        k = int(rng.integers(3, 7))
        angles = np.sort(rng.uniform(0, 2 * np.pi, k))
        polygons.append(list(range(len(vertices), len(vertices) + k)))
        vertices.extend(centre + np.cos(a) * axes[0] + np.sin(a) * axes[1] for a in angles)
    return make_scene(vertices, polygons)


def box(lo, hi, offset=0):
    """8 corners and 6 outward-facing quads of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    corners = [
        [x0, y0, z0],
        [x1, y0, z0],
        [x1, y1, z0],
        [x0, y1, z0],
        [x0, y0, z1],
        [x1, y0, z1],
        [x1, y1, z1],
        [x0, y1, z1],
    ]
    faces = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [2, 3, 7, 6], [0, 4, 7, 3], [1, 2, 6, 5]]
    return corners, [[offset + i for i in f] for f in faces]


def box_on_split_floor():
    """A unit cube [1,2]^2 x [0,1] standing on a floor [0,3] x [0,3] made of two coplanar quads split at x=1.5."""
    floor = [[0, 0, 0], [1.5, 0, 0], [3, 0, 0], [0, 3, 0], [1.5, 3, 0], [3, 3, 0]]
    corners, faces = box((1, 1, 1e-3), (2, 2, 1))
    return make_scene(floor + corners, [[0, 1, 4, 3], [1, 2, 5, 4]] + [[i + 6 for i in f] for f in faces])


# ---------------------------------------------------------------------------------------------------------
# random scenes against the naive references


def test_segments_occluded_equals_naive_on_random_scenes():
    rng = np.random.default_rng(10)
    scene = random_scene(rng)
    bvh = build_bvh(scene)
    starts = rng.random((2500, 3)) * 1.2 - 0.1
    ends = rng.random((2500, 3)) * 1.2 - 0.1
    got = segments_occluded(scene, bvh, starts, ends)
    np.testing.assert_array_equal(got, naive_segments_occluded(scene, starts, ends))
    assert 0.2 < got.mean() < 0.9
    exclude = rng.integers(-1, scene.n_polygons, size=(2500, 2))
    got = segments_occluded(scene, bvh, starts, ends, exclude=exclude)
    np.testing.assert_array_equal(got, naive_segments_occluded(scene, starts, ends, exclude))


def test_first_hits_equal_naive_on_random_scenes():
    rng = np.random.default_rng(11)
    scene = random_scene(rng)
    bvh = build_bvh(scene)
    origins = rng.random((2000, 3))
    directions = rng.normal(size=(2000, 3)) * rng.uniform(0.1, 3.0, size=(2000, 1))
    t_max = rng.uniform(0.05, 2.0, 2000)
    polygon, t, kind = first_hits(scene, bvh, origins, directions, t_max)
    ref_polygon, ref_t, ref_kind = naive_first_hits(scene, origins, directions, t_max)
    np.testing.assert_array_equal(polygon, ref_polygon)
    np.testing.assert_array_equal(kind, ref_kind)
    np.testing.assert_allclose(t[polygon >= 0], ref_t[polygon >= 0], rtol=1e-12)
    assert np.all(np.isinf(t[polygon < 0])) and np.all(kind[polygon < 0] == CONTACT_NONE)
    assert 0.2 < (polygon >= 0).mean() < 0.95


def test_first_hits_without_t_max_reach_the_scene_bounds():
    rng = np.random.default_rng(12)
    scene = random_scene(rng, 25)
    bvh = build_bvh(scene)
    origins = rng.random((500, 3))
    directions = rng.normal(size=(500, 3))
    polygon, t, kind = first_hits(scene, bvh, origins, directions)
    far = np.full(500, 10.0)  # well past the unit cube holding the scene
    ref_polygon, ref_t, ref_kind = naive_first_hits(scene, origins, directions, far)
    np.testing.assert_array_equal(polygon, ref_polygon)
    np.testing.assert_allclose(t[polygon >= 0], ref_t[polygon >= 0], rtol=1e-9)


def test_batch_contacts_are_sorted_and_agree_with_occlusion():
    rng = np.random.default_rng(13)
    scene = random_scene(rng)
    bvh = build_bvh(scene)
    starts, ends = rng.random((300, 3)), rng.random((300, 3))
    batch = batch_segment_contacts(scene, bvh, starts, ends)
    np.testing.assert_array_equal(batch.blocked, segments_occluded(scene, bvh, starts, ends))
    for i in range(300):
        one = batch.segment(i)
        assert np.all(np.diff(one.t) >= 0) and np.all((one.t > 0) & (one.t < 1))
        assert one.blocked == bool(np.any(one.kind == CONTACT_INTERIOR))
        single = segment_contacts(scene, bvh, starts[i], ends[i])
        np.testing.assert_array_equal(single.polygon, one.polygon)


# ---------------------------------------------------------------------------------------------------------
# grazing, built on purpose


def contacts(scene, start, end):
    return segment_contacts(scene, build_bvh(scene), start, end)


def occluded(scene, start, end):
    return bool(segments_occluded(scene, build_bvh(scene), np.array([start], float), np.array([end], float))[0])


def test_grazing_a_box_edge_is_not_occlusion_but_entering_through_it_is():
    scene = make_scene(*box((0, 0, 0), (1, 1, 1)))
    graze = ([-1, 1, 0.5], [1, -1, 0.5])  # touches only the vertical edge x = y = 0
    found = contacts(scene, *graze)
    assert found.kind.tolist() == [CONTACT_EDGE, CONTACT_EDGE]
    assert len(set(found.feature.tolist())) == 1 and found.silhouette.all()
    assert not found.blocked and not occluded(scene, *graze)
    diagonal = ([-1, -1, 0.5], [2, 2, 0.5])  # in at edge x = y = 0, out at edge x = y = 1
    found = contacts(scene, *diagonal)
    assert found.kind.tolist() == [CONTACT_EDGE] * 4 and found.blocked and occluded(scene, *diagonal)


def test_grazing_a_box_corner_is_not_occlusion_but_piercing_it_is():
    scene = make_scene(*box((0, 0, 0), (1, 1, 1)))
    graze = ([-1, 1, -0.3], [1, -1, 0.3])  # through corner 0 = (0, 0, 0), outside the box on both sides
    found = contacts(scene, *graze)
    assert found.kind.tolist() == [CONTACT_VERTEX] * 3 and set(found.feature.tolist()) == {0}
    assert found.silhouette.all() and not occluded(scene, *graze)
    in_bottom_plane = ([-1, 1, 0], [1, -1, 0])
    found = contacts(scene, *in_bottom_plane)
    assert sorted(found.kind.tolist()) == [CONTACT_VERTEX, CONTACT_VERTEX, CONTACT_SLIDING]
    assert not occluded(scene, *in_bottom_plane)
    graze_steep = ([1, -1, -1], [-1, 1, 1])  # through corner 0, direction (-1, 1, 1) stays outside
    assert not occluded(scene, *graze_steep)
    pierce = ([-1, -1, -1], [0.5, 0.5, 0.5])  # ends inside: only the corner is met, yet it enters the box
    found = contacts(scene, *pierce)
    assert found.kind.tolist() == [CONTACT_VERTEX] * 3 and found.blocked and occluded(scene, *pierce)


def test_sliding_along_a_face():
    scene = make_scene(*box((0, 0, 0), (1, 1, 1)))
    along_top = ([-1, 0.5, 1], [2, 0.5, 1])
    found = contacts(scene, *along_top)
    kinds = dict(zip(found.polygon.tolist(), found.kind.tolist(), strict=True))
    assert kinds[1] == CONTACT_SLIDING  # the top face
    assert sorted(k for p, k in kinds.items() if p != 1) == [CONTACT_EDGE, CONTACT_EDGE]  # the two sides
    assert not occluded(scene, *along_top)
    top = found.t[found.polygon == 1][0]
    assert top == pytest.approx(1 / 3, abs=1e-15)


def test_shared_edge_of_coplanar_quads_is_flat_and_blocks():
    scene = box_on_split_floor()
    through = ([1.5, 2.5, 1], [1.5, 2.7, -1])
    found = contacts(scene, *through)
    assert found.kind.tolist() == [CONTACT_EDGE, CONTACT_EDGE]
    assert sorted(found.polygon.tolist()) == [0, 1] and not found.silhouette.any()
    assert occluded(scene, *through)
    vertex = ([1.5, 3, 1], [1.5, 3, -1])  # the floor's boundary vertex (1.5, 3, 0): half the directions open
    found = contacts(scene, *vertex)
    assert found.kind.tolist() == [CONTACT_VERTEX] * 2 and found.silhouette.all()
    assert not occluded(scene, *vertex)


def test_endpoints_on_surfaces_do_not_count():
    scene = box_on_split_floor()
    on_floor, on_wall, on_top, on_side = [0.5, 1.5, 0.0], [1.0, 1.5, 0.5], [1.5, 1.5, 1.0], [2.0, 1.5, 0.5]
    assert not occluded(scene, on_floor, on_wall)
    assert not occluded(scene, on_top, [0.5, 0.5, 2.0])
    assert not occluded(scene, on_side, [2.9, 2.9, 0.0])
    assert not occluded(scene, on_floor, [2.5, 1.5, 0.0])  # sliding on the floor, under the lifted box
    assert occluded(scene, on_floor, on_top)  # enters the box through its wall
    assert occluded(scene, [0.5, 1.5, 0.5], [2.5, 1.5, 0.5])
    assert not contacts(scene, on_floor, on_wall).polygon.size
    polygon, t, kind = first_hits(scene, build_bvh(scene), np.array([on_top]), np.array([[0.0, 0.0, 1.0]]))
    assert polygon[0] == -1 and kind[0] == CONTACT_NONE


@pytest.mark.parametrize("scale", [1e-3, 1e4])
def test_scale_invariance(scale):
    rng = np.random.default_rng(14)
    base = box_on_split_floor()
    scaled = make_scene(base.vertices * scale + 7.0 * scale, [base.polygon_vertices(i) for i in range(base.n_polygons)])
    # segments between random lattice points of the scene: full of grazing and sliding contacts
    lattice = np.array(
        [[x, y, z] for x in np.arange(0, 3.01, 0.5) for y in np.arange(0, 3.01, 0.5) for z in (0, 0.5, 1)]
    )
    pick = rng.integers(0, len(lattice), size=(1500, 2))
    starts, ends = lattice[pick[:, 0]], lattice[pick[:, 1]]
    keep = np.any(starts != ends, axis=1)
    starts, ends = starts[keep], ends[keep]
    ref = batch_segment_contacts(base, build_bvh(base), starts, ends)
    got = batch_segment_contacts(scaled, build_bvh(scaled), starts * scale + 7.0 * scale, ends * scale + 7.0 * scale)
    for name in ("offsets", "polygon", "kind", "feature", "silhouette", "blocked"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    np.testing.assert_allclose(got.t, ref.t, atol=1e-9)
    assert {CONTACT_INTERIOR, CONTACT_EDGE, CONTACT_VERTEX, CONTACT_SLIDING} <= set(ref.kind.tolist())
    directions = ends - starts
    hits = first_hits(base, build_bvh(base), starts, directions)
    hits_scaled = first_hits(scaled, build_bvh(scaled), starts * scale + 7.0 * scale, directions * scale)
    np.testing.assert_array_equal(hits[0], hits_scaled[0])
    np.testing.assert_array_equal(hits[2], hits_scaled[2])
    np.testing.assert_allclose(hits[1], hits_scaled[1], rtol=1e-9)


# ---------------------------------------------------------------------------------------------------------
# jittered form factors


def parallel_source_scene(with_occluder=False):
    """Source [-1,1]^2 at height 2 (polygon 0), floor (polygon 1), optional occluder x <= 0.25 at height 1."""
    vertices = [[-1, -1, 2], [1, -1, 2], [1, 1, 2], [-1, 1, 2], [-4, -4, 0], [4, -4, 0], [4, 4, 0], [-4, 4, 0]]
    polygons = [[0, 3, 2, 1], [4, 5, 6, 7]]
    if with_occluder:
        vertices += [[-4, -4, 1], [0.25, -4, 1], [0.25, 4, 1], [-4, 4, 1]]
        polygons.append([8, 9, 10, 11])
    return make_scene(vertices, polygons)


def test_jittered_form_factors_converge_to_the_closed_form():
    scene = parallel_source_scene()
    bvh = build_bvh(scene)
    rng = np.random.default_rng(15)
    points = np.column_stack([rng.uniform(-2, 2, 150), rng.uniform(-2, 2, 150), np.zeros(150)])
    normals = np.tile([0.0, 0.0, 1.0], (150, 1))
    exact = np.array([parallel_rectangle_ff(p[:2], 2.0, -1, 1, -1, 1) for p in points])
    errors = []
    counts = [4, 16, 64, 256]
    for rays in counts:
        runs = [jittered_form_factors(scene, bvh, points, normals, 0, rays, seed=s) for s in range(4)]
        errors.append(np.mean([np.abs(r - exact) / exact for r in runs]))
    slope = np.polyfit(np.log(counts), np.log(errors), 1)[0]
    # stratified sampling of a smooth integrand in 2-D: about n^-1 (plain Monte-Carlo would give n^-0.5)
    assert slope < -0.8, (slope, errors)
    assert errors[-1] < 0.005
    centre = jittered_form_factors(scene, bvh, np.zeros((1, 3)), np.array([[0, 0, 1.0]]), 0, 4096)
    assert centre[0] == pytest.approx(parallel_rectangle_ff((0, 0), 2.0, -1, 1, -1, 1), rel=1e-3)


def test_jittered_form_factors_with_a_half_occluder():
    scene = parallel_source_scene(with_occluder=True)
    bvh = build_bvh(scene)
    xs = np.array([-0.5, 0.0, 0.25, 0.5, 1.0])
    points = np.column_stack([xs, np.full(5, 0.3), np.zeros(5)])
    normals = np.tile([0.0, 0.0, 1.0], (5, 1))
    # the occluder's edge x = 0.25 at height 1, seen from (x, y, 0), hides source points with x_s < 0.5 - x
    expected = np.array([parallel_rectangle_ff((x, 0.3), 2.0, max(-1.0, 0.5 - x), 1, -1, 1) for x in xs])
    runs = [jittered_form_factors(scene, bvh, points, normals, 0, 256, seed=s) for s in range(8)]
    mean = np.mean(runs, axis=0)
    np.testing.assert_allclose(mean, expected, rtol=0.01)
    unoccluded = np.array([parallel_rectangle_ff((x, 0.3), 2.0, -1, 1, -1, 1) for x in xs])
    assert np.all(mean < 0.9 * unoccluded)


def test_jittered_form_factors_determinism_and_edge_cases():
    scene = parallel_source_scene()
    bvh = build_bvh(scene)
    points = np.array([[0.2, 0.1, 0.0], [0.0, 0.0, 3.0], [0.3, 0.3, 2.0], [5.0, 0.0, 2.0]])
    normals = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, -1.0], [0, 0, 1.0]])
    a = jittered_form_factors(scene, bvh, points, normals, 0, 36, seed=3)
    b = jittered_form_factors(scene, bvh, points, normals, 0, 36, seed=3)
    c = jittered_form_factors(scene, bvh, points, normals, 0, 36, seed=4)
    np.testing.assert_array_equal(a, b)
    assert a[0] != c[0]
    # above the source facing away, on the source, in its plane: zero, never NaN
    assert a[1] == 0.0 and a[2] == 0.0 and a[3] == 0.0 and np.isfinite(a).all()
    for rays in (1, 2, 3, 5, 7, 10):
        value = jittered_form_factors(scene, bvh, points[:1], normals[:1], 0, rays)
        assert np.isfinite(value).all() and value[0] > 0.0


def test_stratification_is_uniform_in_area_over_a_convex_polygon():
    # a skewed pentagon source, a receiver far away: the kernel is nearly constant, so the estimate is exact
    # up to the kernel's variation over each stratum; any area bias would show at the percent level
    vertices = [[0, 0, 0], [3, 0, 0], [3.5, 1, 0], [1, 2.5, 0], [-0.5, 1, 0]]
    scene = make_scene(vertices, [[0, 1, 2, 3, 4]])
    bvh = build_bvh(scene)
    point = np.array([[1.2, 1.0, -1000.0]])
    normal = np.array([[0.0, 0.0, 1.0]])
    value = jittered_form_factors(scene, bvh, point, normal, 0, 7)
    assert value[0] == pytest.approx(scene.areas[0] / (np.pi * 1000.0**2), rel=1e-4)


# ---------------------------------------------------------------------------------------------------------
# validation


def test_bad_arguments_are_rejected_and_inputs_untouched():
    scene = parallel_source_scene()
    bvh = build_bvh(scene)
    starts = np.zeros((2, 3))
    ends = np.ones((2, 3))
    before = starts.copy()
    segments_occluded(scene, bvh, starts, ends)
    np.testing.assert_array_equal(starts, before)
    with pytest.raises(ValueError, match="starts"):
        segments_occluded(scene, bvh, np.zeros((2, 2)), ends)
    with pytest.raises(ValueError, match="ends"):
        segments_occluded(scene, bvh, starts, np.full((2, 3), np.nan))
    with pytest.raises(ValueError, match="same length"):
        segments_occluded(scene, bvh, starts, np.ones((3, 3)))
    with pytest.raises(ValueError, match="exclude"):
        segments_occluded(scene, bvh, starts, ends, exclude=np.zeros((2, 3), dtype=int))
    with pytest.raises(ValueError, match="exclude"):
        segments_occluded(scene, bvh, starts, ends, exclude=np.full((2, 2), 99))
    with pytest.raises(ValueError, match="directions"):
        first_hits(scene, bvh, starts, np.zeros((2, 3)))
    with pytest.raises(ValueError, match="t_max"):
        first_hits(scene, bvh, starts, ends, t_max=-1.0)
    with pytest.raises(ValueError, match="start"):
        segment_contacts(scene, bvh, [0, 0], [1, 1, 1])
    normals = np.tile([0, 0, 1.0], (2, 1))
    with pytest.raises(ValueError, match="rays"):
        jittered_form_factors(scene, bvh, starts, normals, 0, 0)
    with pytest.raises(ValueError, match="source"):
        jittered_form_factors(scene, bvh, starts, normals, 5, 4)
    with pytest.raises(ValueError, match="normals"):
        jittered_form_factors(scene, bvh, starts, np.zeros((2, 3)), 0, 4)
    with pytest.raises(ValueError, match="seed"):
        jittered_form_factors(scene, bvh, starts, normals, 0, 4, seed=1.5)
