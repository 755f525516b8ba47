"""Small scenes for the Visibility Skeleton's acceptance tests (issue 3), with the ids the tests need.

* `lamp_table_scene`: seed 003's exact-blocker example (section 4.4): a small lamp above a big table carrying
  small objects; the objects and the legs are in the table top's umbra, a box on the floor beside the table is
  partly lit. The expected blockers of lamp -> floor are derived here geometrically (tests/core/naive_skeleton
  `reaches`), not typed in.
* `box_over_floor_scene`: one box between a square light and a floor, for the analytic EV / VE event lines.
* `generic_closed_room`: a closed room of floating boxes turned by random rotations: no contacts, no parallel
  edges across objects (generic position), for the graph-consistency tests before the degenerate rooms.
* `free_convex_corners`: the vertices where the closed-room identity holds for every receiver (form factors
  to all polygons sum to 1), for the tests and the furnished-room benchmark.

Every scene is built through bench.scenes.SceneBuilder, so its conventions (objects with their own vertices,
outward boxes, inward rooms, one-sided lights) are those of the benchmarks. Every polygon here is a convex
quad, so scene polygon i is builder polygon i (checked).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from bench.scenes import BOX, LIGHT, WARM_WHITE, SceneBuilder, box_mesh
from core.scene import Scene
from tests.core.furnished_rooms import box_quads
from tests.core.naive_skeleton import reaches

DOWN = (0.0, 0.0, -1.0)
GREY = (0.5, 0.5, 0.5)


def _build(builder: SceneBuilder) -> tuple[Scene, dict[str, np.ndarray]]:
    """The engine scene and {object name: (p,) int64 polygon ids}."""
    spec = builder.spec()
    scene = spec.build()
    if scene.n_polygons != spec.n_polygons:
        raise AssertionError("a scene polygon was split: the ids below would not be the builder's")
    objects = {name: np.flatnonzero(spec.object_ids == i) for i, name in enumerate(spec.object_names)}
    return scene, objects


def _turned_box(builder: SceneBuilder, name: str, centre, size, rotation: np.ndarray) -> int:
    """A closed box of `size` (3,) turned by the (3, 3) rotation matrix about its centre (3,)."""
    half = 0.5 * np.asarray(size, dtype=np.float64)
    vertices, quads = box_mesh(-half, half)
    return builder.add_object(name, BOX, vertices @ rotation.T + np.asarray(centre, dtype=np.float64), quads, GREY)


@dataclass(frozen=True)
class LampTable:
    """The lamp-and-table scene and what the blocker tests need.

    light, floor: polygon ids; objects: {name: (p,) int64 polygon ids} for "room" (floor, ceiling, 4 walls),
    "lamp", "table top", "leg 0".."leg 3", "on table 0".."on table 2", "floor box";
    blockers: sorted (B,) int64 polygons some unoccluded lamp -> floor segment touches (a witness segment was
    found: the table top's upper and side faces, the floor box's top and side faces);
    not_blockers: sorted (N,) int64 polygons no such segment can touch (proved: the legs, the objects on the
    table, the table top's lower face). The room's walls and ceiling, and the floor box's bottom face (lying
    on the floor, only touched by segments ending on it) are in neither list: their status is a convention.
    """

    scene: Scene
    light: int
    floor: int
    objects: dict
    blockers: np.ndarray
    not_blockers: np.ndarray


def lamp_table_scene() -> LampTable:
    """A 5 x 4 x 2.5 m closed room; a 0.2 m square lamp 5 cm under the ceiling, facing down, above the centre
    of a 1.6 x 1.2 m table (a 5 cm thick top at 0.70-0.75 m on four 5 cm legs inset by 5 cm); three small
    boxes standing on the top, well inside its outline; a 0.5 m high box on the floor just beyond the table's
    +x edge, partly in the table's shadow, and offset in y so that four of its vertical faces see the lamp
    along some silhouette.

    Geometry of the claim "objects on the table and legs are not blockers": every line from the lamp through
    one of them crosses the table top's plane strictly inside the top (all lamp-corner / object-corner lines
    do, hence all lines: see naive_skeleton.reaches), so none is touched by an unoccluded lamp -> floor
    segment. The lists are derived by `reaches` for every polygon of the table, the objects and the floor box.
    """
    b = SceneBuilder("lamp table")
    b.room("room", (0.0, 0.0, 0.0), (5.0, 4.0, 2.5))
    centre = np.array([2.2, 2.0])
    b.light("lamp", (centre[0], centre[1], 2.45), DOWN, 0.2, 0.2, 200.0 * WARM_WHITE)
    half = np.array([0.8, 0.6])
    top_lo, top_hi = centre - half, centre + half
    b.box("table top", (*top_lo, 0.70), (*top_hi, 0.75), (0.55, 0.38, 0.22))
    inset, leg = 0.05, 0.05
    for i, (x, y) in enumerate(
        [(top_lo[0] + inset, top_lo[1] + inset), (top_hi[0] - inset - leg, top_lo[1] + inset),
         (top_lo[0] + inset, top_hi[1] - inset - leg), (top_hi[0] - inset - leg, top_hi[1] - inset - leg)]
    ):
        b.box(f"leg {i}", (x, y, 0.0), (x + leg, y + leg, 0.70), (0.55, 0.38, 0.22))
    # on the top, touching it; small enough that their lamp shadows stay on the top
    for i, (lo, hi) in enumerate([((-0.45, -0.30), (-0.20, -0.10)), ((0.05, 0.05), (0.30, 0.25)),
                                  ((0.25, -0.35), (0.45, -0.15))]):
        height = (0.25, 0.15, 0.30)[i]
        b.box(f"on table {i}", (*(centre + lo), 0.75), (*(centre + hi), 0.75 + height), (0.3, 0.4, 0.6))
    b.box("floor box", (centre[0] + 0.9, centre[1] + 0.35, 0.0), (centre[0] + 1.5, centre[1] + 0.95, 0.5),
          (0.6, 0.45, 0.28))
    scene, objects = _build(b)
    light = int(objects["lamp"][0])
    floor = int(objects["room"][0])
    candidates = np.concatenate(
        [objects[name] for name in objects if name not in ("room", "lamp")]
    )
    verdicts = {int(p): reaches(scene, light, floor, int(p)).status for p in candidates}
    return LampTable(
        scene=scene,
        light=light,
        floor=floor,
        objects=objects,
        blockers=np.array(sorted(p for p, v in verdicts.items() if v is True), dtype=np.int64),
        not_blockers=np.array(sorted(p for p, v in verdicts.items() if v is False), dtype=np.int64),
    )


@dataclass(frozen=True)
class BoxOverFloor:
    """One box between a square light and a floor.

    light, floor: polygon ids; box: (6,) int64 polygon ids of the box; room: (6,) int64 ids of the closed
    room (floor first, as bench.scenes.room_mesh) or empty when open (the floor is then a lone two-sided quad).
    """

    scene: Scene
    light: int
    floor: int
    box: np.ndarray
    room: np.ndarray

    def event_geometry(self) -> tuple[np.ndarray, list[np.ndarray], np.ndarray]:
        """(light (4, 3), box faces [6 x (4, 3)], floor (4, 3)): the arguments of
        naive_skeleton.analytic_event_segments, taken from the scene itself."""
        return (
            self.scene.polygon(self.light).copy(),
            [self.scene.polygon(int(p)).copy() for p in self.box],
            self.scene.polygon(self.floor).copy(),
        )


def box_over_floor_scene(
    closed: bool = False, angles=(0.35, 0.6, 0.2), box_centre=(0.15, -0.1, 1.0), box_size=(0.6, 0.5, 0.4),
) -> BoxOverFloor:
    """A 4 x 4 m floor at z = 0 (centred on the origin), a 0.6 m square light at z = 2 facing down, and a box
    of `box_size` centred at `box_centre`, turned by the xyz Euler `angles` (radians; (0, 0, 0) gives an
    axis-aligned box, with edges parallel to the light's: a degenerate configuration).

    closed=True puts everything in a closed 4 x 4 x 2.1 m room whose floor is the floor; otherwise the floor
    is a lone quad. The defaults are generic: no box edge parallel to a light edge, no light corner in a box
    face's plane.
    """
    b = SceneBuilder("box over floor")
    if closed:
        b.room("room", (-2.0, -2.0, 0.0), (2.0, 2.0, 2.1))
    else:
        b.panel("floor", (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 4.0, 4.0, GREY)
    b.light("light", (0.0, 0.0, 2.0), DOWN, 0.6, 0.6, 50.0 * WARM_WHITE)
    rotation = Rotation.from_euler("xyz", angles).as_matrix()
    _turned_box(b, "box", box_centre, box_size, rotation)
    scene, objects = _build(b)
    room = objects["room"] if closed else np.empty(0, dtype=np.int64)
    floor = int(objects["room"][0]) if closed else int(objects["floor"][0])
    return BoxOverFloor(scene=scene, light=int(objects["light"][0]), floor=floor, box=objects["box"], room=room)


@dataclass(frozen=True)
class GenericRoom:
    """A closed room with floating turned boxes and one light.

    light: polygon id; objects: {name: (p,) int64 polygon ids} for "room", "light", "box 0".."box n-1";
    boxes: [(centre (3,), size (3,), rotation (3, 3))] as placed.
    """

    scene: Scene
    light: int
    objects: dict
    boxes: list


def generic_closed_room(seed: int, n_boxes: int = 6) -> GenericRoom:
    """A closed room (4-6 x 4-6 x 2.5-3 m) with `n_boxes` boxes (0.2-0.8 m sides) turned by uniformly random
    rotations, floating: each box's bounding sphere keeps 5 cm from the walls and from the others' spheres, so
    nothing touches. A 0.5 x 0.4 m light 2 cm under the ceiling, facing down, turned by a random angle about
    the vertical. Redrawn until no two edges of different objects are within 1e-3 rad of parallel.
    """
    rng = np.random.default_rng(seed)
    size = np.array([rng.uniform(4.0, 6.0), rng.uniform(4.0, 6.0), rng.uniform(2.5, 3.0)])
    for _ in range(100):
        boxes = []
        while len(boxes) < n_boxes:
            extent = rng.uniform(0.2, 0.8, size=3)
            radius = 0.5 * float(np.linalg.norm(extent))
            centre = rng.uniform(radius + 0.05, size - radius - 0.05)
            ceiling_gap = size[2] - 0.05 - (centre[2] + radius)
            if ceiling_gap < 0.05:
                continue  # keep clear of the light hanging under the ceiling
            if all(np.linalg.norm(centre - c) > radius + 0.5 * np.linalg.norm(s) + 0.05 for c, s, _ in boxes):
                boxes.append((centre, extent, Rotation.random(random_state=rng).as_matrix()))
        yaw = rng.uniform(0.0, np.pi / 2)
        b = SceneBuilder(f"generic room {seed}")
        b.room("room", (0.0, 0.0, 0.0), tuple(size))
        light_centre = (rng.uniform(1.0, size[0] - 1.0), rng.uniform(1.0, size[1] - 1.0), size[2] - 0.02)
        light_vertices, light_quads = _turned_light(light_centre, 0.5, 0.4, yaw)
        b.add_object("light", LIGHT, light_vertices, light_quads, (0.8, 0.8, 0.8), emission=30.0 * WARM_WHITE)
        for i, (centre, extent, rotation) in enumerate(boxes):
            _turned_box(b, f"box {i}", centre, extent, rotation)
        scene, objects = _build(b)
        if _no_parallel_edges_across_objects(scene, 1e-3):
            return GenericRoom(scene=scene, light=int(objects["light"][0]), objects=objects, boxes=boxes)
    raise RuntimeError(f"generic_closed_room({seed}): no generic draw in 100 attempts")


def _turned_light(centre, width: float, depth: float, yaw: float) -> tuple[np.ndarray, list[list[int]]]:
    """A horizontal rectangle facing down, turned by yaw about the vertical: (4, 3) vertices and one quad."""
    cos, sin = np.cos(yaw), np.sin(yaw)
    u = np.array([cos, sin, 0.0]) * width / 2
    v = np.array([-sin, cos, 0.0]) * depth / 2
    c = np.asarray(centre, dtype=np.float64)
    # clockwise seen from above, so the normal points down
    return np.array([c - u - v, c - u + v, c + u + v, c + u - v]), [[0, 1, 2, 3]]


def _no_parallel_edges_across_objects(scene: Scene, angle: float) -> bool:
    directions = scene.vertices[scene.edges[:, 1]] - scene.vertices[scene.edges[:, 0]]
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    owner = scene.object_ids[scene.edge_faces[scene.edge_face_offsets[:-1]]]
    sines = np.linalg.norm(np.cross(directions[:, None, :], directions[None, :, :]), axis=2)
    across = owner[:, None] != owner[None, :]
    return bool(sines[across].min() > angle)


def boxes_in_room(boxes, size=(4.0, 3.0, 2.5)) -> Scene:
    """A closed axis-aligned room of `size` (3,) (inward normals, from the origin) holding axis-aligned boxes
    [(lo (3,), hi (3,))]: the degenerate configurations of everyday scenes (parallel edges, coplanar faces,
    boxes resting on the floor or against a wall), one at a time."""
    vertices, polygons = [], []
    corners, quads = box_quads(np.zeros(3), np.asarray(size, dtype=np.float64))
    vertices.extend(corners)
    polygons.extend([list(reversed(q)) for q in quads])
    for lo, hi in boxes:
        corners, quads = box_quads(np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64))
        base = len(vertices)
        vertices.extend(corners)
        polygons.extend([[base + i for i in q] for q in quads])
    count = len(polygons)
    return Scene.from_polygons(np.array(vertices), polygons, np.full((count, 3), 0.5), np.zeros((count, 3)))


def free_convex_corners(scene: Scene) -> np.ndarray:
    """(V,) bool: vertices of solid objects that touch no polygon of another object and whose edges are all
    convex (every other face at the vertex lies behind each face), so every receiver's hemisphere there
    looks into the room only. Room corners are not: half or three quarters of their hemisphere lie outside,
    where the walls are seen edge-on."""
    tol = 16.0 * scene.tol.length
    result = np.zeros(scene.n_vertices, dtype=bool)
    for vertex in range(scene.n_vertices):
        point = scene.vertices[vertex]
        own = [p for p in range(scene.n_polygons) if vertex in scene.polygon_vertices(p)]
        if not all(scene.solid[p] for p in own):
            continue
        neighbours = np.unique(np.concatenate([scene.polygon_vertices(p) for p in own]))
        if any(((scene.vertices[neighbours] - point) @ scene.normals[p] > tol).any() for p in own):
            continue
        result[vertex] = not any(touches(scene, p, point, tol) for p in range(scene.n_polygons) if p not in own)
    return result


def touches(scene: Scene, polygon: int, point: np.ndarray, tol: float) -> bool:
    """Whether a point lies on a convex polygon (within tol of its plane and inside its sides)."""
    normal = scene.normals[polygon]
    if abs(normal @ point + scene.plane_offsets[polygon]) > tol:
        return False
    corners = scene.polygon(polygon)
    sides = np.roll(corners, -1, axis=0) - corners
    inward = np.cross(normal, sides)
    inward /= np.linalg.norm(inward, axis=1)[:, None]
    return bool((np.einsum("ij,ij->i", point - corners, inward) >= -tol).all())
