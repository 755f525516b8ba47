import numpy as np
import pytest

from core.errors import SceneError
from core.scene import (
    EDGE_BOUNDARY,
    EDGE_CREASE,
    EDGE_FLAT,
    VERTEX_FLAT,
    VERTEX_SILHOUETTE,
    VERTEX_UNUSED,
    Scene,
)
from tests.core.furnished_rooms import box_quads


def grey(count):
    return np.full((count, 3), 0.5)


def build(vertices, polygons, **kwargs):
    count = len(polygons)
    return Scene.from_polygons(vertices, polygons, grey(count), np.zeros((count, 3)), **kwargs)


def test_convex_planar_polygon_kept_with_geometry():
    vertices = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [0, 1, 0.0]])
    scene = build(vertices, [[0, 1, 2, 3]])
    assert scene.n_polygons == 1
    np.testing.assert_allclose(scene.normals[0], [0, 0, 1])
    assert scene.areas[0] == pytest.approx(2.0)
    np.testing.assert_allclose(scene.centroids[0], [1.0, 0.5, 0.0])
    assert scene.plane_offsets[0] == pytest.approx(0.0)
    np.testing.assert_array_equal(scene.polygon_min[0], [0, 0, 0])
    np.testing.assert_array_equal(scene.polygon_max[0], [2, 1, 0])
    assert np.all(scene.edge_kind == EDGE_BOUNDARY)
    assert scene.two_sided[0]  # an open plane is seen from both sides
    assert scene.diagonal == pytest.approx(np.sqrt(5.0))


def test_non_convex_polygon_split_not_dropped():
    l_shape = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 1, 0], [1, 2, 0], [0, 2, 0.0]])
    scene = build(l_shape, [[0, 1, 2, 3, 4, 5]])
    assert scene.n_polygons >= 2
    assert scene.areas.sum() == pytest.approx(3.0, rel=1e-14)
    assert np.all(scene.source_polygon == 0)
    np.testing.assert_allclose(scene.normals, np.tile([0, 0, 1.0], (scene.n_polygons, 1)))
    # the split's inner edges are flat (no visual event), the outline stays a boundary
    outline = {tuple(sorted(e)) for e in zip(range(6), [1, 2, 3, 4, 5, 0], strict=True)}
    for edge, kind in zip(scene.edges, scene.edge_kind, strict=True):
        assert kind == (EDGE_BOUNDARY if tuple(edge) in outline else EDGE_FLAT)
    for i in range(scene.n_polygons):
        poly = scene.polygon(i)
        turns = np.cross(np.roll(poly, -1, 0) - poly, np.roll(poly, -2, 0) - np.roll(poly, -1, 0)) @ [0, 0, 1]
        assert np.all(turns >= -1e-12)


def test_non_planar_quad_split_into_triangles():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0.3], [0, 1, 0.0]])
    scene = build(vertices, [[0, 1, 2, 3]])
    assert scene.n_polygons == 2
    for i in range(2):
        poly = scene.polygon(i)
        assert np.abs((poly - scene.centroids[i]) @ scene.normals[i]).max() < 1e-12
    inner = scene.edge_kind[[k for k, e in enumerate(scene.edges) if {int(e[0]), int(e[1])} in ({0, 2}, {1, 3})]]
    assert list(inner) == [EDGE_CREASE]


def test_closed_box_edges_vertices_and_sides():
    corners, quads = box_quads(np.zeros(3), np.ones(3))
    extra = np.vstack([corners, [[5.0, 5.0, 5.0]]])  # an unused vertex
    scene = build(extra, quads)
    assert np.all(scene.edge_kind == EDGE_CREASE)
    assert len(scene.edges) == 12
    assert np.all(np.diff(scene.edge_face_offsets) == 2)
    assert not scene.two_sided.any()  # a closed object's inside never exchanges light
    assert np.all(scene.vertex_kind[:8] == VERTEX_SILHOUETTE)
    assert scene.vertex_kind[8] == VERTEX_UNUSED
    np.testing.assert_allclose(scene.areas, 1.0)
    centre_side = np.einsum("ij,ij->i", scene.normals, scene.centroids - 0.5)
    assert np.all(centre_side > 0)  # outward normals


@pytest.mark.parametrize("offset", [0.0, 1e4])
def test_solid_objects_are_closed_with_outward_normals(offset):
    corners, quads = box_quads(np.full(3, offset), np.full(3, offset + 1.0))
    outward = build(corners, quads)
    assert outward.solid.all()
    inward = build(corners, [q[::-1] for q in quads])
    assert not inward.solid.any()  # normals pointing in: its faces turned away from a viewer are the ones it sees
    open_box = build(corners, quads[1:])
    assert not open_box.solid.any()
    # two faces back to back close every edge but enclose nothing
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]) + offset
    flat = build(square, [[0, 1, 2, 3], [3, 2, 1, 0]])
    assert not flat.solid.any()
    mixed = build(np.vstack([corners, square]), quads + [[8, 9, 10, 11]])
    np.testing.assert_array_equal(mixed.solid, [True] * 6 + [False])


def test_flat_vertex_inside_coplanar_grid():
    vertices = np.array([[x, y, 0.0] for y in range(3) for x in range(3)])
    quads = [[0, 1, 4, 3], [1, 2, 5, 4], [3, 4, 7, 6], [4, 5, 8, 7]]
    scene = build(vertices, quads)
    assert scene.vertex_kind[4] == VERTEX_FLAT
    assert np.all(np.delete(scene.vertex_kind, 4) == VERTEX_SILHOUETTE)
    assert len(np.unique(scene.object_ids)) == 1


