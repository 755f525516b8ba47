"""Deterministic benchmark and test scenes, as plain polygon arrays for `core.scene.Scene.from_polygons`.

Role: every benchmark in bench/ and every test that needs a realistic scene gets it from here, so the
numbers we publish are always measured on the same geometry. The family mirrors the test scenes of the
seed papers (shared/seeds/README.md):

* ``office(n)`` for n in 84 ... 1488: the furnished rooms of the Visibility Skeleton paper (seed 003,
  Table 1), with exactly the paper's polygon counts;
* ``desk()`` (444 polygons, 2 large area lights), ``many_lights()`` (the same geometry with the large lights
  turned down and 8 small bright lights added), ``indirect_bedroom()`` (534 polygons, one small lamp that
  emits downwards only) and ``village()`` (312 polygons, buildings and cars under an overhead rectangle):
  the scenes of seed 000, section 7.2, rebuilt from their descriptions (the originals are not public);
* ``cornell_box()``: the published Cornell box (bench/data/cornell_box.json), the one scene whose exact
  geometry and materials are public;
* ``closed_furnished_room(seed)``: random closed rooms of boxes resting, stacked, floating and touching, for
  robustness tests (coplanar and touching faces are the degenerate cases of visibility events).

Conventions: metres, z up, Diffuse-like reflectances in [0, 1) (walls and ceiling 0.7 grey, floor 0.5),
emission is exitance in W/m^2 (DESIGN.md section 2). Polygons are counter-clockwise seen from the side their
normal points to. Every object has its own vertices (nothing is welded across objects) and is welded inside
itself, so a closed object is watertight by vertex index. Generators only produce arrays; ``SceneSpec.build``
is the one place that calls the engine.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

# a verbatim copy of the steering repository's shared/data/cornell_box.json, so a clone is self-contained
CORNELL_BOX_JSON = Path(__file__).resolve().parent / "data" / "cornell_box.json"

OFFICE_SIZES = (84, 168, 312, 432, 756, 1056, 1488)

# Object kinds (SceneSpec.object_kinds). The closed kinds are watertight by construction.
ROOM = "room"  # closed, normals pointing inwards
BOX = "box"  # closed box, normals pointing outwards
SOLID = "solid"  # other closed polyhedron (roof prism, pyramid), normals outwards
OPEN = "open"  # open polyhedral surface (lampshade, Cornell block without its bottom)
PANEL = "panel"  # a single flat quad that is not a light (poster, rug, ground, wall)
LIGHT = "light"  # a one-sided emitting quad
CLOSED_KINDS = frozenset({ROOM, BOX, SOLID})

WALL = (0.7, 0.7, 0.7)
CEILING = (0.7, 0.7, 0.7)
FLOOR = (0.5, 0.5, 0.5)
LIGHT_HOUSING = (0.8, 0.8, 0.8)
WOOD = (0.55, 0.38, 0.22)
DARK_WOOD = (0.33, 0.21, 0.12)
METAL = (0.6, 0.6, 0.62)
DARK_PLASTIC = (0.08, 0.08, 0.09)
PAPER = (0.8, 0.8, 0.78)
FABRICS = ((0.6, 0.15, 0.12), (0.15, 0.25, 0.6), (0.2, 0.5, 0.25), (0.75, 0.65, 0.2), (0.45, 0.3, 0.55))
BOOK_COLOURS = (
    (0.55, 0.1, 0.1),
    (0.1, 0.3, 0.55),
    (0.15, 0.45, 0.2),
    (0.7, 0.6, 0.3),
    (0.2, 0.2, 0.22),
    (0.6, 0.35, 0.15),
    (0.75, 0.75, 0.7),
)
CARDBOARD = (0.6, 0.45, 0.28)
WARM_WHITE = np.array([1.0, 0.92, 0.8])

DOWN = (0.0, 0.0, -1.0)
UP = (0.0, 0.0, 1.0)


@dataclass
class SceneSpec:
    """A scene as the arrays `Scene.from_polygons` takes, plus what benchmarks and tests need to know.

    vertices (V, 3) float64 metres; polygons: P lists of vertex indices, counter-clockwise seen from the
    normal side; reflectance (P, 3) float64 in [0, 1); emission (P, 3) float64 exitance W/m^2;
    object_ids (P,) int64 indexing object_names and object_kinds; two_sided (P,) bool;
    lights: sorted (L,) int64 indices of the polygons with non-zero emission.
    """

    name: str
    vertices: np.ndarray
    polygons: list[list[int]]
    reflectance: np.ndarray
    emission: np.ndarray
    object_ids: np.ndarray
    two_sided: np.ndarray
    object_names: list[str]
    lights: np.ndarray
    object_kinds: list[str]

    @property
    def n_polygons(self) -> int:
        return len(self.polygons)

    def build(self):
        """The validated engine scene (`core.scene.Scene`); raises core.errors.SceneError on bad input."""
        from core.scene import Scene

        return Scene.from_polygons(
            self.vertices,
            self.polygons,
            self.reflectance,
            self.emission,
            object_ids=self.object_ids,
            two_sided=self.two_sided,
        )

    def object_polygons(self, object_id: int) -> list[int]:
        """Indices of the polygons of one object, in scene order."""
        return np.flatnonzero(self.object_ids == object_id).tolist()


# ---------------------------------------------------------------------------------------------------------
# Meshes: pure functions returning (vertices (k, 3) float64, polygons as index lists into those vertices).


def box_mesh(lo, hi, yaw: float = 0.0, pivot=None) -> tuple[np.ndarray, list[list[int]]]:
    """A closed box with outward normals: 8 vertices (8, 3) float64 and 6 quads.

    lo, hi: (3,) opposite corners of the axis-aligned box before rotation. yaw (radians) turns it
    counter-clockwise about the vertical axis through pivot (x, y), by default the box's own centre.
    Vertex i has corner bits x = i & 1, y = i & 2, z = i & 4.
    """
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    bits = np.array([[i & 1, (i >> 1) & 1, (i >> 2) & 1] for i in range(8)], dtype=bool)
    vertices = np.where(bits, hi, lo)
    if yaw:
        centre = (lo[:2] + hi[:2]) / 2 if pivot is None else np.asarray(pivot, dtype=np.float64)
        cos, sin = math.cos(yaw), math.sin(yaw)
        offset = vertices[:, :2] - centre
        vertices[:, 0] = centre[0] + cos * offset[:, 0] - sin * offset[:, 1]
        vertices[:, 1] = centre[1] + sin * offset[:, 0] + cos * offset[:, 1]
    quads = [[0, 2, 3, 1], [4, 5, 7, 6], [0, 1, 5, 4], [2, 6, 7, 3], [0, 4, 6, 2], [1, 3, 7, 5]]
    return vertices, quads


def room_mesh(lo, hi) -> tuple[np.ndarray, list[list[int]]]:
    """A closed room with inward normals: 8 vertices (8, 3) float64 and 6 quads in the order
    floor, ceiling, wall at y = lo, wall at y = hi, wall at x = lo, wall at x = hi."""
    vertices, quads = box_mesh(lo, hi)
    return vertices, [quad[::-1] for quad in quads]


def rectangle_axes(normal, width: float, height: float) -> tuple[np.ndarray, np.ndarray]:
    """Half-extent vectors (u, v), each (3,) float64, of a width x height rectangle facing `normal`.

    u x v points along normal. v follows the world z axis for a vertical rectangle and the y axis for a
    horizontal one, so posters stand upright and rugs are aligned with the room.
    """
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    up = np.array([0.0, 0.0, 1.0]) if abs(n[2]) < 0.9 else np.array([0.0, 1.0, 0.0])
    v = up - np.dot(up, n) * n
    v /= np.linalg.norm(v)
    u = np.cross(v, n)
    return u * (width / 2), v * (height / 2)


def quad_mesh(centre, normal, width: float, height: float) -> tuple[np.ndarray, list[list[int]]]:
    """A width x height rectangle centred at `centre` facing `normal`: (4, 3) float64 vertices, one quad."""
    c = np.asarray(centre, dtype=np.float64)
    u, v = rectangle_axes(normal, width, height)
    return np.array([c - u - v, c + u - v, c + u + v, c - u + v]), [[0, 1, 2, 3]]


def gable_roof_mesh(lo, hi, ridge_height: float, ridge_along: str = "x") -> tuple[np.ndarray, list[list[int]]]:
    """A closed triangular prism (gable roof) on the rectangle lo..hi at height lo[2], outward normals:
    6 vertices (6, 3) float64, 5 polygons (bottom quad, 2 sloped quads, 2 triangular gables)."""
    x0, y0, z0 = (float(c) for c in lo)
    x1, y1 = float(hi[0]), float(hi[1])
    top = z0 + ridge_height
    if ridge_along == "x":
        ym = (y0 + y1) / 2
        vertices = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (x0, ym, top), (x1, ym, top)]
        polygons = [[0, 3, 2, 1], [0, 1, 5, 4], [2, 3, 4, 5], [0, 4, 3], [1, 2, 5]]
    elif ridge_along == "y":
        xm = (x0 + x1) / 2
        vertices = [(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), (xm, y0, top), (xm, y1, top)]
        polygons = [[0, 3, 2, 1], [1, 2, 5, 4], [3, 0, 4, 5], [0, 1, 4], [2, 3, 5]]
    else:
        raise ValueError(f"ridge_along must be 'x' or 'y', not {ridge_along!r}")
    return np.array(vertices, dtype=np.float64), polygons


def pyramid_roof_mesh(lo, hi, apex_height: float) -> tuple[np.ndarray, list[list[int]]]:
    """A closed pyramid (hip roof, spire) on the rectangle lo..hi at height lo[2], outward normals:
    5 vertices (5, 3) float64, 5 polygons (bottom quad and 4 triangles)."""
    x0, y0, z0 = (float(c) for c in lo)
    x1, y1 = float(hi[0]), float(hi[1])
    apex = ((x0 + x1) / 2, (y0 + y1) / 2, z0 + apex_height)
    vertices = np.array([(x0, y0, z0), (x1, y0, z0), (x1, y1, z0), (x0, y1, z0), apex], dtype=np.float64)
    return vertices, [[0, 3, 2, 1], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


def open_box_mesh(lo, hi) -> tuple[np.ndarray, list[list[int]]]:
    """A box without its bottom face (a lampshade, a hood): 8 vertices (8, 3) float64, 5 quads, outward
    normals."""
    vertices, quads = box_mesh(lo, hi)
    return vertices, quads[1:]


# ---------------------------------------------------------------------------------------------------------
# Assembling a scene.


class SceneBuilder:
    """Collects objects, each with its own vertices, and turns them into a SceneSpec."""

    def __init__(self, name: str):
        self.name = name
        self._vertex_blocks: list[np.ndarray] = []
        self._n_vertices = 0
        self._polygons: list[list[int]] = []
        self._reflectance: list[np.ndarray] = []
        self._emission: list[np.ndarray] = []
        self._object_ids: list[np.ndarray] = []
        self._two_sided: list[np.ndarray] = []
        self.object_names: list[str] = []
        self.object_kinds: list[str] = []

    @property
    def n_polygons(self) -> int:
        return len(self._polygons)

    def add_object(
        self, name: str, kind: str, vertices, polygons, reflectance, emission=(0.0, 0.0, 0.0), two_sided=False
    ) -> int:
        """Append one object; reflectance, emission ((3,) or (p, 3)) and two_sided (bool or (p,)) broadcast
        over its p polygons. Returns the object id."""
        vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        n = len(polygons)
        object_id = len(self.object_names)
        self._polygons.extend([[self._n_vertices + int(i) for i in polygon] for polygon in polygons])
        self._vertex_blocks.append(vertices)
        self._n_vertices += len(vertices)
        self._reflectance.append(np.broadcast_to(np.asarray(reflectance, dtype=np.float64), (n, 3)))
        self._emission.append(np.broadcast_to(np.asarray(emission, dtype=np.float64), (n, 3)))
        self._object_ids.append(np.full(n, object_id, dtype=np.int64))
        self._two_sided.append(np.broadcast_to(np.asarray(two_sided, dtype=bool), (n,)))
        self.object_names.append(name)
        self.object_kinds.append(kind)
        return object_id

    def box(self, name: str, lo, hi, reflectance, yaw: float = 0.0, pivot=None) -> int:
        return self.add_object(name, BOX, *box_mesh(lo, hi, yaw, pivot), reflectance)

    def room(self, name: str, lo, hi, wall=WALL, floor=FLOOR, ceiling=CEILING) -> int:
        vertices, quads = room_mesh(lo, hi)
        return self.add_object(name, ROOM, vertices, quads, [floor, ceiling, wall, wall, wall, wall])

    def panel(self, name: str, centre, normal, width: float, height: float, reflectance, two_sided=True) -> int:
        """A flat rectangle facing `normal` (poster, rug, ground). Two-sided by default, like any open surface
        in Blender and in `Scene.from_polygons`: even a poster's back side, facing its wall, is a surface."""
        vertices, quads = quad_mesh(centre, normal, width, height)
        return self.add_object(name, PANEL, vertices, quads, reflectance, two_sided=two_sided)

    def light(self, name: str, centre, normal, width: float, height: float, exitance, reflectance=LIGHT_HOUSING) -> int:
        """A one-sided emitting rectangle that emits towards `normal`; exitance (3,) W/m^2."""
        vertices, quads = quad_mesh(centre, normal, width, height)
        return self.add_object(name, LIGHT, vertices, quads, reflectance, emission=exitance)

    def spec(self) -> SceneSpec:
        emission = np.concatenate(self._emission) if self._emission else np.zeros((0, 3))
        return SceneSpec(
            name=self.name,
            vertices=np.concatenate(self._vertex_blocks) if self._vertex_blocks else np.zeros((0, 3)),
            polygons=[list(p) for p in self._polygons],
            reflectance=np.concatenate(self._reflectance) if self._reflectance else np.zeros((0, 3)),
            emission=emission,
            object_ids=np.concatenate(self._object_ids) if self._object_ids else np.zeros(0, np.int64),
            two_sided=np.concatenate(self._two_sided) if self._two_sided else np.zeros(0, bool),
            object_names=list(self.object_names),
            lights=np.flatnonzero((emission > 0).any(axis=1)).astype(np.int64),
            object_kinds=list(self.object_kinds),
        )


