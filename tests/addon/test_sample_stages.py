"""Every stage operator on every sample scene (issue 6: "run every operator on the sample scenes").

On each of the five samples: Build Skeleton, Coarse Lighting and Refine one by one, Write Results (result
meshes with finite radiance on every receiver), Clear Results (nothing of the add-on's left), then Bake, which
continues the same solution with one more refinement and writes, and Clear Results again. The user's data is
compared before and after.

Speed. The settings are the cheapest that still run every stage for real: ray-cast form factors with 4 rays,
JND 0.5, direct light only, one refinement iteration (two for Bake). Build Skeleton dominates: it builds the
Visibility Skeleton of the emitters (core's Settings.discontinuities, on by default, which the add-on's
settings do not expose), measured on the 2-core machine at 0.8 s (Cornell box), 8.5 s (desk), 12 s
(many_lights), 8.3 s (indirect_bedroom) and 6.5 s (village); Coarse Lighting and Refine then take 0.3-1.1 s
each. So the skeleton is built once per sample; the test takes about 45 s for the five. The Fast preset's
refinement alone took 6-13 s per sample and the Accurate preset's coarse lighting 12-15 s (desk,
indirect_bedroom at JND 0.5): too slow here.
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

    assert bpy.ops.visrad.build_skeleton() == {"FINISHED"}
    skeleton = store.get(blender_scene).state[stages.SOLVER]
    assert skeleton.facing is not None and skeleton.lighting is None
    assert bpy.ops.visrad.coarse_lighting() == {"FINISHED"}
    coarse = store.get(blender_scene).state[stages.SOLVER]
    assert coarse.lighting is not None and coarse.iterations == 0 and coarse.facing is skeleton.facing
    assert bpy.ops.visrad.refine() == {"FINISHED"}
    refined = store.get(blender_scene).state[stages.SOLVER]
    assert refined.iterations == 1 or refined.converged
    assert result_objects(blender_scene) == [], "only Bake and Write Results write"

    assert bpy.ops.visrad.write_results() == {"FINISHED"}
    assert_written(blender_scene)
    assert bpy.ops.visrad.clear_results() == {"FINISHED"}
    assert result_objects(blender_scene) == [] and owned_datablocks() == []

    # Bake continues the session's solution (one more refinement) rather than building the skeleton again
    blender_scene.visrad.max_iterations = 2
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    baked = store.get(blender_scene).state[stages.SOLVER]
    assert baked.facing is skeleton.facing and baked.refinement_log[:1] == refined.refinement_log[:1]
    assert baked.iterations == 2 or baked.converged
    assert_written(blender_scene)
    assert bpy.ops.visrad.clear_results() == {"FINISHED"}
    assert result_objects(blender_scene) == [] and owned_datablocks() == []
    assert not bpy.ops.visrad.clear_results.poll()

    assert user_data_fingerprint(ROLE_PROPERTY) == user_data, "the user's data is only read"
