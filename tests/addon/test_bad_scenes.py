"""Bad scenes the add-on must take without harm (issue 6: "feed bad scenes ... non-manifold and huge meshes:
each gives a clear report and changes nothing"). test_session.py and test_convert.py cover no light, no mesh,
zero-area faces and NaN transforms; this file covers the rest.

* Non-manifold meshes (three faces on one edge, two faces sharing only a vertex, coincident duplicate faces,
  faces back to back, a flipped face in a closed box) are valid Blender meshes: Check Scene, Build Skeleton,
  Coarse Lighting and Write Results succeed, and the side of each face turned to the light gets exactly the
  direct light (rho E F / pi, unoccluded, Max Bounces 1).
* Huge and tiny scales (the same scene scaled by 1e-4, 1e5 and 1e6, and moved 1e5 and 1e6 m from the origin)
  give the same radiance as the scene at 1 m (core's tolerances are relative to the scene's size).
* A huge count (a 100-face grid subdivided by a modifier into 25 600 faces): Check Scene converts it and
  reports the counts in bounded time and memory, without harm to the user's mesh. Measured on the 2-core
  machine: 10 s for 25 600 faces, 32-40 s for 102 400 (core's Scene.from_polygons checks each polygon in
  Python, about 0.4 ms each), which is why the test stops at 25 600. The solver stages are not run on it:
  core's Build Skeleton allocates a (corners x polygons) float64 array (`facing_sources`: 313 GiB for
  102 400 faces, 48 GiB for 40 000) and fails with MemoryError, which the stage reports as "Build Skeleton
  failed: MemoryError: ..."; on 10 000 faces it succeeds in 38 s and Coarse Lighting takes 74 s more.

Every case compares the user's data before and after (tests/addon/blender_scenes.user_data_fingerprint).
"""

import math
import resource
import time

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.formfactor import point_polygon_ff  # noqa: E402
from visrad.visrad_addon.session import store  # noqa: E402
from visrad.visrad_addon.write_back import (  # noqa: E402
    RADIANCE_ATTRIBUTE,
    RESULT_SUFFIX,
    ROLE_PROPERTY,
    ROLE_RESULT_OBJECT,
    SIDE_GAP,
    result_objects,
)

from tests.addon.blender_scenes import (  # noqa: E402
    area_light,
    box,
    diffuse_material,
    grid,
    mesh_object,
    user_data_fingerprint,
)

RHO = 0.5
HEIGHT = 0.5  # of the floating non-manifold pieces, between the floor (z = 0) and the light (z = 2)


def exact_direct_light(blender_scene) -> None:
    settings = blender_scene.visrad
    settings.preset = "CUSTOM"
    settings.form_factors, settings.jnd = "EXACT", 0.5
    settings.max_bounces, settings.max_iterations = 1, 1


@pytest.fixture
def lit_floor(registered_addon):
    """An empty file with a square area light 2 m above a 2 m floor; exact form factors, direct light only."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    store.clear()
    area_light("Light", size=0.5, power=50.0, location=(0.0, 0.0, 2.0))
    grid("Floor", (-1.0, -1.0, 0.0), (2, 0, 0), (0, 2, 0), 2, diffuse_material("floor", (0.7, 0.7, 0.7)))
    exact_direct_light(bpy.context.scene)
    return bpy.context.scene


def result_mesh(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(vertices (N, 3) float64, triangles (T, 3), radiance (N, 3)) of the result mesh of object `name`."""
    mesh = bpy.data.objects[name + RESULT_SUFFIX].data
    vertices = np.empty(3 * len(mesh.vertices), np.float32)
    mesh.vertices.foreach_get("co", vertices)
    corners = np.empty(len(mesh.loops), np.int32)
    mesh.loops.foreach_get("vertex_index", corners)
    colours = np.empty(4 * len(mesh.vertices), np.float32)
    mesh.color_attributes[RADIANCE_ATTRIBUTE].data.foreach_get("color", colours)
    return vertices.reshape(-1, 3).astype(np.float64), corners.reshape(-1, 3), colours.reshape(-1, 4)[:, :3]