@dataclass(frozen=True)
class _Frame:
    """Places furniture modelled in a local frame into the world.

    Local frame: footprint [0, width] x [0, depth] on the floor z = 0, the piece's front towards -y.
    World: the footprint turned by quarter_turns x 90 degrees counter-clockwise, its lower corner moved to
    origin (x, y, z).
    """

    origin: tuple[float, float, float]
    width: float
    depth: float
    quarter_turns: int = 0

    def point(self, p) -> np.ndarray:
        x, y, z = (float(c) for c in p)
        w, d = self.width, self.depth
        turned = [(x, y), (d - y, x), (w - x, d - y), (y, w - x)][self.quarter_turns % 4]
        return np.array([turned[0], turned[1], z]) + np.asarray(self.origin, dtype=np.float64)

    def aabb(self, lo, hi) -> tuple[np.ndarray, np.ndarray]:
        a, b = self.point(lo), self.point(hi)
        return np.minimum(a, b), np.maximum(a, b)

    def sub(self, lo, width: float, depth: float, quarter_turns: int = 0) -> _Frame:
        """A frame for a piece standing at local corner lo (x, y, z) of this one, turned further."""
        extent = (width, depth) if quarter_turns % 2 == 0 else (depth, width)
        corner, _ = self.aabb(lo, (lo[0] + extent[0], lo[1] + extent[1], lo[2]))
        return _Frame(tuple(corner), width, depth, self.quarter_turns + quarter_turns)


