"""DESIGN.md sections 2 and 5.6 end to end: a Cycles DIFFUSE bake (pass DIRECT + COLOR) agrees with
rho sum_l E_l F_l from the converted scene and core's exact form factors, within Cycles' own noise.

Scene: a tilted square area light over an open floor grid, with a floating box casting a penumbra on it; all
surfaces Diffuse BSDF (Principled adds a specular layer). Cycles bakes rho E_in / pi at the floor's vertices
into a colour attribute, twice with different seeds; B - E = pi x bake is compared with the exact direct light
computed from what convert.py read (reflectance, the light's exitance and polygon). The noise is estimated from
the difference of the two seeds.
"""

import math

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.core.visibility import exact_form_factors  # noqa: E402
from visrad.visrad_addon.convert import scene_from_blender  # noqa: E402

from tests.addon.blender_scenes import area_light, box, diffuse_material, grid  # noqa: E402

FLOOR_RHO = (0.8, 0.5, 0.2)
SAMPLES = 1024
SEEDS = (1, 2)


@pytest.fixture(scope="module")
def baked():
    """(exact direct light (V, 3), bakes x pi (seeds, V, 3)) at the floor's vertices."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    floor = grid("Floor", (-1.0, -1.0, 0.0), (2, 0, 0), (0, 2, 0), 8, diffuse_material("floor", FLOOR_RHO))
    box("Box", (-0.1, -0.3, 0.4), (0.3, 0.1, 0.8), diffuse_material("box", (0.5, 0.5, 0.5)))
    area_light("Light", size=1.0, power=200.0, location=(0.2, 0.1, 1.5), rotation=(0.3, 0.0, 0.0))

    scene, source_map = scene_from_blender(bpy.context)
    floor_index = next(i for i, s in enumerate(source_map.objects) if s.name == "Floor")
    floor_polygons = np.flatnonzero(source_map.polygon_object[scene.source_polygon] == floor_index)
    rho = scene.reflectance[floor_polygons[0]]
    points = np.array([tuple(floor.matrix_world @ v.co) for v in floor.data.vertices])
    normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    irradiance = sum(
        exact_form_factors(scene, points, normals, int(l))[:, None] * scene.emission[l] for l in scene.lights
    )
    exact = rho * irradiance

    render = bpy.context.scene.render
    render.engine = "CYCLES"
    cycles = bpy.context.scene.cycles
    cycles.device, cycles.samples, cycles.use_adaptive_sampling = "CPU", SAMPLES, False
    attribute = floor.data.color_attributes.new("bake", "FLOAT_COLOR", "POINT")
    floor.data.color_attributes.active_color = attribute
    bpy.context.view_layer.objects.active = floor
    floor.select_set(True)
    bakes = []
    for seed in SEEDS:
        cycles.seed = seed
        bpy.ops.object.bake(type="DIFFUSE", pass_filter={"DIRECT", "COLOR"}, target="VERTEX_COLORS")
        colours = np.empty(4 * len(points), dtype=np.float32)
        attribute.data.foreach_get("color", colours)
        bakes.append(math.pi * colours.reshape(-1, 4)[:, :3].astype(np.float64))
    return exact, np.array(bakes)


def test_the_scene_has_light_penumbra_and_shadow(baked):
    exact, _ = baked
    lit = exact[:, 0] / exact[:, 0].max()
    assert (lit == 0.0).sum() >= 1, "some floor vertex is in the box's umbra"
    assert ((lit > 0.0) & (lit < 0.5)).sum() >= 3, "some vertices are in the penumbra"


def test_cycles_noise_is_small_enough_for_the_comparison(baked):
    exact, bakes = baked
    lit = exact[:, 0] > 0.0
    relative_noise = np.sqrt(np.mean(((bakes[0] - bakes[1])[lit] / exact[lit]) ** 2) / 2.0)
    assert relative_noise < 0.005


def test_pi_times_the_bake_is_rho_sum_e_f_within_cycles_noise(baked):
    exact, bakes = baked
    mean = bakes.mean(axis=0)
    error = mean - exact
    # each seed has variance s^2 per vertex; the mean of two has s^2 / 2, and so has (b1 - b2) / 2
    noise = (bakes[0] - bakes[1]) / 2.0
    ratio = np.sum(error**2) / np.sum(noise**2)
    assert ratio < 2.5, f"squared error is {ratio:.2f} x the noise variance (about 1 expected)"
    bias = np.sum(error) / np.sqrt(np.sum(noise**2))
    assert abs(bias) < 4.0, f"bias {bias:.1f} standard deviations"
    lit = exact[:, 0] > 0.0
    assert np.abs(error[lit] / exact[lit]).max() < 0.01
    np.testing.assert_array_equal(mean[~lit], 0.0)
