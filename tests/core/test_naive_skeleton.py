"""The skeleton oracles checked against independent evidence before they judge the skeleton.

* analytic EV / VE events: crossing one changes the topology of the exact view of the light
  (core.visibility.exact_view) while moving along it does not; every topology change found on scan lines lies
  on an event or on a face-plane trace; symmetric configurations give symmetric event sets; occluded parts are
  exactly those whose event line core.raycast finds blocked.
* face-plane traces: the form factor's derivative jumps across them (a D1 discontinuity), and only there.
* blocker oracles: witnesses are unoccluded grazes by core.raycast; removal by object agrees with the proofs;
  a stacked-boxes scene with a known answer.
"""

import numpy as np
import pytest

from bench.scenes import SceneBuilder
from core.raycast import segment_contacts, segments_occluded
from core.scene import Scene
from core.visibility import exact_form_factors, exact_view, scene_bvh
from tests.core.naive_skeleton import (
    analytic_event_segments,
    analytic_events,
    blockers_by_removal,
    face_plane_traces,
    reaches,
    same_segment_sets,
    uncovered,
)
from tests.core.skeleton_scenes import box_over_floor_scene, generic_closed_room, lamp_table_scene

UP = np.array([0.0, 0.0, 1.0])


def view_signature(scene, light: int, point, bvh) -> tuple:
    """What EV and VE events change in the visible part of `light` from a floor point, and face events do not.

    Corners of the visible region's boundary are of three kinds: a light corner (two light edges meet), a
    crossing (a light edge meets a blocker's image), a blocker corner (two blocker image edges meet). Crossing
    an EV event hides or shows a light corner; crossing a VE event moves a box corner in or out of the light,
    changing the blocker corners by one. Crossing a face's plane adds or removes two nearly flat blocker corners
    (the face's sliver), which changes nothing here unless the sliver straddles a light edge: that happens
    only on the face-plane traces (naive_skeleton.face_plane_traces), which the tests treat as events too.
    Returns (frozenset of visible light corner indices, number of crossings, blocker corners modulo 2).
    """
    view = exact_view(scene, point, UP, light, bvh=bvh)
    # boundary segments share their end points exactly; a loose match would pair the ends of tiny segments
    tol = 10.0 * scene.tol.length
    light_corners = scene.polygon(light)
    visible, crossings, blocker_corners = set(), 0, 0
    for i in range(len(view.segments)):
        end = view.segments[i, 1]
        for j in np.flatnonzero(np.linalg.norm(view.segments[:, 0] - end, axis=1) <= tol):
            on_light = (view.generators[i, 0] == light, view.generators[j, 0] == light)
            if all(on_light):
                visible.add(int(np.argmin(np.linalg.norm(light_corners - end, axis=1))))
            elif any(on_light):
                crossings += 1
            else:
                blocker_corners += 1
    return frozenset(visible), crossings, blocker_corners % 2


def _distance_2d(p, q, a, b) -> float:
    """Distance between 2-D segments p-q and a-b (0 when they cross)."""

    def orient(u, v, w):
        return (v[0] - u[0]) * (w[1] - u[1]) - (v[1] - u[1]) * (w[0] - u[0])

    def to_segment(x, u, v):
        d = v - u
        t = np.clip((x - u) @ d / (d @ d), 0.0, 1.0) if d @ d > 0.0 else 0.0
        return float(np.linalg.norm(x - (u + t * d)))

    if orient(p, q, a) * orient(p, q, b) < 0 and orient(a, b, p) * orient(a, b, q) < 0:
        return 0.0
    return min(to_segment(p, a, b), to_segment(q, a, b), to_segment(a, p, q), to_segment(b, p, q))


def _clearance(p, q, segments, skip: int) -> float:
    """Distance from the 2-D segment p-q to the nearest segment of (M, 2, 3) other than `skip`."""
    return min(
        (_distance_2d(p, q, s[0, :2], s[1, :2]) for k, s in enumerate(segments) if k != skip), default=np.inf
    )