def _box(b: SceneBuilder, frame: _Frame, name: str, lo, hi, colour) -> int:
    return b.box(name, *frame.aabb(lo, hi), colour)


def _table(b: SceneBuilder, frame: _Frame, name: str, height: float, colour, leg: float = 0.05) -> None:
    """Top + 4 legs (5 boxes) filling the frame's footprint; the top's upper face is at `height`."""
    w, d, top = frame.width, frame.depth, 0.04
    _box(b, frame, f"{name} top", (0, 0, height - top), (w, d, height), colour)
    inset = 0.05
    corners = ((inset, inset), (w - inset - leg, inset), (inset, d - inset - leg), (w - inset - leg, d - inset - leg))
    for i, (x, y) in enumerate(corners):
        _box(b, frame, f"{name} leg {i}", (x, y, 0), (x + leg, y + leg, height - top), colour)


def _chair(b: SceneBuilder, frame: _Frame, name: str, colour, seat_height: float = 0.45) -> None:
    """Seat, 4 legs and a backrest standing on the seat at the back (+y): 6 boxes in the frame's footprint."""
    w, d, leg, seat = frame.width, frame.depth, 0.04, 0.04
    for i, (x, y) in enumerate(((0, 0), (w - leg, 0), (0, d - leg), (w - leg, d - leg))):
        _box(b, frame, f"{name} leg {i}", (x, y, 0), (x + leg, y + leg, seat_height - seat), METAL)
    _box(b, frame, f"{name} seat", (0, 0, seat_height - seat), (w, d, seat_height), colour)
    _box(b, frame, f"{name} back", (0, d - 0.04, seat_height), (w, d, seat_height + 0.45), colour)


def _book_row(b: SceneBuilder, frame: _Frame, name: str, start, count: int, depth: float, first_colour: int) -> float:
    """`count` books standing side by side (touching, coplanar fronts) from local corner start (x, y, z)
    along +x; returns the local x after the last book."""
    x, y, z = start
    for i in range(count):
        k = first_colour + i
        width = 0.025 + 0.01 * (k % 3)
        height = 0.18 + 0.03 * (k % 4)
        _box(
            b, frame, f"{name} {i}", (x, y, z), (x + width, y + depth, z + height), BOOK_COLOURS[k % len(BOOK_COLOURS)]
        )
        x += width
    return x


def _bookshelf(
    b: SceneBuilder, frame: _Frame, name: str, height: float, boards: int, books_per_row: int, colour
) -> None:
    """Two sides on the floor, `boards` boards between them (the lowest on the floor), a top board resting on
    the sides, and a row of books on every board but the highest: 3 + boards + (boards - 1) x books boxes."""
    w, d, side, board = frame.width, frame.depth, 0.03, 0.03
    _box(b, frame, f"{name} side 0", (0, 0, 0), (side, d, height), colour)
    _box(b, frame, f"{name} side 1", (w - side, 0, 0), (w, d, height), colour)
    _box(b, frame, f"{name} top", (0, 0, height), (w, d, height + board), colour)
    spacing = height / boards
    for i in range(boards):
        z = i * spacing
        _box(b, frame, f"{name} board {i}", (side, 0, z), (w - side, d, z + board), colour)
        if i < boards - 1:
            _book_row(b, frame, f"{name} book {i}", (side + 0.02, 0.02, z + board), books_per_row, d - 0.05, 3 * i)


def _desk_lamp(b: SceneBuilder, frame: _Frame, name: str, colour, stem: float = 0.4, reach: float = 0.25) -> np.ndarray:
    """Base, stem, arm reaching towards -y, and a head hanging under the arm's end (4 boxes) in a 0.15 x
    (reach + 0.1) footprint; returns the world centre (3,) of the head's bottom face."""
    d = frame.depth
    _box(b, frame, f"{name} base", (0, d - 0.15, 0), (0.15, d, 0.02), colour)
    _box(b, frame, f"{name} stem", (0.065, d - 0.05, 0.02), (0.085, d - 0.03, 0.02 + stem), colour)
    arm_z = 0.02 + stem
    _box(b, frame, f"{name} arm", (0.065, d - 0.05 - reach, arm_z), (0.085, d - 0.03, arm_z + 0.02), colour)
    head_lo = (0.015, d - 0.05 - reach, arm_z - 0.07)
    _box(b, frame, f"{name} head", head_lo, (0.135, head_lo[1] + 0.12, arm_z), colour)
    return frame.point((0.075, head_lo[1] + 0.06, arm_z - 0.07))


def _pad_with_panels(b: SceneBuilder, target: int, slots: Sequence[tuple]) -> None:
    """Add flat decals (posters, rugs) from `slots` (name, centre, normal, width, height, reflectance) until
    the scene has exactly `target` polygons."""
    missing = target - b.n_polygons
    if missing < 0 or missing > len(slots):
        raise ValueError(f"{b.name}: {b.n_polygons} polygons before decals, cannot reach {target}")
    for slot in slots[:missing]:
        b.panel(*slot)


# ---------------------------------------------------------------------------------------------------------
# Office family (seed 003, Table 1).

_CELL_PITCH = 2.0  # furniture groups stand on a grid of 2 m cells ...
_CELL_SIZE = 1.6  # ... each using a 1.6 m square, so 0.4 m aisles separate them
_WALL_GAP = 0.6  # cells keep this far from the walls; rugs lie in the strip along the wall y = 0
_OFFICE_HEIGHT = 2.7


def _workstation(b: SceneBuilder, frame: _Frame, name: str, k: int) -> None:
    """A table (5 boxes) and a chair facing it (6 boxes)."""
    _table(b, frame.sub((0.1, 0.8, 0), 1.4, 0.7), f"{name} table", 0.74, WOOD if k % 2 == 0 else DARK_WOOD)
    _chair(b, frame.sub((0.55, 0.2, 0), 0.45, 0.45, quarter_turns=2), f"{name} chair", FABRICS[k % len(FABRICS)])


