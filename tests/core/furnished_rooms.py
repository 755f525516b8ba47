"""Closed rooms furnished with boxes, written for the tests: resting, stacked, floating, touching, coplanar."""

import numpy as np


def box_quads(lo, hi):
    """Corners (8, 3) and the 6 outward-facing quads (local indices) of an axis-aligned box."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    corners = np.array(
        [[x0, y0, z0], [x1, y0, z0], [x1, y1, z0], [x0, y1, z0],
         [x0, y0, z1], [x1, y0, z1], [x1, y1, z1], [x0, y1, z1]], dtype=float,
    )
    quads = [[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]]
    return corners, quads


def _overlap(a_lo, a_hi, b_lo, b_hi):
    return bool(np.all(np.minimum(a_hi, b_hi) - np.maximum(a_lo, b_lo) > 0.0))


def furnished_room(seed: int, n_boxes: int = 8):
    """A closed room (inward normals) with boxes; returns (vertices, polygons, boxes [(lo, hi)], size)."""
    rng = np.random.default_rng(seed)
    size = np.array([rng.uniform(3, 6), rng.uniform(3, 6), rng.uniform(2.5, 3.5)])
    boxes = []

    def free(lo, hi):
        if np.any(lo < 0.0) or np.any(hi > size):
            return False
        return not any(_overlap(lo, hi, b_lo, b_hi) for b_lo, b_hi in boxes)

    attempts = 0
    while len(boxes) < n_boxes and attempts < 2000:
        attempts += 1
        kind = rng.integers(5) if boxes else 0
        extent = rng.uniform([0.3, 0.3, 0.2], [1.2, 1.2, 1.0])
        if kind == 0:  # resting on the floor
            lo = np.array([rng.uniform(0, size[0] - extent[0]), rng.uniform(0, size[1] - extent[1]), 0.0])
        elif kind == 1:  # stacked on another box
            b_lo, b_hi = boxes[rng.integers(len(boxes))]
            lo = np.array([rng.uniform(b_lo[0] - 0.2, b_hi[0] - 0.1), rng.uniform(b_lo[1] - 0.2, b_hi[1] - 0.1),
                           b_hi[2]])
        elif kind == 2:  # floating
            lo = np.array([rng.uniform(0, size[0] - extent[0]), rng.uniform(0, size[1] - extent[1]),
                           rng.uniform(0.3, size[2] - extent[2] - 0.1)])
        elif kind == 3:  # touching another box side by side, same height: coplanar tops and bottoms
            b_lo, b_hi = boxes[rng.integers(len(boxes))]
            extent[2] = b_hi[2] - b_lo[2]
            lo = np.array([b_hi[0], rng.uniform(b_lo[1] - 0.3, b_hi[1] - 0.1), b_lo[2]])
        else:  # against a wall
            lo = np.array([0.0, rng.uniform(0, size[1] - extent[1]), rng.uniform(0.0, 1.0) * (rng.random() < 0.5)])
        hi = lo + extent
        if free(lo, hi):
            boxes.append((lo, hi))

    vertices = []
    polygons = []
    # the room: the box turned inside out so its normals point inwards
    corners, quads = box_quads(np.zeros(3), size)
    vertices.extend(corners)
    polygons.extend([list(reversed(q)) for q in quads])
    for lo, hi in boxes:
        corners, quads = box_quads(lo, hi)
        base = len(vertices)
        vertices.extend(corners)
        polygons.extend([[base + i for i in q] for q in quads])
    return np.array(vertices), polygons, boxes, size


def free_points(boxes, size, count: int, rng, margin: float = 1e-3):
    """Random points inside the room and outside every box, at least `margin` from any surface."""
    points = []
    while len(points) < count:
        p = rng.uniform(margin, size - margin)
        if all(np.any(p < lo - margin) or np.any(p > hi + margin) for lo, hi in boxes):
            points.append(p)
    return np.array(points)
