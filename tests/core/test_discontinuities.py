"""Discontinuity meshing (core/pipeline/discontinuities.py and the solver's use of it): the events inserted
into a receiver lie on the analytic visual events and the leaves follow them; the geometric helpers agree
with naive references."""

import numpy as np

from core.pipeline import Settings, Solver
from core.pipeline.discontinuities import clip_to_convex, crossing
from tests.core.naive_skeleton import analytic_event_segments, face_plane_traces, uncovered
from tests.core.skeleton_scenes import box_over_floor_scene


def test_inserted_discontinuities_lie_on_the_analytic_events_and_the_mesh_follows_them():
    setup = box_over_floor_scene()
    scene = setup.scene
    result = Solver(scene, Settings(max_iterations=4, jnd=0.01)).solve()
    inserted = result.discontinuities.get(setup.floor, np.empty((0, 2, 3)))
    stats = result.stats
    print(f"\ninserted {stats['discontinuities_inserted']} of {stats['discontinuities_available']} events")
    assert len(inserted) >= 8
    assert stats["discontinuities_inserted"] == sum(len(v) for v in result.discontinuities.values())
    assert set(result.discontinuities) == {setup.floor}
    tol = 1e-7 * scene.diagonal
    geometry = setup.event_geometry()
    events = np.concatenate([analytic_event_segments(*geometry), face_plane_traces(*geometry)])
    assert len(uncovered(inserted, events, tol)) == 0
    on_floor = result.triangles[(result.triangle_polygon == setup.floor) & (result.triangle_side == 0)]
    corners = result.vertices[on_floor]
    edges = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 3)
    assert len(uncovered(inserted, edges, tol)) == 0
    # leaves the triangulation's rounding left without area are not output: front triangles face the polygon's
    # normal, back triangles away (the add-on tells the sides apart that way)
    corners = result.vertices[result.triangles]
    facing = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    along = np.einsum("ij,ij->i", facing, scene.normals[result.triangle_polygon])
    assert np.all(np.where(result.triangle_side == 0, along, -along) > 0.0)


def test_without_discontinuities_nothing_is_built_or_inserted():
    setup = box_over_floor_scene()
    solver = Solver(setup.scene, Settings(max_iterations=4, jnd=0.01, discontinuities=False))
    result = solver.solve()
    assert solver.skeleton is None
    assert result.discontinuities == {}
    assert result.stats["discontinuities_inserted"] == 0
    assert Settings.preset("fast").discontinuities is False
    assert Settings.preset("accurate").discontinuities is True


def _inside_convex(points, polygon, normal, tol):
    inside = np.ones(len(points), bool)
    centre = polygon.mean(axis=0)
    for k in range(len(polygon)):
        a, b = polygon[k], polygon[(k + 1) % len(polygon)]
        inward = np.cross(normal, b - a)
        inward *= np.sign(inward @ (centre - a))
        inside &= (points - a) @ inward / np.linalg.norm(inward) >= -tol
    return inside


def test_clip_to_convex_keeps_exactly_the_inside_part():
    rng = np.random.default_rng(2)
    angles = np.sort(rng.uniform(0, 2 * np.pi, 7))
    u, v = np.array([1.0, 0.2, 0.1]), np.array([-0.2, 1.0, 0.3])
    u /= np.linalg.norm(u)
    v -= (v @ u) * u
    v /= np.linalg.norm(v)
    normal = np.cross(u, v)
    polygon = np.cos(angles)[:, None] * u + np.sin(angles)[:, None] * v + [3.0, -1.0, 2.0]
    t = np.linspace(0.0, 1.0, 2001)
    for _ in range(200):
        ends = [3.0, -1.0, 2.0] + rng.uniform(-1.6, 1.6, (2, 1)) * u + rng.uniform(-1.6, 1.6, (2, 1)) * v
        samples = ends[0] + t[:, None] * (ends[1] - ends[0])
        inside = _inside_convex(samples, polygon, normal, 1e-12)
        clipped = clip_to_convex(ends, polygon, normal)
        if clipped is None:
            assert inside.sum() <= 1
            continue
        assert _inside_convex(clipped, polygon, normal, 1e-9).all()
        kept = np.linalg.norm(clipped[1] - clipped[0]) / np.linalg.norm(ends[1] - ends[0])
        assert abs(kept - inside.mean()) <= 2.0 / len(t)


def _orientation(a, b, c):
    return (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1]) - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0])


def _naive_meets(segment, triangle):
    """A segment meets a triangle when an end lies inside it or the segment crosses one of its sides."""
    signs = [np.sign(_orientation(triangle[k], triangle[(k + 1) % 3], segment)) for k in range(3)]
    for end in range(2):
        if all(s[end] >= 0 for s in signs) or all(s[end] <= 0 for s in signs):
            return True
    for k in range(3):
        a, b = triangle[k], triangle[(k + 1) % 3]
        d1 = _orientation(a, b, segment[0]) * _orientation(a, b, segment[1])
        d2 = _orientation(segment[0], segment[1], a) * _orientation(segment[0], segment[1], b)
        if d1 <= 0 and d2 <= 0:
            return True
    return False


def test_crossing_agrees_with_a_naive_test():
    rng = np.random.default_rng(8)
    segments = rng.uniform(0.0, 10.0, (300, 2, 2))
    triangles = rng.uniform(0.0, 10.0, (40, 3, 2))
    meets = crossing(segments, triangles, 0.0)
    expected = np.array([[_naive_meets(s, t) for t in triangles] for s in segments])
    np.testing.assert_array_equal(meets, expected)
    assert 0.05 < meets.mean() < 0.95


def test_discontinuities_the_triangulation_cannot_take_are_rejected_and_said(monkeypatch):
    """When completing a step with discontinuities fails (a hierarchy defect), that iteration refines at the
    worst samples, the events are not tried again and the refinement log and stats say so."""
    from core.errors import VisradError
    from core.hierarchy import Hierarchy

    setup = box_over_floor_scene()
    complete = Hierarchy.complete_step
    failures = []

    def failing_once_with_segments(self):
        # the queue holds [points, segments, grid step] per element
        if not failures and any(entry[1] for entry in self._queue.values()):
            failures.append(True)
            raise VisradError("a hierarchy defect")
        return complete(self)

    monkeypatch.setattr(Hierarchy, "complete_step", failing_once_with_segments)
    result = Solver(setup.scene, Settings(max_iterations=4, jnd=0.01)).solve()
    third = result.stats["refinement"][2]
    assert failures and third["discontinuities"] == 0 and third["discontinuities_rejected"] > 0
    assert third["rejection"] == "a hierarchy defect"
    assert result.stats["discontinuities_rejected"] == third["discontinuities_rejected"]
    assert result.stats["discontinuities_inserted"] == sum(len(v) for v in result.discontinuities.values())
    assert result.stats["refinement"][3]["leaves"] > third["leaves"], "the third iteration still refined"