def _shelf_unit(b: SceneBuilder, frame: _Frame, name: str, k: int) -> None:
    """A bookshelf (7 boxes) with 3 rows of 3 books (9 boxes)."""
    _bookshelf(b, frame.sub((0.2, 1.2, 0), 1.2, 0.35), name, 1.8, 4, 3, WOOD if k % 2 else DARK_WOOD)


# Boxes in a cell's local frame. Each rests on the floor or on an earlier box, floats, or touches an earlier
# box side by side with coplanar faces, so any prefix of the list is a valid arrangement.
_CRATES = (
    ((0.1, 0.1, 0.0), (0.6, 0.6, 0.5), 0.0),  # on the floor
    ((0.6, 0.1, 0.0), (1.0, 0.6, 0.5), 0.0),  # touching the first: shared side plane, coplanar tops
    ((0.15, 0.15, 0.5), (0.55, 0.55, 0.85), 0.0),  # stacked on the first
    ((0.65, 0.2, 1.2), (0.95, 0.5, 1.5), 0.0),  # floating above the second
    ((0.2, 0.2, 0.85), (0.5, 0.5, 1.1), 0.0),  # stacked on the stack
    ((1.15, 1.15, 0.0), (1.45, 1.45, 0.4), 0.5),  # on the floor, turned 0.5 rad
    ((0.6, 0.6, 0.0), (1.0, 0.9, 0.3), 0.0),  # touching the second along y
    ((0.65, 0.65, 0.3), (0.95, 0.85, 0.5), 0.0),  # stacked on it, top coplanar with the first two
    ((0.1, 1.0, 1.6), (0.4, 1.3, 1.8), 0.0),  # floating high
    ((0.1, 1.0, 0.0), (0.5, 1.4, 0.6), 0.0),  # on the floor under the floating one
    ((0.1, 1.0, 0.6), (0.3, 1.2, 0.9), 0.0),  # stacked flush with two of its sides (coplanar sides)
    ((0.5, 1.0, 0.0), (0.8, 1.4, 0.6), 0.0),  # touching it side by side, same height
)


def _crates(b: SceneBuilder, frame: _Frame, name: str, k: int, count: int = len(_CRATES)) -> None:
    for i, (lo, hi, yaw) in enumerate(_CRATES[:count]):
        colour = CARDBOARD if (i + k) % 3 else FABRICS[(i + k) % len(FABRICS)]
        b.box(f"{name} box {i}", *frame.aabb(lo, hi), colour, yaw=yaw)


_OFFICE_GROUPS = (("workstation", 11, _workstation), ("shelf", 16, _shelf_unit), ("crates", len(_CRATES), _crates))


def _office_plan(budget: int) -> tuple[list[int], int, int]:
    """Fill `budget` polygons: group indices (cycling through _OFFICE_GROUPS, skipping those that no longer
    fit), then a partial crate cell of budget // 6 boxes, then the remainder (< 6) as decals."""
    plan: list[int] = []
    turn = 0
    while True:
        for shift in range(len(_OFFICE_GROUPS)):
            g = (turn + shift) % len(_OFFICE_GROUPS)
            if 6 * _OFFICE_GROUPS[g][1] <= budget:
                plan.append(g)
                budget -= 6 * _OFFICE_GROUPS[g][1]
                turn = g + 1
                break
        else:
            return plan, budget // 6, budget % 6


def _office_grid(cells: int) -> tuple[int, int]:
    nx = max(1, math.ceil(math.sqrt(cells)))
    return nx, max(1, math.ceil(cells / nx))


def office(n_polygons: int) -> SceneSpec:
    """A closed office with exactly `n_polygons` polygons (one of OFFICE_SIZES; Table 1 of seed 003).

    Furniture groups (workstation = table + chair, bookshelf with books, a cell of crates resting, stacked,
    floating, turned and touching) stand on a grid of 2 m cells, the room growing with n; ceiling lights
    (0.6 m squares 2 cm below the ceiling, facing down, one per 2 x 2 cells) light it. Posters and rugs make
    up the last few polygons.
    """
    if n_polygons not in OFFICE_SIZES:
        raise ValueError(f"office scenes have {OFFICE_SIZES} polygons, not {n_polygons}")
    # The grid depends on the furniture, the furniture budget on the number of lights, the lights on the grid.
    n_lights = 1
    for _ in range(10):
        plan, crate_count, decals = _office_plan(n_polygons - 6 - n_lights)
        nx, ny = _office_grid(len(plan) + (crate_count > 0))
        lights_x, lights_y = math.ceil(nx / 2), math.ceil(ny / 2)
        if lights_x * lights_y == n_lights:
            break
        n_lights = lights_x * lights_y
    else:
        raise RuntimeError(f"office({n_polygons}): no consistent furniture and light layout")

    size_x = 2 * _WALL_GAP + nx * _CELL_PITCH - (_CELL_PITCH - _CELL_SIZE)
    size_y = 2 * _WALL_GAP + ny * _CELL_PITCH - (_CELL_PITCH - _CELL_SIZE)
    b = SceneBuilder(f"office-{n_polygons}")
    b.room("room", (0, 0, 0), (size_x, size_y, _OFFICE_HEIGHT))
    for i in range(lights_x):
        for j in range(lights_y):
            centre = (size_x * (i + 0.5) / lights_x, size_y * (j + 0.5) / lights_y, _OFFICE_HEIGHT - 0.02)
            b.light(f"ceiling light {i},{j}", centre, DOWN, 0.6, 0.6, 40.0 * WARM_WHITE)

    def cell_frame(index: int) -> _Frame:
        i, j = index % nx, index // nx
        return _Frame((_WALL_GAP + i * _CELL_PITCH, _WALL_GAP + j * _CELL_PITCH, 0.0), _CELL_SIZE, _CELL_SIZE)

    for index, g in enumerate(plan):
        group_name, _, build_group = _OFFICE_GROUPS[g]
        build_group(b, cell_frame(index), f"{group_name} {index}", index)
    if crate_count:
        _crates(b, cell_frame(len(plan)), f"crates {len(plan)}", len(plan), crate_count)

    poster = (0.45, 0.5, 0.6)
    slots = [
        ("rug 0", (size_x * 0.3, 0.3, 0.0), UP, 1.2, 0.4, FABRICS[1]),  # exactly on the floor
        ("poster 0", (size_x * 0.3, size_y - 0.001, 1.6), (0, -1, 0), 0.6, 0.8, poster),  # 1 mm off the wall
        ("poster 1", (0.0, size_y * 0.5, 1.5), (1, 0, 0), 0.5, 0.7, FABRICS[3]),  # exactly on the wall
        ("rug 1", (size_x * 0.7, 0.3, 0.001), UP, 1.0, 0.4, FABRICS[0]),  # 1 mm above the floor
        ("poster 2", (size_x - 0.001, size_y * 0.5, 1.5), (-1, 0, 0), 0.8, 0.6, poster),
    ]
    _pad_with_panels(b, b.n_polygons + decals, slots)
    return b.spec()


