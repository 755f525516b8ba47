import numpy as np
import pytest

from core.errors import SceneError
from core.formfactor import disk_ff_estimate, point_polygon_ff


def parallel_corner_ff(a, b, c):
    """Textbook: differential area below one corner of a parallel a x b rectangle at distance c."""
    x, y = a / c, b / c
    sx, sy = np.sqrt(1 + x * x), np.sqrt(1 + y * y)
    return (x / sx * np.arctan(y / sx) + y / sy * np.arctan(x / sy)) / (2 * np.pi)


def rectangle(x0, x1, y0, y1, z):
    return np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], dtype=float)


@pytest.mark.parametrize("a, b, c", [(1.0, 2.0, 0.7), (0.1, 0.1, 10.0), (5.0, 3.0, 0.01), (1e-3, 2e-3, 4e-4)])
def test_parallel_rectangle_closed_form(a, b, c):
    f = point_polygon_ff([[0, 0, 0]], [[0, 0, 1]], rectangle(0, a, 0, b, c))
    assert f[0] == pytest.approx(parallel_corner_ff(a, b, c), rel=1e-12)
    # a point below the middle is the sum of four corner configurations
    centre = point_polygon_ff([[a / 2, b / 2, 0]], [[0, 0, 1]], rectangle(0, a, 0, b, c))
    assert centre[0] == pytest.approx(4 * parallel_corner_ff(a / 2, b / 2, c), rel=1e-12)


def test_disk_on_axis():
    radius, height = 0.8, 1.3
    angles = np.linspace(0, 2 * np.pi, 20001)[:-1]
    disk = np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(len(angles), height)])
    f = point_polygon_ff([[0, 0, 0]], [[0, 0, 1]], disk)[0]
    assert f == pytest.approx(radius**2 / (radius**2 + height**2), rel=1e-7)


def test_orientation_and_hemisphere_clipping():
    square = rectangle(-1, 1, -1, 1, 1)
    up = point_polygon_ff([[0, 0, 0]], [[0, 0, 1]], square)[0]
    assert point_polygon_ff([[0, 0, 0]], [[0, 0, 1]], square[::-1])[0] == pytest.approx(up, rel=1e-15)
    assert point_polygon_ff([[0, 0, 0]], [[0, 0, -1]], square)[0] == 0.0
    # a receiver facing sideways sees half of the square, by symmetry half of its projected solid angle
    side = point_polygon_ff([[0, 0, 0]], [[1, 0, 0]], square)[0]
    half = point_polygon_ff([[0, 0, 0]], [[1, 0, 0]], rectangle(0, 1, -1, 1, 1))[0]
    assert side == pytest.approx(half, rel=1e-14)
    assert 0 < side < up


def gauss_points(polygon, order):
    """Gauss-Legendre points and weights over a planar parallelogram given as 4 corners."""
    nodes, weights = np.polynomial.legendre.leggauss(order)
    s = (nodes + 1) / 2
    u, v = np.meshgrid(s, s, indexing="ij")
    w = np.outer(weights, weights).ravel() / 4
    origin, e1, e2 = polygon[0], polygon[1] - polygon[0], polygon[3] - polygon[0]
    points = origin + u.ravel()[:, None] * e1 + v.ravel()[:, None] * e2
    area = np.linalg.norm(np.cross(e1, e2))
    return points, w * area, np.cross(e1, e2) / area


@pytest.mark.parametrize("perpendicular", [False, True])
def test_reciprocity(perpendicular):
    first = rectangle(0, 1, 0, 1.5, 0)
    if perpendicular:
        second = np.array([[0.3, 2.0, 0.2], [1.3, 2.0, 0.2], [1.3, 2.0, 1.4], [0.3, 2.0, 1.4]])
    else:
        second = rectangle(0.5, 1.7, 0.2, 1.0, 1.1)[::-1]
    p1, w1, n1 = gauss_points(first, 40)
    p2, w2, n2 = gauss_points(second, 40)
    # each receiver faces the other polygon
    n1 = n1 if n1 @ (second.mean(0) - first.mean(0)) > 0 else -n1
    n2 = n2 if n2 @ (first.mean(0) - second.mean(0)) > 0 else -n2
    a1f12 = np.sum(w1 * point_polygon_ff(p1, np.tile(n1, (len(p1), 1)), second))
    a2f21 = np.sum(w2 * point_polygon_ff(p2, np.tile(n2, (len(p2), 1)), first))
    assert a1f12 > 0.01
    assert a1f12 == pytest.approx(a2f21, rel=1e-8)


def test_disk_estimate_matches_far_field_and_is_bounded():
    square = rectangle(-0.05, 0.05, -0.05, 0.05, 0)
    far = np.array([[0.3, 0.2, -20.0]])
    exact = point_polygon_ff(far, [[0, 0, 1]], square)[0]
    estimate = disk_ff_estimate(far, [[0, 0, 1]], [0, 0, 0], [0, 0, 1], 0.01)[0]
    assert estimate == pytest.approx(exact, rel=1e-3)
    near = disk_ff_estimate([[0, 0, -1e-9]], [[0, 0, 1]], [0, 0, 0], [0, 0, 1], 0.01)[0]
    assert 0.0 < near <= 1.0
    assert disk_ff_estimate([[0, 0, -1]], [[0, 0, -1]], [0, 0, 0], [0, 0, 1], 0.01)[0] == 0.0


def test_bad_input():
    with pytest.raises(SceneError, match="points"):
        point_polygon_ff([[0, 0]], [[0, 0, 1]], rectangle(0, 1, 0, 1, 1))
    with pytest.raises(SceneError, match="NaN"):
        point_polygon_ff([[0, np.nan, 0]], [[0, 0, 1]], rectangle(0, 1, 0, 1, 1))
    with pytest.raises(SceneError, match="normal 0 is zero"):
        point_polygon_ff([[0, 0, 0]], [[0, 0, 0]], rectangle(0, 1, 0, 1, 1))
    with pytest.raises(SceneError, match="at least 3"):
        point_polygon_ff([[0, 0, 0]], [[0, 0, 1]], rectangle(0, 1, 0, 1, 1)[:2])
