"""Every stage operator on every sample scene (issue 6: "run every operator on the sample scenes").

On each of the five samples: Bake from a fresh file writes result meshes with finite radiance; Clear Results
removes everything the add-on made; then Build Skeleton, Coarse Lighting, Refine and Write Results one by one
write the same solution again (the solver is seeded, so the stages and Bake must agree), and Clear Results
removes it. The user's data is compared before and after.

Speed. The settings are the cheapest that still run every stage for real: ray-cast form factors with 4 rays,
JND 0.5, direct light only, one refinement iteration. Measured on the 2-core machine (seconds for Build
Skeleton, Coarse Lighting, Refine) the Fast preset takes desk 0.2 / 2.1 / 9.5, many_lights 0.6 / 2.8 / 12.9,
indirect_bedroom 0.4 / 5.0 / 13.4, village 0.2 / 1.6 / 6.2, and the Accurate preset (exact form factors) is
slower still (desk coarse lighting alone 12 s at JND 0.5): too slow to run twice on five samples in a test.
With these settings the test of one sample (both passes) takes 1 s (Cornell box) to 7 s (indirect_bedroom),
22 s for the five.
"""

from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.visrad_addon import stages  # noqa: E402
from visrad.visrad_addon.session import store  # noqa: E402
from visrad.visrad_addon.write_back import (  # noqa: E402
    RADIANCE_ATTRIBUTE,
    ROLE_PROPERTY,
    ROLE_RESULT_OBJECT,
    result_objects,
)

from tests.addon.blender_scenes import user_data_fingerprint  # noqa: E402

SAMPLES = Path(__file__).resolve().parents[2] / "sample_blends"
NAMES = ("cornell_box", "desk", "many_lights", "indirect_bedroom", "village")
# every kind of datablock write_back.py creates, to check that Clear Results leaves none behind
OWNED_KINDS = ("objects", "meshes", "curves", "materials", "collections")


def cheap_settings(blender_scene) -> None:
    settings = blender_scene.visrad
    settings.preset = "CUSTOM"
    settings.form_factors, settings.rays = "RAYS", 4
    settings.jnd, settings.max_bounces, settings.max_iterations = 0.5, 1, 1


def written_radiance(blender_scene) -> dict[str, np.ndarray]:
    """{result object name: (N, 3) visrad_radiance} of the scene's result meshes."""
    values = {}
    for obj in result_objects(blender_scene):
        if obj.get(ROLE_PROPERTY) != ROLE_RESULT_OBJECT:
            continue
        attribute = obj.data.color_attributes[RADIANCE_ATTRIBUTE]
        assert attribute.domain == "POINT" and attribute.data_type == "FLOAT_COLOR", obj.name
        colours = np.empty(4 * len(attribute.data), np.float32)
        attribute.data.foreach_get("color", colours)
        values[obj.name] = colours.reshape(-1, 4)[:, :3]
    return values


def owned_datablocks() -> list[str]:
    return [f"{kind}/{d.name}" for kind in OWNED_KINDS for d in getattr(bpy.data, kind) if d.get(ROLE_PROPERTY)]


def assert_written(blender_scene) -> dict[str, np.ndarray]:
    """The scene's results are one mesh per receiving mesh object with finite, non-negative radiance, lit
    somewhere, as many triangles as the session says it wrote; returns their radiance."""
    session = store.get(blender_scene)
    receivers = {source.name for source in session.source_map.objects if source.kind == "mesh"}
    radiance = written_radiance(blender_scene)
    assert set(radiance) == {f"{name}.visrad" for name in receivers}
    for name, values in radiance.items():
        assert len(values) > 0 and np.isfinite(values).all(), name
        assert values.min() >= 0.0, name
    assert max(values.max() for values in radiance.values()) > 0.0, "the light reaches some receiver"
    written = session.state[stages.WRITTEN]
    assert written["triangles"] == sum(len(bpy.data.objects[name].data.polygons) for name in radiance)
    return radiance


@pytest.mark.parametrize("name", NAMES)
def test_every_operator_on_the_sample(registered_addon, name):
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLES / f"{name}.blend"))
    blender_scene = bpy.context.scene
    cheap_settings(blender_scene)
    user_data = user_data_fingerprint(ROLE_PROPERTY)
    assert not bpy.ops.visrad.clear_results.poll(), "a sample comes without results"

    assert bpy.ops.visrad.bake() == {"FINISHED"}
    baked_solver = store.get(blender_scene).state[stages.SOLVER]
    assert baked_solver.iterations == 1 or baked_solver.converged
    baked = assert_written(blender_scene)
    assert bpy.ops.visrad.clear_results() == {"FINISHED"}
    assert result_objects(blender_scene) == [] and owned_datablocks() == []

    assert bpy.ops.visrad.build_skeleton() == {"FINISHED"}
    solver = store.get(blender_scene).state[stages.SOLVER]
    assert solver is not baked_solver and solver.facing is not None and solver.lighting is None
    assert bpy.ops.visrad.coarse_lighting() == {"FINISHED"}
    assert store.get(blender_scene).state[stages.SOLVER].lighting is not None
    assert bpy.ops.visrad.refine() == {"FINISHED"}
    solver = store.get(blender_scene).state[stages.SOLVER]
    assert solver.iterations == baked_solver.iterations
    assert result_objects(blender_scene) == [], "only Bake and Write Results write"

    assert bpy.ops.visrad.write_results() == {"FINISHED"}
    staged = assert_written(blender_scene)
    assert staged.keys() == baked.keys()
    for key, values in staged.items():
        np.testing.assert_allclose(values, baked[key], rtol=1e-5, atol=1e-7, err_msg=key)
    assert bpy.ops.visrad.clear_results() == {"FINISHED"}
    assert result_objects(blender_scene) == [] and owned_datablocks() == []
    assert not bpy.ops.visrad.clear_results.poll()

    assert user_data_fingerprint(ROLE_PROPERTY) == user_data, "the user's data is only read"