# ---------------------------------------------------------------------------------------------------------
# Seed 000, section 7.2: Desk, Many Lights, Indirect (bedroom), Village.

_DESK_ROOM = (6.0, 5.0, 2.7)
DESK_POLYGONS = 444


def _desk_builder(name: str, large_light_exitance: float) -> tuple[SceneBuilder, np.ndarray]:
    """The Desk geometry and its two large lights; also returns the desk lamp's head bottom centre (3,)."""
    sx, sy, sz = _DESK_ROOM
    b = SceneBuilder(name)
    b.room("room", (0, 0, 0), (sx, sy, sz))
    for i, x in enumerate((2.0, 4.0)):
        b.light(f"ceiling light {i}", (x, 2.5, sz - 0.02), DOWN, 1.2, 0.6, large_light_exitance * WARM_WHITE)

    # The desk against the back wall, front (user side) towards -y: a 3-drawer pedestal, two legs, a top.
    desk = _Frame((1.5, 4.1, 0.0), 1.8, 0.8)
    for i in range(3):
        _box(b, desk, f"desk drawer {i}", (0.03, 0.05, 0.24 * i), (0.48, 0.75, 0.24 * (i + 1)), WOOD)
    for i, y in enumerate((0.05, 0.7)):
        _box(b, desk, f"desk leg {i}", (1.72, y, 0), (1.77, y + 0.05, 0.72), METAL)
    _box(b, desk, "desk top", (0, 0, 0.72), (1.8, 0.8, 0.76), WOOD)

    on_desk = _Frame((1.5, 4.1, 0.76), 1.8, 0.8)
    for k, x in enumerate((0.45, 1.05)):
        _box(b, on_desk, f"monitor {k} base", (x, 0.5, 0), (x + 0.25, 0.68, 0.02), DARK_PLASTIC)
        _box(b, on_desk, f"monitor {k} neck", (x + 0.1, 0.56, 0.02), (x + 0.15, 0.6, 0.14), DARK_PLASTIC)
        _box(b, on_desk, f"monitor {k} screen", (x - 0.15, 0.55, 0.14), (x + 0.4, 0.6, 0.49), DARK_PLASTIC)
    _box(b, on_desk, "keyboard", (0.5, 0.12, 0), (0.95, 0.27, 0.02), DARK_PLASTIC)
    _box(b, on_desk, "mouse", (1.05, 0.15, 0), (1.11, 0.25, 0.03), DARK_PLASTIC)
    _box(b, on_desk, "mug", (1.25, 0.15, 0), (1.33, 0.23, 0.1), FABRICS[3])
    _box(b, on_desk, "phone", (1.4, 0.12, 0), (1.55, 0.3, 0.04), DARK_PLASTIC)
    _box(b, on_desk, "pencil box", (0.3, 0.1, 0), (0.4, 0.2, 0.08), FABRICS[0])
    lamp_head = _desk_lamp(b, on_desk.sub((1.55, 0.4, 0), 0.15, 0.35), "desk lamp", FABRICS[2], stem=0.45, reach=0.2)
    for i in range(4):  # a stack of books, each a little smaller than the one below
        inset = 0.01 * i
        lo, hi = (0.02 + inset, 0.05 + inset, 0.03 * i), (0.26 - inset, 0.22 - inset, 0.03 * (i + 1))
        _box(b, on_desk, f"book stack {i}", lo, hi, BOOK_COLOURS[i])
    _box(b, on_desk, "bookend 0", (0.02, 0.5, 0), (0.03, 0.7, 0.2), METAL)
    end = _book_row(b, on_desk, "desk book", (0.03, 0.52, 0), 6, 0.16, 1)
    _box(b, on_desk, "bookend 1", (end, 0.5, 0), (end + 0.01, 0.7, 0.2), METAL)

    _chair(b, _Frame((2.15, 3.45, 0.0), 0.5, 0.5, quarter_turns=2), "desk chair", FABRICS[1])
    _box(b, _Frame((1.0, 4.4, 0.0), 0.3, 0.3), "waste bin", (0, 0, 0), (0.3, 0.3, 0.35), DARK_PLASTIC)

    # A filing cabinet (3 stacked drawers) with a plant on it, right of the desk.
    cabinet = _Frame((3.5, 4.3, 0.0), 0.45, 0.6)
    for i in range(3):
        _box(b, cabinet, f"cabinet drawer {i}", (0, 0, 0.25 * i), (0.45, 0.6, 0.25 * (i + 1)), METAL)
    _box(b, cabinet, "plant pot", (0.1, 0.15, 0.75), (0.35, 0.4, 0.95), CARDBOARD)
    _box(b, cabinet, "plant", (0.05, 0.1, 0.95), (0.4, 0.45, 1.35), FABRICS[2])

    # A bookshelf against the left wall, its open side facing the room (+x).
    _bookshelf(b, _Frame((0.0, 1.2, 0.0), 1.2, 0.35, quarter_turns=1), "bookshelf", 1.8, 4, 3, DARK_WOOD)

    # A meeting table with one chair.
    _table(b, _Frame((3.5, 1.2, 0.0), 1.4, 0.9), "meeting table", 0.74, WOOD)
    _chair(b, _Frame((3.95, 0.6, 0.0), 0.45, 0.45, quarter_turns=2), "meeting chair", FABRICS[4])
    return b, lamp_head


def _desk_decals(sx: float, sy: float) -> list[tuple]:
    return [
        ("whiteboard", (sx, 2.5, 1.5), (-1, 0, 0), 1.6, 1.0, PAPER),  # exactly on the right wall
        ("window", (3.0, 0.001, 1.6), (0, 1, 0), 1.5, 1.0, (0.15, 0.2, 0.3)),  # 1 mm off the front wall
        ("poster", (0.8, sy - 0.001, 1.7), (0, -1, 0), 0.5, 0.7, FABRICS[3]),
        ("rug", (2.5, 2.4, 0.0), UP, 1.6, 1.0, FABRICS[0]),  # exactly on the floor, clear of all legs
        ("calendar", (4.9, sy, 1.5), (0, -1, 0), 0.3, 0.4, PAPER),
    ]


def desk() -> SceneSpec:
    """Seed 000's "Desk": an office with a desk, monitors, a lamp, books, shelves, a meeting table and chairs,
    lit by 2 large (1.2 x 0.6 m) ceiling lights. Exactly 444 polygons."""
    b, _ = _desk_builder("desk", large_light_exitance=60.0)
    _pad_with_panels(b, DESK_POLYGONS, _desk_decals(*_DESK_ROOM[:2]))
    return b.spec()


def many_lights() -> SceneSpec:
    """Seed 000's "Many Lights": the Desk geometry with its large lights turned down and 8 small bright lights
    added (one under the desk lamp's head, seven 0.12 m ceiling spots). 452 polygons: the paper's version has
    492, its small lights were probably not single quads."""
    b, lamp_head = _desk_builder("many-lights", large_light_exitance=20.0)
    _pad_with_panels(b, DESK_POLYGONS, _desk_decals(*_DESK_ROOM[:2]))
    b.light("lamp light", lamp_head - (0, 0, 0.001), DOWN, 0.1, 0.1, 600.0 * WARM_WHITE)
    sz = _DESK_ROOM[2]
    spots = ((0.7, 0.7), (0.7, 4.3), (3.0, 1.0), (3.0, 4.0), (5.3, 0.7), (5.3, 4.3), (3.0, 2.5))
    for i, (x, y) in enumerate(spots):
        b.light(f"ceiling light spot {i}", (x, y, sz - 0.01), DOWN, 0.12, 0.12, 800.0 * WARM_WHITE)
    return b.spec()