def assert_all_results_finite(blender_scene) -> None:
    written = [obj for obj in result_objects(blender_scene) if obj.get(ROLE_PROPERTY) == ROLE_RESULT_OBJECT]
    assert written
    for obj in written:
        _, _, radiance = result_mesh(obj.name.removesuffix(RESULT_SUFFIX))
        assert np.isfinite(radiance).all() and radiance.min() >= 0.0, obj.name


def assert_lit_from_above(name: str, height: float, area: float) -> None:
    """The faces of `name`'s result mesh that face up at `height` cover `area` and carry exactly the direct
    light of the scene's one light, unoccluded: pi L = rho E F (float32 precision)."""
    vertices, triangles, radiance = result_mesh(name)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    session = store.get(bpy.context.scene)
    # the back side of a two-sided face is written SIDE_GAP x the scene's diagonal behind its front
    gap = 1.01 * SIDE_GAP * session.scene.diagonal + 1e-6
    up = (normals[:, 2] > 0.999 * lengths) & (np.abs(a[:, 2] - height) < gap)
    assert math.isclose(0.5 * lengths[up].sum(), area, rel_tol=1e-5), "the faces turned to the light are written"
    (light,) = session.scene.lights
    points = vertices[np.unique(triangles[up])]
    points[:, 2] = height
    form_factors = point_polygon_ff(points, np.tile([0.0, 0.0, 1.0], (len(points), 1)), session.scene.polygon(light))
    expected = RHO * form_factors[:, None] * session.scene.emission[light] / math.pi
    assert expected.min() > 0.0
    np.testing.assert_allclose(radiance[np.unique(triangles[up])], expected, rtol=1e-5)


# ---------------------------------------------------------------------------------------------------------
# Non-manifold meshes


def three_fins(material):
    """A T: two horizontal fins and one hanging down, all on the edge x = 0, z = HEIGHT (three faces, one
    edge). The hanging fin is under the others; the horizontal fins' tops see the light unoccluded."""
    h = HEIGHT
    vertices = [(0, -0.3, h), (0, 0.3, h), (0.4, 0.3, h), (0.4, -0.3, h), (-0.4, 0.3, h), (-0.4, -0.3, h)]
    vertices += [(0, 0.3, h - 0.3), (0, -0.3, h - 0.3)]
    mesh_object("Fins", vertices, [(0, 3, 2, 1), (1, 4, 5, 0), (0, 1, 6, 7)], material)
    return "Fins", 2 * 0.4 * 0.6


def bow_tie(material):
    """Two triangles facing up that share one vertex and no edge."""
    h = HEIGHT
    vertices = [(0, 0, h), (0.3, 0.1, h), (0.3, -0.1, h), (-0.3, 0.1, h), (-0.3, -0.1, h)]
    mesh_object("BowTie", vertices, [(0, 2, 1), (0, 3, 4)], material)
    return "BowTie", 2 * 0.03


SQUARE = [(-0.15, -0.15, HEIGHT), (0.15, -0.15, HEIGHT), (0.15, 0.15, HEIGHT), (-0.15, 0.15, HEIGHT)]


def duplicate_faces(material):
    """The same face twice on the same vertices (an open surface: both copies are lit on both sides)."""
    mesh_object("Doubled", SQUARE, [(0, 1, 2, 3), (0, 1, 2, 3)], material)
    return "Doubled", 2 * 0.09


def back_to_back_faces(material):
    """A card made of two faces on the same vertices, one facing up, one down: one surface with two sides (not
    two surfaces touching face to face, as a box resting on a floor), each face lit on its own side."""
    mesh_object("Card", SQUARE, [(0, 1, 2, 3), (3, 2, 1, 0)], material)
    return "Card", 0.09


