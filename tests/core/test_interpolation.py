"""core.pipeline.interpolation.locate against the naive search of tests/core/naive_interpolation.py: the grid
of each polygon's triangles must find what testing every triangle finds."""

import numpy as np
import pytest

from core.pipeline.interpolation import locate

from .naive_interpolation import coordinates, naive_locate


def _tilted_grid(rng, origin, u, w, cells, jitter=0.2, notch=False):
    """A cells x cells grid of a parallelogram (origin, u, w), each square cut into two triangles along a
    random diagonal, its inner vertices moved by up to `jitter` cells; with `notch`, without the squares of
    its last quarter (an L-shaped polygon)."""
    s, t = np.meshgrid(np.linspace(0.0, 1.0, cells + 1), np.linspace(0.0, 1.0, cells + 1), indexing="ij")
    inner = (s > 0) & (s < 1) & (t > 0) & (t < 1)
    s = s + inner * rng.uniform(-jitter, jitter, s.shape) / cells
    t = t + inner * rng.uniform(-jitter, jitter, t.shape) / cells
    vertices = origin + s.reshape(-1, 1) * u + t.reshape(-1, 1) * w
    triangles = []
    for i in range(cells):
        for j in range(cells):
            if notch and 2 * i >= cells and 2 * j >= cells:
                continue
            a, b, c, d = (
                i * (cells + 1) + j,
                (i + 1) * (cells + 1) + j,
                (i + 1) * (cells + 1) + j + 1,
                i * (cells + 1) + j + 1,
            )
            triangles += [[a, b, c], [a, c, d]] if rng.random() < 0.5 else [[a, b, d], [b, c, d]]
    return vertices, np.array(triangles)


def _scene(seed):
    rng = np.random.default_rng(seed)
    parts = [
        _tilted_grid(rng, np.array([0.0, 0.0, 0.0]), np.array([2.0, 0.0, 0.0]), np.array([0.0, 3.0, 0.0]), 12),
        _tilted_grid(rng, np.array([1.0, -2.0, 0.5]), np.array([0.3, 0.4, 2.0]), np.array([-1.0, 0.6, 0.0]), 7),
        _tilted_grid(rng, np.array([5.0, 5.0, 5.0]), np.array([1e-4, 0.0, 0.0]), np.array([0.0, 0.0, 2e-4]), 2),
        _tilted_grid(
            rng, np.array([0.0, 0.0, 1.0]), np.array([4.0, 0.0, 0.0]), np.array([0.0, 4.0, 0.0]), 8, 0.0, True
        ),
    ]
    vertices, triangles, triangle_polygon = [], [], []
    first = 0
    for key, (v, t) in enumerate(parts):
        vertices.append(v)
        triangles.append(t + first)
        triangle_polygon.append(np.full(len(t), 10 * key + 3))
        first += len(v)
    vertices, triangles, triangle_polygon = (
        np.concatenate(vertices),
        np.concatenate(triangles),
        np.concatenate(triangle_polygon),
    )
    # a triangle without area on the first polygon (three points on a line)
    vertices = np.concatenate([vertices, [[0.1, 0.1, 0.0], [0.5, 0.5, 0.0], [0.9, 0.9, 0.0]]])
    triangles = np.concatenate([triangles, [[len(vertices) - 3, len(vertices) - 2, len(vertices) - 1]]])
    triangle_polygon = np.append(triangle_polygon, 3)
    return rng, vertices, triangles, triangle_polygon


#: the L-shaped polygon of _scene, its notch the square [2, 4]^2 of the plane z = 1: points there are inside
#: its triangles' bounding box, on none of them
NOTCH_POLYGON = 33