GENERIC_BOXES = [
    {},
    {"angles": (1.1, -0.4, 0.7), "box_centre": (-0.3, 0.25, 0.9)},
    {"angles": (-0.2, 0.9, 2.0), "box_centre": (0.4, 0.3, 1.3), "box_size": (0.5, 0.8, 0.3)},
]


@pytest.fixture(scope="module", params=range(len(GENERIC_BOXES)))
def generic_box(request):
    """A box over the floor (the default one first), its EV / VE segments, and those followed by the
    face-plane traces."""
    setup = box_over_floor_scene(**GENERIC_BOXES[request.param])
    segments = analytic_event_segments(*setup.event_geometry())
    everything = np.concatenate([segments, face_plane_traces(*setup.event_geometry())])
    return setup, segments, everything, scene_bvh(setup.scene)


def test_the_generic_box_casts_ev_and_ve_events(generic_box):
    setup, segments, everything, _ = generic_box
    events = analytic_events(*setup.event_geometry())
    # a convex box seen from a point has a silhouette of 4 or 6 edges; each of the 4 light corners sees one
    assert {e.kind for e in events} == {"EV", "VE"}
    assert sum(e.kind == "EV" for e in events) in (16, 24)
    assert np.all(np.abs(segments[:, :, 2]) <= 1e-12)
    assert np.all(np.linalg.norm(segments[:, 1] - segments[:, 0], axis=1) > 1e-6)


def test_crossing_an_event_changes_the_view_and_moving_along_it_does_not(generic_box):
    setup, segments, everything, bvh = generic_box
    scene, light = setup.scene, setup.light
    offset = 1e-5
    crossed = along = 0
    for k, (p, q) in enumerate(segments):
        direction = (q - p)[:2] / np.linalg.norm((q - p)[:2])
        across = np.array([-direction[1], direction[0], 0.0])
        for fraction in (0.3, 0.5, 0.7):
            m = p + fraction * (q - p)
            if _clearance(m[:2], m[:2], everything, k) < 1e-3:
                continue  # near another event: both sides may differ by two events
            before = view_signature(scene, light, m - offset * across, bvh)
            after = view_signature(scene, light, m + offset * across, bvh)
            assert before != after, f"event {k} at {m}: the view does not change across it"
            crossed += 1
            further = p + (fraction + 0.15) * (q - p)
            for side in (-offset, offset):
                start, end = m + side * across, further + side * across
                if _clearance(start[:2], end[:2], everything, k) < 1e-3:
                    continue
                assert view_signature(scene, light, start, bvh) == view_signature(scene, light, end, bvh)
                along += 1
    assert crossed >= 2 * len(segments)
    assert along >= 2 * len(segments)


def test_every_view_change_on_scan_lines_lies_on_an_event(generic_box):
    setup, segments, everything, bvh = generic_box
    scene, light = setup.scene, setup.light
    floor = setup.scene.polygon(setup.floor)[:, :2]
    # events are clipped to the floor: scan the floor only
    lo = np.maximum(segments[:, :, :2].reshape(-1, 2).min(axis=0) - 0.2, floor.min(axis=0) + 1e-3)
    hi = np.minimum(segments[:, :, :2].reshape(-1, 2).max(axis=0) + 0.2, floor.max(axis=0) - 1e-3)
    changes = 0
    for axis in (0, 1):
        for level in np.linspace(lo[1 - axis], hi[1 - axis], 9)[1:-1]:
            samples = np.zeros((241, 3))
            samples[:, axis] = np.linspace(lo[axis], hi[axis], 241)
            samples[:, 1 - axis] = level
            signatures = [view_signature(scene, light, s, bvh) for s in samples]
            for i in range(len(samples) - 1):
                if signatures[i] != signatures[i + 1]:
                    changes += 1
                    gap = _clearance(samples[i, :2], samples[i + 1, :2], everything, -1)
                    assert gap <= 1e-9, f"the view changes between {samples[i]} and {samples[i + 1]}, no event"
    assert changes >= 40