def flipped_face(material):
    """A floating closed box whose top face is wound the wrong way (its normal points into the box)."""
    obj = box("Flipped", (-0.2, -0.2, HEIGHT - 0.3), (0.2, 0.2, HEIGHT), material)
    (top,) = [p for p in obj.data.polygons if p.center.z > HEIGHT - 1e-6]
    top.flip()
    return "Flipped", 0.16


@pytest.mark.parametrize(
    "build",
    [three_fins, bow_tie, duplicate_faces, back_to_back_faces, flipped_face],
    ids=["three faces on one edge", "bow-tie", "duplicate faces", "back-to-back faces", "flipped face"],
)
def test_a_non_manifold_mesh_is_lit_and_left_unchanged(lit_floor, build):
    name, lit_area = build(diffuse_material("grey", (RHO, RHO, RHO)))
    bpy.context.view_layer.update()
    before = user_data_fingerprint(ROLE_PROPERTY)
    polygons = len(bpy.data.objects[name].data.polygons)

    assert bpy.ops.visrad.check_scene() == {"FINISHED"}
    session = store.get(lit_floor)
    assert session.summary.startswith(f"{polygons + 5} polygons"), session.summary
    assert session.source_map.warnings == []
    assert bpy.ops.visrad.build_skeleton() == {"FINISHED"}
    assert bpy.ops.visrad.coarse_lighting() == {"FINISHED"}
    assert bpy.ops.visrad.write_results() == {"FINISHED"}

    assert_all_results_finite(lit_floor)
    assert_lit_from_above(name, HEIGHT, lit_area)
    assert user_data_fingerprint(ROLE_PROPERTY) == before


# ---------------------------------------------------------------------------------------------------------
# Huge and tiny scales


def scaled_scene(scale: float, offset) -> None:
    """A box on a floor under a tilted area light, all lengths x scale, light power x scale^2 (the same
    exitance), the meshes' objects placed at `offset` (their vertices stay small: Blender stores both in
    float32, which represents 1e5 and 1e6 exactly but not 1e6 + 0.1)."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    store.clear()
    light = (offset[0] + 0.125 * scale, offset[1], offset[2] + 2.0 * scale)
    area_light("Light", size=0.5 * scale, power=50.0 * scale**2, location=light, rotation=(0.2, 0.1, 0.0))
    floor = grid(
        "Floor", (-scale, -scale, 0.0), (2 * scale, 0, 0), (0, 2 * scale, 0), 2, diffuse_material("f", (0.7,) * 3)
    )
    cube = box(
        "Box",
        (-0.2 * scale, -0.2 * scale, 0.0),
        (0.2 * scale, 0.2 * scale, 0.4 * scale),
        diffuse_material("b", (RHO,) * 3),
    )
    floor.location = cube.location = offset
    exact_direct_light(bpy.context.scene)
    bpy.context.view_layer.update()


def bake_scaled(scale: float, offset) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{object: (result vertices brought back to the 1 m scene, radiance)} after Check Scene and Bake, which
    must leave the user's data as it was."""
    scaled_scene(scale, offset)
    before = user_data_fingerprint(ROLE_PROPERTY)
    assert bpy.ops.visrad.check_scene() == {"FINISHED"}
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    results = {}
    for name in ("Floor", "Box"):
        vertices, _, radiance = result_mesh(name)
        assert np.isfinite(radiance).all()
        results[name] = ((vertices - offset) / scale, radiance)
    return results


@pytest.fixture(scope="module")
def one_metre(registered_addon):
    return bake_scaled(1.0, (0.0, 0.0, 0.0))