BEDROOM_POLYGONS = 534


def _lamp_with_shade(b: SceneBuilder, frame: _Frame, name: str, lit: bool) -> None:
    """A bedside lamp on a 0.3 x 0.45 footprint: base, stem and arm (boxes) and a lampshade open at the
    bottom (5 two-sided quads) hanging under the arm's end; if `lit`, a 0.12 m emitting quad inside the shade,
    2 cm under its top, faces down, so only the cone below the shade's rim receives direct light."""
    _box(b, frame, f"{name} base", (0.08, 0.31, 0), (0.22, 0.45, 0.02), METAL)
    _box(b, frame, f"{name} stem", (0.14, 0.39, 0.02), (0.16, 0.41, 0.4), METAL)
    _box(b, frame, f"{name} arm", (0.14, 0.1, 0.4), (0.16, 0.41, 0.42), METAL)
    vertices, quads = open_box_mesh(*frame.aabb((0.05, 0.05, 0.25), (0.25, 0.25, 0.4)))
    b.add_object(f"{name} shade", OPEN, vertices, quads, (0.75, 0.7, 0.55), two_sided=True)
    if lit:
        centre = frame.point((0.15, 0.15, 0.38))
        b.light(f"{name} light", centre, DOWN, 0.12, 0.12, 1500.0 * WARM_WHITE)


def _night_stand(b: SceneBuilder, frame: _Frame, name: str) -> None:
    """Carcass on 4 legs, 2 drawer fronts stacked on its front face, 2 handles: 9 boxes."""
    w, d, leg = frame.width, frame.depth, 0.04
    for i, (x, y) in enumerate(((0, 0), (w - leg, 0), (0, d - leg), (w - leg, d - leg))):
        _box(b, frame, f"{name} leg {i}", (x, y, 0), (x + leg, y + leg, 0.1), DARK_WOOD)
    _box(b, frame, f"{name} carcass", (0, 0.02, 0.1), (w, d, 0.55), WOOD)
    for i, (z0, z1) in enumerate(((0.12, 0.32), (0.32, 0.53))):
        _box(b, frame, f"{name} drawer {i}", (0.02, 0.0, z0), (w - 0.02, 0.02, z1), WOOD)
        _box(b, frame, f"{name} handle {i}", (w / 2 - 0.05, -0.02, z1 - 0.06), (w / 2 + 0.05, 0.0, z1 - 0.04), METAL)


def indirect_bedroom() -> SceneSpec:
    """Seed 000's "Indirect": a bedroom (bed, two night stands, wardrobe, chest of drawers, desk, wall shelves
    with books) lit only by one small bedside lamp that emits downwards inside its shade, so almost every
    surface is lit indirectly. Exactly 534 polygons."""
    sx, sy, sz = 4.5, 4.0, 2.6
    b = SceneBuilder("indirect-bedroom")
    b.room("room", (0, 0, 0), (sx, sy, sz))

    # Bed against the back wall (y = sy): headboard, base on 4 legs, mattress, blanket, 2 pillows.
    b.box("headboard", (1.45, 3.92, 0.0), (3.05, 4.0, 1.0), DARK_WOOD)
    for i, (x, y) in enumerate(((1.45, 1.92), (3.0, 1.92), (1.45, 3.87), (3.0, 3.87))):
        b.box(f"bed leg {i}", (x, y, 0.0), (x + 0.05, y + 0.05, 0.1), DARK_WOOD)
    b.box("bed base", (1.45, 1.92, 0.1), (3.05, 3.92, 0.35), WOOD)
    b.box("mattress", (1.5, 1.97, 0.35), (3.0, 3.87, 0.55), PAPER)
    b.box("blanket", (1.5, 1.97, 0.55), (3.0, 3.2, 0.6), FABRICS[1])
    b.box("pillow 0", (1.6, 3.4, 0.55), (2.25, 3.8, 0.67), PAPER)
    b.box("pillow 1", (2.25, 3.4, 0.55), (2.9, 3.8, 0.67), PAPER)

    # Night stands touching the bed base on both sides, fronts towards -y; a lamp on each, the left one lit.
    for k, x in enumerate((0.95, 3.05)):
        stand = _Frame((x, 3.45, 0.0), 0.5, 0.5)
        _night_stand(b, stand, f"night stand {k}")
        _lamp_with_shade(b, _Frame((x + 0.1, 3.47, 0.55), 0.3, 0.45), f"lamp {k}", lit=k == 0)
    _book_row(b, _Frame((3.1, 3.5, 0.55), 0.1, 0.2), "night stand book", (0, 0, 0), 3, 0.16, 2)

    # Wardrobe against the left wall, doors facing the room (+x).
    b.box("wardrobe", (0.0, 0.3, 0.0), (0.6, 1.5, 2.0), WOOD)
    for i, (y0, y1) in enumerate(((0.32, 0.9), (0.9, 1.48))):
        b.box(f"wardrobe door {i}", (0.6, y0, 0.05), (0.62, y1, 1.95), WOOD)
        handle_y = y1 - 0.08 if i == 0 else y0 + 0.05
        b.box(f"wardrobe handle {i}", (0.62, handle_y, 0.95), (0.64, handle_y + 0.03, 1.15), METAL)
    b.box("wardrobe cornice", (0.0, 0.28, 2.0), (0.65, 1.52, 2.06), DARK_WOOD)
    b.box("suitcase 0", (0.05, 0.4, 2.06), (0.55, 1.0, 2.26), FABRICS[4])
    b.box("suitcase 1", (0.1, 0.5, 2.26), (0.5, 0.9, 2.4), FABRICS[1])
    b.box("storage box 0", (0.05, 1.6, 0.0), (0.45, 2.0, 0.35), CARDBOARD)
    b.box("storage box 1", (0.05, 2.0, 0.0), (0.45, 2.4, 0.35), FABRICS[3])  # touching the first
    b.box("storage box 2", (0.1, 1.7, 0.35), (0.4, 2.1, 0.6), CARDBOARD)  # stacked across both

    # Desk against the right wall with a chair, a laptop and a book stack; two wall shelves of books above.
    desk_frame = _Frame((3.8, 0.5, 0.0), 0.7, 1.2)
    _table(b, desk_frame, "desk", 0.74, WOOD)
    _chair(b, _Frame((3.25, 0.9, 0.0), 0.45, 0.45, quarter_turns=1), "desk chair", FABRICS[0])
    b.box("laptop base", (3.95, 0.8, 0.74), (4.25, 1.15, 0.76), METAL)
    b.box("laptop screen", (4.25, 0.8, 0.76), (4.27, 1.15, 0.98), DARK_PLASTIC)
    for i in range(3):
        b.box(
            f"desk book {i}",
            (3.95 + 0.01 * i, 1.3, 0.74 + 0.03 * i),
            (4.2, 1.6 - 0.01 * i, 0.77 + 0.03 * i),
            BOOK_COLOURS[i],
        )
    for k, z in enumerate((1.3, 1.7)):
        shelf = _Frame((4.25, 0.6, z), 1.0, 0.25, quarter_turns=3)
        _box(b, shelf, f"wall shelf {k}", (0, 0, 0), (1.0, 0.25, 0.02), DARK_WOOD)
        _book_row(b, shelf, f"wall shelf {k} book", (0.05, 0.05, 0.02), 6, 0.18, 2 * k)

    # Chest of drawers against the front wall, drawers facing the room (+y).
    chest = _Frame((1.5, 0.0, 0.0), 1.2, 0.5, quarter_turns=2)
    _box(b, chest, "chest", (0, 0.02, 0), (1.2, 0.5, 0.8), WOOD)
    for i in range(3):
        z0 = 0.02 + 0.26 * i
        _box(b, chest, f"chest drawer {i}", (0.02, 0.0, z0), (1.18, 0.02, z0 + 0.25), WOOD)
        _box(b, chest, f"chest handle {i}", (0.5, -0.02, z0 + 0.17), (0.7, 0.0, z0 + 0.2), METAL)
    _box(b, chest, "jewel box", (0.1, 0.15, 0.8), (0.3, 0.3, 0.9), FABRICS[4])

    slots = [
        ("rug", (2.25, 1.3, 0.0), UP, 1.4, 0.8, FABRICS[0]),  # exactly on the floor
        ("picture", (2.25, sy - 0.001, 1.6), (0, -1, 0), 0.8, 0.5, FABRICS[2]),  # 1 mm off the wall
        ("window", (2.1, 0.0, 1.6), (0, 1, 0), 1.2, 0.9, (0.15, 0.2, 0.3)),  # exactly on the wall
        ("mirror", (sx - 0.001, 2.8, 1.5), (-1, 0, 0), 0.5, 0.9, (0.6, 0.62, 0.65)),
        ("poster", (0.0, 3.0, 1.6), (1, 0, 0), 0.5, 0.7, FABRICS[3]),
    ]
    _pad_with_panels(b, BEDROOM_POLYGONS, slots)
    return b.spec()