def _reflect(segments, matrix):
    return segments @ np.asarray(matrix, dtype=np.float64).T


def test_a_symmetric_configuration_has_symmetric_events(generic_box):
    setup = box_over_floor_scene(angles=(0.0, 0.0, np.pi / 4), box_centre=(0.0, 0.0, 1.0), box_size=(0.6, 0.6, 0.4))
    segments = analytic_event_segments(*setup.event_geometry())
    assert len(segments) >= 16
    mirror_x = np.diag([-1.0, 1.0, 1.0])
    diagonal = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    quarter_turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    for matrix in (mirror_x, diagonal, quarter_turn):
        assert same_segment_sets(segments, _reflect(segments, matrix), 1e-9)
    # the comparison has teeth: the generic box's events are not symmetric
    generic = generic_box[1]
    assert not same_segment_sets(generic, _reflect(generic, mirror_x), 1e-6)


def _slope_jump(scene, light, point, across, step) -> float:
    """Jump of the form factor's derivative along `across` at a floor point, by one-sided differences."""
    points = np.array([point + k * step * across for k in (-2, 0, 2)])
    ff = exact_form_factors(scene, points, np.tile(UP, (3, 1)), light)
    return ((ff[2] - ff[1]) - (ff[1] - ff[0])) / (2.0 * step)


def test_face_plane_traces_are_where_the_derivative_jumps(generic_box):
    """A kink (D1) does not shrink with the step, a smooth second derivative (D2 events included) does."""
    setup = generic_box[0]
    traces = face_plane_traces(*setup.event_geometry())
    assert len(traces) >= 1
    for p, q in traces:
        direction = (q - p) / np.linalg.norm(q - p)
        across = np.array([-direction[1], direction[0], 0.0])
        for fraction in (0.25, 0.5, 0.75):
            m = p + fraction * (q - p)
            coarse, fine = (_slope_jump(setup.scene, setup.light, m, across, h) for h in (1e-4, 1e-5))
            assert abs(fine) > 1e-5 and abs(fine - coarse) < 0.05 * abs(fine)
        for beyond in (p - 0.05 * (q - p), q + 0.05 * (q - p)):
            if np.any(np.abs(beyond[:2]) >= 2.0):
                continue  # outside the floor (|x|, |y| <= 2): the floor clipped the trace there, the kink goes on
            coarse, fine = (_slope_jump(setup.scene, setup.light, beyond, across, h) for h in (1e-4, 1e-5))
            assert abs(fine) < 0.2 * abs(coarse) + 1e-9


def test_segment_sets_compare_as_point_sets():
    a = np.array([[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]], [[0.0, 1.0, 0.0], [0.0, 2.0, 0.0]]])
    # split at other places, reversed, overlapping
    b = np.array([[[1.2, 0.0, 0.0], [0.0, 0.0, 0.0]], [[0.9, 0.0, 0.0], [2.0, 0.0, 0.0]],
                  [[0.0, 2.0, 0.0], [0.0, 1.0, 0.0]]])
    assert same_segment_sets(a, b, 1e-9)
    shorter = b.copy()
    shorter[1, 1, 0] = 1.9
    assert not same_segment_sets(a, shorter, 1e-9)
    np.testing.assert_allclose(uncovered(a, shorter, 1e-9), [[[1.9 + 1e-9, 0.0, 0.0], [2.0, 0.0, 0.0]]])
    shifted = b.copy()
    shifted[2, :, 0] = 1e-6
    assert not same_segment_sets(a, shifted, 1e-9)
    assert same_segment_sets(a, shifted, 1e-5)