@pytest.mark.parametrize(
    ("scale", "offset", "tolerance"),
    [
        (1e-4, (0.0, 0.0, 0.0), 1e-6),
        (1e5, (0.0, 0.0, 0.0), 1e-6),
        (1e6, (0.0, 0.0, 0.0), 1e-6),
        # far from the origin core loses digits in differences of large coordinates (measured: 1e-5 of the
        # largest radiance at 1e5 m, 2e-4 at 1e6 m), far below the smallest JND
        (1.0, (1e5, -1e5, 0.0), 1e-4),
        (1.0, (1e6, 1e6, 1e5), 1e-3),
    ],
    ids=["0.1 mm", "100 km", "1000 km", "100 km away", "1000 km away"],
)
def test_huge_and_tiny_scales_light_the_same(one_metre, scale, offset, tolerance):
    results = bake_scaled(scale, offset)
    for name, (vertices, radiance) in one_metre.items():
        scaled_vertices, scaled_radiance = results[name]
        assert scaled_radiance.shape == radiance.shape, f"{name}: the same mesh at every scale"
        # result meshes are in world space, stored in float32: far from the origin their positions are
        # rounded to float32's spacing there (write_back.py)
        rounding = float(np.spacing(np.float32(max(np.abs(offset)) + 2.0 * scale))) / scale
        np.testing.assert_allclose(scaled_vertices, vertices, atol=2e-7 + rounding)
        np.testing.assert_allclose(scaled_radiance, radiance, atol=tolerance * radiance.max())


# ---------------------------------------------------------------------------------------------------------
# A huge polygon count


def test_check_scene_converts_a_huge_face_count_and_changes_nothing(lit_floor):
    bpy.data.objects.remove(bpy.data.objects["Floor"])
    plane = grid("Terrain", (-1.0, -1.0, 0.0), (2, 0, 0), (0, 2, 0), 10, diffuse_material("ground", (0.6,) * 3))
    subdivision = plane.modifiers.new("Subdivision", "SUBSURF")
    subdivision.subdivision_type, subdivision.levels = "SIMPLE", 4
    bpy.context.view_layer.update()
    before = user_data_fingerprint(ROLE_PROPERTY)
    peak_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    started = time.perf_counter()
    assert bpy.ops.visrad.check_scene() == {"FINISHED"}
    seconds = time.perf_counter() - started

    session = store.get(lit_floor)
    assert session.summary == "25601 polygons (25601 convex), 1 objects, 1 area lights, 1 emitting polygons"
    assert session.scene.n_polygons == 100 * 4**4 + 1
    assert seconds < 60.0, f"Check Scene took {seconds:.0f} s"
    growth = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - peak_before) * 1024
    assert growth < 2e9, f"Check Scene's peak memory grew by {growth / 1e9:.1f} GB"
    assert user_data_fingerprint(ROLE_PROPERTY) == before
    assert len(plane.data.polygons) == 100, "the modifier's faces are converted, the user's mesh is left alone"


def test_build_skeleton_refuses_a_scene_too_large_for_the_memory_and_changes_nothing(lit_floor, monkeypatch):
    """The visibility stage holds the pairs of the scene's polygons (P^2): when they cannot fit in the memory
    the machine has (here made small), it says so before allocating, and nothing changes."""
    from visrad.core.pipeline import links

    bpy.data.objects.remove(bpy.data.objects["Floor"])
    plane = grid("Terrain", (-1.0, -1.0, 0.0), (2, 0, 0), (0, 2, 0), 10, diffuse_material("ground", (0.6,) * 3))
    plane.modifiers.new("Subdivision", "SUBSURF").levels = 2
    bpy.context.view_layer.update()
    monkeypatch.setattr(links, "_available_memory", lambda: 4 * 2**20)
    before = user_data_fingerprint(ROLE_PROPERTY)
    message = r"pairs of the scene's 1,601 polygons need about 10 MiB and 4 MiB of memory are available"
    with pytest.raises(RuntimeError, match=message):
        bpy.ops.visrad.build_skeleton()
    assert store.get(lit_floor) is None or "solver" not in store.get(lit_floor).state
    assert result_objects(lit_floor) == []
    assert user_data_fingerprint(ROLE_PROPERTY) == before
