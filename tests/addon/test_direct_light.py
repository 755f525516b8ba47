"""Issue 6 acceptance: direct light at the result vertices is exact. After a Bake with Max Bounces 1, every
vertex of every result mesh satisfies  pi x visrad_radiance = rho sum_l E_l F_l  within float32 precision.

The scene: a tilted square area light above, a rectangular area light with colour and exposure below, a
floating closed box and, between them, a floating open plane (two-sided: its top is lit by the upper light
and shadowed by the box, its underside by the lower light). The reference is computed independently of the
add-on's conversion and of the solver: the polygons are read from the Blender meshes and the light corners
from the lights' transforms here, E_l from the Blender light by DESIGN.md section 2 (E = C P 2^x / A), and the
form factors by core.visibility.exact_form_factors (exact occluded point-to-polygon form factors, validated
against the closed-room identity and an independent polygon-clipping oracle in tests/core). The result
vertices are those of the Blender result meshes (float32 positions): the back side of the plane, written
SIDE_GAP behind the front, is put back onto the plane.
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from mathutils import Vector  # noqa: E402
from visrad.core.scene import Scene  # noqa: E402
from visrad.core.visibility import exact_form_factors  # noqa: E402
from visrad.visrad_addon.write_back import RADIANCE_ATTRIBUTE, RESULT_SUFFIX  # noqa: E402

from tests.addon.blender_scenes import area_light, box, diffuse_material, grid  # noqa: E402

PLANE_RHO = (0.8, 0.5, 0.2)
BOX_RHO = (0.3, 0.6, 0.45)
PLANE_HEIGHT = 0.3


@pytest.fixture(scope="module")
def baked(registered_addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    plane = grid("Plane", (-0.8, -0.8, PLANE_HEIGHT), (1.6, 0, 0), (0, 1.6, 0), 2, diffuse_material("plane", PLANE_RHO))
    cube = box("Box", (-0.25, -0.2, 0.7), (0.15, 0.2, 1.0), diffuse_material("box", BOX_RHO))
    area_light("Top", size=0.6, power=80.0, location=(0.1, 0.05, 1.8), rotation=(0.3, -0.15, 0.0))
    bottom = area_light("Bottom", size=0.4, power=30.0, location=(0.3, 0.2, -0.6), rotation=(math.pi - 0.2, 0.0, 0.0))
    bottom.data.shape, bottom.data.size_y = "RECTANGLE", 0.25
    bottom.data.color, bottom.data.exposure = (1.0, 0.8, 0.6), 0.5
    props = bpy.context.scene.visrad
    props.preset, props.max_bounces, props.max_iterations = "CUSTOM", 1, 1
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    return {"Plane": plane, "Box": cube}


def light_polygon(obj) -> tuple[np.ndarray, np.ndarray]:
    """(corners (4, 3) facing the light's local -Z, exitance (3,)) of a square or rectangular area light."""
    light = obj.data
    width = light.size
    height = light.size if light.shape == "SQUARE" else light.size_y
    local = [(-width / 2, -height / 2), (-width / 2, height / 2), (width / 2, height / 2), (width / 2, -height / 2)]
    matrix = obj.matrix_world
    corners = np.array([tuple(matrix @ Vector((x, y, 0.0))) for x, y in local])
    normal = np.cross(corners[1] - corners[0], corners[2] - corners[0])
    emits = -np.array(tuple(matrix.to_3x3().col[2]))
    assert np.dot(normal, emits) > 0.0, "the loop faces where the light emits"
    area = width * height  # unit scale
    exitance = np.array(light.color[:3]) * light.energy * 2.0**light.exposure / area
    return corners, exitance


def reference_scene(objects: dict) -> tuple[Scene, list]:
    """A core Scene built here from the Blender data, and its lights [(polygon, E_l)]."""
    vertices, polygons, rho, emission, two_sided = [], [], [], [], []
    for name, reflectance, open_surface in (("Plane", PLANE_RHO, True), ("Box", BOX_RHO, False)):
        obj = objects[name]
        offset = sum(len(v) for v in vertices)
        vertices.append(np.array([tuple(obj.matrix_world @ v.co) for v in obj.data.vertices]))
        for polygon in obj.data.polygons:
            polygons.append([offset + i for i in polygon.vertices])
            rho.append(reflectance)
            emission.append((0.0, 0.0, 0.0))
            two_sided.append(open_surface)
    lights = []
    for name in ("Top", "Bottom"):
        corners, exitance = light_polygon(bpy.data.objects[name])
        offset = sum(len(v) for v in vertices)
        vertices.append(corners)
        lights.append((len(polygons), exitance))
        polygons.append(list(range(offset, offset + 4)))
        rho.append((0.0, 0.0, 0.0))
        emission.append(tuple(exitance))
        two_sided.append(False)
    scene = Scene.from_polygons(
        np.concatenate(vertices), polygons, np.array(rho), np.array(emission), two_sided=np.array(two_sided)
    )
    return scene, lights


def result_samples(obj, reference_normals: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(points (N, 3) float64, normals (N, 3), pi x radiance (N, 3)) at the vertices of obj's result mesh.
    Each vertex takes the normal of the side its faces carry (the reference normal nearest their geometric
    normal, so float32 rounding of tiny triangles does not tilt it)."""
    mesh = bpy.data.objects[obj.name + RESULT_SUFFIX].data
    points = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", points)
    points = points.reshape(-1, 3).astype(np.float64)
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    triangles = corners.reshape(-1, 3)
    a, b, c = (points[triangles[:, k]] for k in range(3))
    face_normals = np.cross(b - a, c - a)
    side = np.argmax(face_normals @ reference_normals.T, axis=1)
    vertex_side = np.full(len(points), -1)
    for k in range(3):
        previous = vertex_side[triangles[:, k]]
        assert ((previous == -1) | (previous == side)).all(), "a result vertex is shared by two sides"
        vertex_side[triangles[:, k]] = side
    assert (vertex_side >= 0).all()
    normals = reference_normals[vertex_side]
    values = np.empty(4 * len(mesh.vertices), np.float32)
    mesh.color_attributes[RADIANCE_ATTRIBUTE].data.foreach_get("color", values)
    return points, normals, math.pi * values.reshape(-1, 4)[:, :3].astype(np.float64)


def expected(scene, lights, points, normals, rho) -> np.ndarray:
    irradiance = sum(exact_form_factors(scene, points, normals, index)[:, None] * e for index, e in lights)
    return np.asarray(rho) * irradiance


def check(measured, reference) -> float:
    scale = np.abs(reference).max()
    error = np.abs(measured - reference)
    # float32: the stored radiance (2^-24 relative) and the vertex positions (about 1e-7 m here)
    assert (error <= 2e-6 * np.abs(reference) + 1e-6 * scale).all(), (
        f"largest error {error.max():.3g} (relative to the largest value {error.max() / scale:.3g})"
    )
    return float(error.max() / scale)


def test_plane_both_sides_direct_light_is_exact(baked):
    scene, lights = reference_scene(baked)
    points, normals, measured = result_samples(baked["Plane"], np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]]))
    underside = normals[:, 2] < 0.0
    assert underside.any() and (~underside).any(), "both sides of the plane were written"
    # the back side's faces lie SIDE_GAP below the plane: put them back on it (its float32 height, as read)
    points[underside, 2] = float(np.float32(PLANE_HEIGHT))
    reference = expected(scene, lights, points, normals, PLANE_RHO)
    top, bottom = reference[~underside], reference[underside]
    assert (top[:, 0] == 0.0).any() and (top[:, 0] > 0.5 * top[:, 0].max()).any(), "the box shadows the top"
    assert bottom[:, 0].max() > 0.0, "the lower light reaches the underside"
    check(measured, reference)
    assert len(points) > 2 * 9, "refinement added vertices to the plane's 9 corners per side"


def test_box_direct_light_is_exact(baked):
    scene, lights = reference_scene(baked)
    axes = np.concatenate([np.eye(3), -np.eye(3)])
    points, normals, measured = result_samples(baked["Box"], axes)
    reference = expected(scene, lights, points, normals, BOX_RHO)
    assert reference[:, 0].max() > 0.0 and (reference[:, 0] == 0.0).any()
    check(measured, reference)