VILLAGE_POLYGONS = 312


def _house(b: SceneBuilder, name: str, lo, size, roof: str, colour, roof_colour=(0.5, 0.2, 0.15)) -> None:
    """A box body on the ground and a closed roof (gable prism along x or y, or pyramid) resting on it."""
    hi = np.asarray(lo, dtype=np.float64) + size
    b.box(f"{name} body", lo, hi, colour)
    roof_lo = (lo[0], lo[1], hi[2])
    pitch = 0.4 * min(size[0], size[1])
    if roof == "pyramid":
        b.add_object(f"{name} roof", SOLID, *pyramid_roof_mesh(roof_lo, hi, pitch), roof_colour)
    else:
        b.add_object(f"{name} roof", SOLID, *gable_roof_mesh(roof_lo, hi, pitch, ridge_along=roof), roof_colour)


def _car(b: SceneBuilder, name: str, centre_xy, heading: float, colour) -> None:
    """A 4.2 x 1.8 m body resting on the ground and a cabin on it, turned together by `heading`."""
    cx, cy = centre_xy
    b.box(f"{name} body", (cx - 2.1, cy - 0.9, 0.0), (cx + 2.1, cy + 0.9, 0.8), colour, yaw=heading)
    b.box(
        f"{name} cabin",
        (cx - 1.2, cy - 0.8, 0.8),
        (cx + 0.8, cy + 0.8, 1.4),
        (0.2, 0.22, 0.25),
        yaw=heading,
        pivot=(cx, cy),
    )


def village() -> SceneSpec:
    """Seed 000's "Village": an open 60 m square of ground (one two-sided quad), two rows of houses with
    gable or pyramid roofs, a garage touching a house, a church tower with a spire, trees and cars on the
    street, lit by a 30 m square emitting quad 40 m overhead, facing down. Exactly 312 polygons."""
    b = SceneBuilder("village")
    b.panel("ground", (0.0, 0.0, 0.0), UP, 60.0, 60.0, (0.35, 0.4, 0.3))
    b.light("sky light", (0.0, 0.0, 40.0), DOWN, 30.0, 30.0, 60.0 * np.array([1.0, 0.97, 0.92]), reflectance=(0, 0, 0))

    walls = ((0.75, 0.7, 0.6), (0.65, 0.6, 0.55), (0.7, 0.55, 0.45), (0.6, 0.62, 0.6))
    roofs = ("x", "y", "pyramid")
    # (x, width) of the lots; the street runs along x between y = -8 and y = 8.
    north_lots = ((-27.0, 6.0), (-19.0, 7.0), (-10.0, 8.0), (3.5, 6.0), (11.5, 7.0), (20.5, 7.0))
    south_lots = ((-26.0, 7.0), (-17.0, 6.0), (-9.0, 8.0), (1.0, 6.0), (9.0, 7.0), (25.0, 4.5))
    for i, (x, width) in enumerate(north_lots):
        depth, height = 6.0 + i % 2, 3.0 + 1.5 * (i % 2)
        _house(b, f"north house {i}", (x, 8.0, 0.0), (width, depth, height), roofs[i % 3], walls[i % 4])
    for i, (x, width) in enumerate(south_lots):
        depth, height = 7.0 - i % 2, 4.5 - 1.5 * (i % 2)
        lo = (x, -8.0 - depth, 0.0)
        _house(b, f"south house {i}", lo, (width, depth, height), roofs[(i + 1) % 3], walls[(i + 2) % 4])
    b.box("garage", (-2.0, 9.0, 0.0), (1.5, 15.0, 2.5), walls[3])  # flat roof, touching north house 2
    b.box("church tower", (18.0, -13.0, 0.0), (23.0, -8.0, 12.0), (0.7, 0.68, 0.62))
    spire = pyramid_roof_mesh((18.0, -13.0, 12.0), (23.0, -8.0, 12.0), 8.0)
    b.add_object("church spire", SOLID, *spire, (0.3, 0.32, 0.35))

    for i, tx in enumerate((-18.0, -8.0, 2.0, 12.0, -13.0)):
        ty = 5.8 if i < 4 else -5.8
        b.box(f"tree {i} trunk", (tx - 0.2, ty - 0.2, 0.0), (tx + 0.2, ty + 0.2, 2.5), DARK_WOOD)
        b.box(f"tree {i} crown", (tx - 1.2, ty - 1.2, 2.5), (tx + 1.2, ty + 1.2, 5.0), (0.2, 0.42, 0.18))

    cars = (
        ((-20.0, 2.0), 0.0),
        ((-12.0, 2.0), 0.0),
        ((1.0, 2.0), 0.0),
        ((15.0, 2.2), 0.25),
        ((-16.0, -2.2), -0.2),
        ((-3.0, -2.0), math.pi),
        ((5.0, -2.0), math.pi),
        ((17.0, -2.0), math.pi),
    )
    for i, (centre, heading) in enumerate(cars):
        _car(b, f"car {i}", centre, heading, FABRICS[i % len(FABRICS)])

    slots = [(f"crossing stripe {i}", (7.5 + 0.9 * i, 0.0, 0.0), UP, 0.5, 6.0, PAPER) for i in range(6)]
    _pad_with_panels(b, VILLAGE_POLYGONS, slots)
    return b.spec()