def _points(rng, vertices, triangles, triangle_polygon):
    """Points inside triangles, on their edges (shared ones included), at their corners, a rounding error
    outside, well outside their polygon, and in the notch of the L-shaped one."""
    real = np.flatnonzero(
        np.linalg.norm(np.cross(*(vertices[triangles[:, k]] - vertices[triangles[:, 0]] for k in (1, 2))), axis=1) > 0
    )
    chosen = rng.choice(real, 300)
    corners = vertices[triangles[chosen]]
    inside = np.einsum("qk,qkc->qc", rng.dirichlet([1.0, 1.0, 1.0], len(chosen)), corners)
    on_edge = 0.5 * (corners[:, 0] + corners[:, 1])
    at_corner = corners[:, 2]
    centre = corners.mean(axis=1)
    outside_by_rounding = on_edge + 1e-13 * (on_edge - centre)
    far_outside = centre + 3.0 * (on_edge - centre) * rng.uniform(5.0, 50.0, (len(chosen), 1))
    notch = np.column_stack([rng.uniform(2.0, 4.0, (200, 2)), np.ones(200)])
    points = np.concatenate([inside, on_edge, at_corner, outside_by_rounding, far_outside, notch])
    return points, np.append(np.tile(triangle_polygon[chosen], 5), np.full(len(notch), NOTCH_POLYGON))


def _depth(vertices, triangles, triangle, point):
    return min(coordinates(*vertices[triangles[triangle]], point))


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_locate_finds_what_testing_every_triangle_finds(seed):
    rng, vertices, triangles, triangle_polygon = _scene(seed)
    points, polygons = _points(rng, vertices, triangles, triangle_polygon)
    best, other, weights = locate(vertices, triangles, triangle_polygon, points, polygons)
    n_best, n_other, n_weights, depth, second_depth = naive_locate(
        vertices, triangles, triangle_polygon, points, polygons
    )
    # the same triangle where the deepest is clear; among (near) equals, one just as deep
    clear = depth - second_depth > 1e-12
    assert clear.sum() > len(points) // 3
    np.testing.assert_array_equal(best[clear], n_best[clear])
    np.testing.assert_array_equal(other[clear], n_other[clear])
    same = best == n_best
    np.testing.assert_allclose(weights[same], n_weights[same], atol=1e-9)
    # where several are as deep (a shared edge or corner, a point far off), one of them, and a second holder
    # where the naive search has one
    tied = np.flatnonzero(~clear)
    assert len(tied) > 100
    for q in tied:
        assert _depth(vertices, triangles, best[q], points[q]) >= depth[q] - 1e-12
        assert (other[q] >= 0) == (n_other[q] >= 0)
        if other[q] >= 0:
            assert other[q] != best[q]
            assert _depth(vertices, triangles, other[q], points[q]) >= -1e-9
    # every weight triple interpolates the point it belongs to wherever the point is on its triangle
    on = depth >= -1e-9
    located = np.einsum("qk,qkc->qc", weights, vertices[triangles[best]])
    np.testing.assert_allclose(located[on], points[on], atol=1e-9)
    np.testing.assert_allclose(weights.sum(axis=1), 1.0)
    assert (weights >= 0.0).all()
    assert (
        best[:, None]
        != np.flatnonzero(
            np.linalg.norm(np.cross(*(vertices[triangles[:, k]] - vertices[triangles[:, 0]] for k in (1, 2))), axis=1)
            == 0
        )[None]
    ).all()


def test_locate_names_a_polygon_without_triangles_or_without_area():
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [2.0, 0.0, 0.0]])
    triangles = np.array([[0, 1, 2], [0, 1, 3]])
    with pytest.raises(ValueError, match="polygon 7 has no triangle to locate"):
        locate(vertices, triangles, np.array([4, 5]), np.zeros((1, 3)), np.array([7]))
    with pytest.raises(ValueError, match="polygon 5 has no triangle with an area"):
        locate(vertices, triangles, np.array([4, 5]), np.zeros((2, 3)), np.array([4, 5]))


def test_locate_leaves_its_arguments_alone():
    rng, vertices, triangles, triangle_polygon = _scene(4)
    points, polygons = _points(rng, vertices, triangles, triangle_polygon)
    copies = [a.copy() for a in (vertices, triangles, triangle_polygon, points, polygons)]
    locate(vertices, triangles, triangle_polygon, points, polygons)
    for before, after in zip(copies, (vertices, triangles, triangle_polygon, points, polygons), strict=True):
        np.testing.assert_array_equal(before, after)