def test_object_ids_default_to_connected_components_and_can_be_given():
    a, qa = box_quads(np.zeros(3), np.ones(3))
    b, qb = box_quads(np.array([2.0, 0, 0]), np.array([3.0, 1, 1]))
    scene = build(np.vstack([a, b]), qa + [[i + 8 for i in q] for q in qb])
    assert len(np.unique(scene.object_ids[:6])) == 1
    assert scene.object_ids[0] != scene.object_ids[6]
    given = build(np.vstack([a, b]), qa + [[i + 8 for i in q] for q in qb], object_ids=[7] * 12,
                  two_sided=[True] * 12)
    assert np.all(given.object_ids == 7)
    assert given.two_sided.all()


def test_caller_arrays_untouched_and_scene_read_only():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])
    polygons = [[0, 1, 2, 3]]
    rho = np.array([[0.2, 0.3, 0.4]])
    emission = np.array([[1.0, 2.0, 3.0]])
    copies = [vertices.copy(), rho.copy(), emission.copy()]
    scene = Scene.from_polygons(vertices, polygons, rho, emission)
    for original, copy in zip([vertices, rho, emission], copies, strict=True):
        np.testing.assert_array_equal(original, copy)
    assert polygons == [[0, 1, 2, 3]]
    with pytest.raises(ValueError):
        scene.vertices[0, 0] = 9.0
    vertices[0, 0] = 9.0
    assert scene.vertices[0, 0] == 0.0
    np.testing.assert_array_equal(scene.lights, [0])


SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]])


@pytest.mark.parametrize(
    "vertices, polygons, rho, emission, message",
    [
        (np.vstack([SQUARE, [[np.nan, 0, 0]]]), [[0, 1, 2, 3]], grey(1), np.zeros((1, 3)), "vertex 4"),
        (np.vstack([SQUARE, [[np.inf, 0, 0]]]), [[0, 1, 2, 3]], grey(1), np.zeros((1, 3)), "vertex 4"),
        (SQUARE, [[0, 1, 2], [0, 2, 7]], grey(2), np.zeros((2, 3)), "polygon 1 uses vertex index 7"),
        (SQUARE, [[0, 1, 2], [0, -1, 2]], grey(2), np.zeros((2, 3)), "polygon 1 uses vertex index -1"),
        (SQUARE, [[0, 1, 2], [2, 3]], grey(2), np.zeros((2, 3)), "polygon 1 has 2 vertices"),
        (np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]]), [[0, 1, 2]], grey(1), np.zeros((1, 3)),
         "polygon 0 has zero area"),
        (np.array([[0, 0, 0], [0, 0, 0], [0, 0, 0.0]]), [[0, 1, 2]], grey(1), np.zeros((1, 3)),
         "polygon 0 has zero area"),
        (SQUARE, [[0, 1, 2, 3]], [[0.5, 1.0, 0.5]], np.zeros((1, 3)), "reflectance of polygon 0"),
        (SQUARE, [[0, 1, 2, 3]], [[0.5, -0.1, 0.5]], np.zeros((1, 3)), "reflectance of polygon 0"),
        (SQUARE, [[0, 1, 2, 3]], grey(1), [[0, -1.0, 0]], "emission of polygon 0"),
        (SQUARE, [[0, 1, 2, 3]], grey(1), [[0, np.nan, 0]], "emission of polygon 0 is not finite"),
        (SQUARE, [[0, 1, 2, 3]], grey(2), np.zeros((1, 3)), r"reflectance must have shape \(1, 3\)"),
        (SQUARE, [[0, 1, 2, 3]], grey(1), np.zeros((3,)), r"emission must have shape \(1, 3\)"),
        (SQUARE, [[0, 1, 2, 3]], grey(1), np.zeros((1, 3)), None),
        (np.array([[0, 0, 0], [2, 0, 0], [0, 1, 0], [1, 1, 0.0]]), [[0, 1, 2, 3]], grey(1), np.zeros((1, 3)),
         "polygon 0 is self-intersecting"),
        (SQUARE, [[0, 1, 3, 2]], grey(1), np.zeros((1, 3)), "polygon 0 has zero area"),
        (SQUARE, [[0, 1, 2, 1]], grey(1), np.zeros((1, 3)), "polygon 0 repeats a vertex index"),
        (SQUARE[:, :2], [[0, 1, 2, 3]], grey(1), np.zeros((1, 3)), r"vertices must have shape \(V, 3\)"),
        (SQUARE, [], np.zeros((0, 3)), np.zeros((0, 3)), "no polygons"),
    ],
)
def test_bad_input_names_the_culprit(vertices, polygons, rho, emission, message):
    if message is None:
        Scene.from_polygons(vertices, polygons, rho, emission)
        return
    with pytest.raises(SceneError, match=message):
        Scene.from_polygons(vertices, polygons, rho, emission)


def test_mismatched_per_polygon_arrays():
    with pytest.raises(SceneError, match="object_ids"):
        build(SQUARE, [[0, 1, 2, 3]], object_ids=[1, 2])
    with pytest.raises(SceneError, match="two_sided"):
        build(SQUARE, [[0, 1, 2, 3]], two_sided=[True, False])


def test_tolerance_scales_with_scene():
    corners, quads = box_quads(np.zeros(3), np.ones(3))
    for scale in (1e-3, 1.0, 1e4):
        scene = build(corners * scale, quads)
        assert scene.tol.length == pytest.approx(1e-9 * np.sqrt(3.0) * scale)
        assert np.all(scene.edge_kind == EDGE_CREASE)