def test_occluded_parts_of_events_are_those_whose_line_is_blocked(generic_box):
    setup = generic_box[0]
    light, faces, floor = setup.event_geometry()
    plate = np.array([[-0.1, -1.0, 1.6], [0.6, -1.0, 1.6], [0.6, 1.0, 1.6], [-0.1, 1.0, 1.6]])
    bare = analytic_events(light, faces, floor)
    hidden = analytic_events(light, faces, floor, occluders=[plate])
    plate_scene = Scene.from_polygons(plate, [[0, 1, 2, 3]], [[0.5] * 3], [[0.0] * 3])
    plate_bvh = scene_bvh(plate_scene)
    light_normal = np.cross(light[1] - light[0], light[2] - light[0])

    def light_point(event, q):
        if event.kind == "EV":
            return event.centre
        # the line from q through the box corner, continued to the light's plane
        w = event.centre
        s = ((light[0] - q) @ light_normal) / ((w - q) @ light_normal)
        return q + s * (w - q)

    def blocked(event, pieces):
        fractions = np.linspace(0.05, 0.95, 7)
        points = [p + f * (q - p) for p, q in pieces for f in fractions]
        starts = np.array([light_point(event, q) for q in points]).reshape(-1, 3)
        return segments_occluded(plate_scene, plate_bvh, starts, np.array(points).reshape(-1, 3))

    def key(event):
        return event.kind, event.centre.tobytes(), event.generator.tobytes()

    kept = {key(e): e.segments for e in hidden}
    assert set(kept) <= {key(e) for e in bare}
    kept_total = removed_total = 0
    for event in bare:
        after = kept.get(key(event), np.empty((0, 2, 3)))
        assert len(uncovered(after, event.segments, 1e-9)) == 0
        removed = uncovered(event.segments, after, 1e-9)
        assert not blocked(event, after).any()
        assert blocked(event, removed).all()
        kept_total += len(after)
        removed_total += len(removed)
    assert kept_total > 0 and removed_total > 0


# ---------------------------------------------------------------------------------------------------------
# Blocker oracles.


@pytest.fixture(scope="module")
def lamp_table():
    return lamp_table_scene()


def _faces_down(scene, polygons):
    return [int(p) for p in polygons if scene.normals[p] @ UP < -0.5]


def test_lamp_table_lists_follow_the_construction(lamp_table):
    setup = lamp_table
    scene, objects = setup.scene, setup.objects
    hidden = [n for n in objects if n.startswith(("leg", "on table"))]
    expected_not = set(np.concatenate([objects[n] for n in hidden]).tolist())
    expected_not |= set(_faces_down(scene, objects["table top"]))
    touched = set(objects["table top"].tolist()) - set(_faces_down(scene, objects["table top"]))
    touched |= set(objects["floor box"].tolist()) - set(_faces_down(scene, objects["floor box"]))
    assert set(setup.not_blockers.tolist()) == expected_not
    assert set(setup.blockers.tolist()) == touched
    # the floor box's bottom lies on the floor: neither list
    assert not set(_faces_down(scene, objects["floor box"])) & (expected_not | touched)


def test_lamp_table_witnesses_are_unoccluded_grazes(lamp_table):
    setup = lamp_table
    bvh = scene_bvh(setup.scene)
    for polygon in setup.blockers:
        answer = reaches(setup.scene, setup.light, setup.floor, int(polygon))
        start, touch, end = answer.witness
        contacts = segment_contacts(setup.scene, bvh, start, end)
        assert not contacts.blocked, f"witness of polygon {polygon} is blocked"
        assert polygon in contacts.polygon, f"witness of polygon {polygon} does not touch it"
        assert np.linalg.norm(np.cross(end - start, touch - start)) <= 1e-9 * np.linalg.norm(end - start) ** 2