# ---------------------------------------------------------------------------------------------------------
# Cornell box (bench/data/cornell_box.json, a copy of shared/data/cornell_box.json).


def cornell_box(z_up: bool = True) -> SceneSpec:
    """The published Cornell box: 15 quads (floor, ceiling, back, right (green), left (red) walls and the
    two blocks' tops and sides) and the light quad, in metres, 16 polygons.

    Reflectances and emission are the file's RGB band averages (its recommended reduction; the light's
    emission (17.0, 11.8, 4.0) is used as exitance). Vertex order, the slightly non-planar left wall and
    the light's position (coplanar with the ceiling, facing down) are kept exactly as published. The
    data is y up; with z_up the points are turned by the proper rotation (x, y, z) -> (-x, z, y), which
    keeps every normal's side, so the camera looks along +y and the red wall stays on its left.
    The walls and blocks are one-sided: their back sides face out of the box or into the blocks.
    """
    if not CORNELL_BOX_JSON.is_file():
        raise FileNotFoundError(
            f"Cornell box data not found at {CORNELL_BOX_JSON}: restore bench/data/cornell_box.json "
            "(a copy of the steering repository's shared/data/cornell_box.json)"
        )
    data = json.loads(CORNELL_BOX_JSON.read_text())
    if data["units"]["length"] != "mm":
        raise ValueError(f"{CORNELL_BOX_JSON}: expected lengths in mm, found {data['units']['length']!r}")

    def metres(points) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64) / 1000.0
        return np.column_stack([0.0 - p[:, 0], p[:, 2], p[:, 1]]) if z_up else p

    b = SceneBuilder("cornell-box")
    groups: dict[str, list[dict]] = {}
    for surface in data["surfaces"]:
        name = surface["name"]
        groups.setdefault(name.rsplit("_", 1)[0] if "_block_" in name else name, []).append(surface)
    for name, surfaces in groups.items():
        vertices = np.concatenate([metres(s["vertices_mm"]) for s in surfaces])
        polygons, start = [], 0
        for s in surfaces:
            polygons.append(list(range(start, start + len(s["vertices_mm"]))))
            start += len(s["vertices_mm"])
        kind = OPEN if len(surfaces) > 1 else PANEL
        b.add_object(name, kind, vertices, polygons, [s["reflectance_rgb_band_avg"] for s in surfaces])
    light = data["light"]
    b.add_object(
        "light",
        LIGHT,
        metres(light["vertices_mm"]),
        [[0, 1, 2, 3]],
        light["reflectance_rgb_band_avg"],
        emission=light["emission_rgb_band_avg"],
    )
    return b.spec()


# ---------------------------------------------------------------------------------------------------------
# Random closed rooms for robustness tests.


def _overlap_volume(lo_a, hi_a, lo_b, hi_b) -> float:
    return float(np.prod(np.clip(np.minimum(hi_a, hi_b) - np.maximum(lo_a, lo_b), 0.0, None)))


def _supports(below: tuple[np.ndarray, np.ndarray], above: tuple[np.ndarray, np.ndarray]) -> bool:
    """Whether box `above` (lo, hi) rests on box `below`: its bottom on the other's top, footprints overlapping."""
    overlap = np.minimum(below[1][:2], above[1][:2]) - np.maximum(below[0][:2], above[0][:2])
    return bool(below[1][2] == above[0][2] and (overlap > 0).all())


def closed_furnished_room(seed: int, n_boxes: int = 16) -> SceneSpec:
    """A random closed room (3-6 m x 3-6 m x 2.4-3.2 m) with `n_boxes` axis-aligned boxes: resting on the
    floor, stacked on another box, floating, or touching another box side by side on a shared plane (often
    with coplanar tops, bottoms or sides). Coordinates lie on a 5 cm grid so that coincidences are exact.
    No box interpenetrates another or the walls (touching is allowed); there is no emission (the caller
    picks the lights). Deterministic in `seed`."""
    rng = np.random.default_rng(seed)
    grid = 0.05

    def snap(value):
        return np.round(np.asarray(value, dtype=np.float64) / grid) * grid

    room_hi = snap([rng.uniform(3, 6), rng.uniform(3, 6), rng.uniform(2.4, 3.2)])
    boxes: list[tuple[np.ndarray, np.ndarray]] = []
    kinds = ["floor", "stacked", "beside", "floating"]

    def propose(kind: str) -> tuple[np.ndarray, np.ndarray]:
        size = snap(rng.uniform([0.2, 0.2, 0.15], [1.0, 1.0, 0.9]))
        if kind in ("floor", "floating") or not boxes:
            lo = snap(rng.uniform(0, room_hi - size))
            if kind != "floating":
                lo[2] = 0.0
            return lo, lo + size
        base_lo, base_hi = boxes[rng.integers(len(boxes))]
        if kind == "stacked":
            size[:2] = np.minimum(size[:2], base_hi[:2] - base_lo[:2])
            lo = snap(rng.uniform(base_lo, np.maximum(base_lo, base_hi - size)))
            lo[2] = base_hi[2]
            return lo, lo + size
        axis, side = rng.integers(2), rng.integers(2)
        other = 1 - axis
        lo = base_lo.copy()
        lo[axis] = base_hi[axis] if side else base_lo[axis] - size[axis]
        if rng.random() < 0.5:  # otherwise flush with the base's side: coplanar faces
            lo[other] = snap(rng.uniform(base_lo[other] - size[other] / 2, base_hi[other] - size[other] / 2))
        if rng.random() < 0.5:
            size[2] = base_hi[2] - base_lo[2]  # same height: coplanar tops
        return lo, lo + size

    attempts = 0
    while len(boxes) < n_boxes:
        attempts += 1
        if attempts > 1000 * n_boxes:
            raise RuntimeError(f"closed_furnished_room({seed}): could not place {n_boxes} boxes")
        kind = kinds[len(boxes)] if len(boxes) < len(kinds) else kinds[rng.integers(len(kinds))]
        lo, hi = propose(kind)
        if (lo < 0).any() or (hi > room_hi + 1e-9).any() or (hi - lo <= 0).any():
            continue
        if any(_overlap_volume(lo, hi, other_lo, other_hi) > 0 for other_lo, other_hi in boxes):
            continue
        if kind == "floating" and (lo[2] == 0 or any(_supports(other, (lo, hi)) for other in boxes)):
            continue
        boxes.append((lo, hi))

    b = SceneBuilder(f"closed-furnished-room-{seed}")
    b.room("room", (0.0, 0.0, 0.0), room_hi)
    for i, (lo, hi) in enumerate(boxes):
        b.box(f"box {i}", lo, hi, rng.uniform(0.15, 0.85, size=3))
    return b.spec()


SCENES: dict[str, Callable[[], SceneSpec]] = {
    **{f"office-{n}": partial(office, n) for n in OFFICE_SIZES},
    "desk": desk,
    "many-lights": many_lights,
    "indirect-bedroom": indirect_bedroom,
    "village": village,
    "cornell-box": cornell_box,
}