def test_lamp_table_removal_by_object(lamp_table):
    setup = lamp_table
    one_per_object = {name: int(ids[0]) for name, ids in setup.objects.items() if name not in ("room", "lamp")}
    evidence = blockers_by_removal(
        setup.scene, setup.light, setup.floor, one_per_object.values(), 400, np.random.default_rng(3), remove="object"
    )
    for name, polygon in one_per_object.items():
        blocks = name in ("table top", "floor box")
        assert evidence[polygon].changed == blocks, (name, evidence[polygon].largest_change)
        assert len(evidence[polygon].removed) == 6


def test_removing_one_face_of_a_closed_box_changes_nothing(lamp_table):
    """Why the blocker acceptance removes whole objects: every line through one face of a closed box also
    crosses another face, so no single face of the table top changes a form factor."""
    setup = lamp_table
    top = setup.objects["table top"]
    evidence = blockers_by_removal(setup.scene, setup.light, setup.floor, top, 400, np.random.default_rng(4))
    assert not any(e.changed for e in evidence.values())
    assert max(e.largest_change for e in evidence.values()) <= 1e-12


def stacked_boxes():
    """A 0.4 m square light on the floor facing up, a 1.2 x 1.2 m box floating at 1.0-1.2 m above it, a small
    box (0.4 x 0.4 x 0.3 m) resting on it, and a 4 x 4 m ceiling panel at 3 m facing down (the receiver)."""
    b = SceneBuilder("stacked boxes")
    b.light("light", (0.0, 0.0, 0.0), UP, 0.4, 0.4, (10.0, 10.0, 10.0))
    b.box("lower", (-0.6, -0.6, 1.0), (0.6, 0.6, 1.2), (0.5, 0.5, 0.5))
    b.box("upper", (-0.2, -0.1, 1.2), (0.2, 0.3, 1.5), (0.5, 0.5, 0.5))
    b.panel("ceiling", (0.0, 0.0, 3.0), -UP, 4.0, 4.0, (0.5, 0.5, 0.5))
    spec = b.spec()
    objects = {name: np.flatnonzero(spec.object_ids == i) for i, name in enumerate(spec.object_names)}
    return spec.build(), objects


def test_stacked_boxes_known_blockers():
    """Every line from the light (|x|, |y| <= 0.2, z = 0) to the upper box (|x| <= 0.2, -0.1 <= y <= 0.3,
    z >= 1.2) crosses z = 1.0 within |x| <= 0.2 + 0.4 * 1.0 / 1.2 < 0.6 and -0.2 - 0.5 / 1.2 < y < 0.2 + 0.5 / 1.2:
    inside the lower box's bottom face. So the upper box is never touched by an unoccluded light -> ceiling
    segment, nor is the lower box's top (the same argument); the lower box's bottom and sides are, along its
    bottom edges (a silhouette seen from the light, which lies under the box)."""
    scene, objects = stacked_boxes()
    light, receiver = int(objects["light"][0]), int(objects["ceiling"][0])
    lower_top = [int(p) for p in objects["lower"] if scene.normals[p] @ UP > 0.5]
    expected = {int(p): False for p in objects["upper"]}
    expected.update({int(p): True for p in objects["lower"]})
    expected.update({p: False for p in lower_top})
    found = {p: reaches(scene, light, receiver, p).status for p in expected}
    assert found == expected
    evidence = blockers_by_removal(
        scene, light, receiver, [objects["lower"][0], objects["upper"][0]], 300, np.random.default_rng(5),
        remove="object",
    )
    assert evidence[int(objects["lower"][0])].changed
    assert not evidence[int(objects["upper"][0])].changed


def test_generic_room_is_closed_and_generic():
    setup = generic_closed_room(7)
    scene = setup.scene
    faces_per_edge = np.diff(scene.edge_face_offsets)
    light_edges = scene.polygon_edge_ids[scene.polygon_offsets[setup.light] : scene.polygon_offsets[setup.light + 1]]
    assert np.all(faces_per_edge[light_edges] == 1)
    assert np.all(np.delete(faces_per_edge, light_edges) == 2)
    assert len(setup.objects) == 2 + len(setup.boxes) == 8
