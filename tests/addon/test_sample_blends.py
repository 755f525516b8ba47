"""sample_blends/: generate.py reproduces the committed .blend files, and the add-on's operators run on each.

Reproducible means the same objects, transforms, mesh geometry, material assignments, material node values
and lights (the bytes of a .blend also hold a timestamp and the file's own bookkeeping). The operators: Check
Scene and Build Skeleton on all five samples; Coarse Lighting and Write Results on the Village (its mesh
emitter is the path the others do not take); the Cornell box gets every operator in tests/addon/test_stages.py
and the batch run in test_batch.py. The other samples' coarse lighting takes 15-25 s each: bench/ measures them.
"""

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from visrad.visrad_addon import stages  # noqa: E402
from visrad.visrad_addon.session import store  # noqa: E402
from visrad.visrad_addon.write_back import ROLE_PROPERTY, result_objects  # noqa: E402

from tests.addon.blender_scenes import user_data_fingerprint  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SAMPLES = ROOT / "sample_blends"
NAMES = ("cornell_box", "desk", "many_lights", "indirect_bedroom", "village")


def content_digest(path: Path) -> str:
    """What generate.py promises to reproduce, of the .blend at `path` (opened in this process)."""
    bpy.ops.wm.open_mainfile(filepath=str(path), load_ui=False)
    digest = hashlib.sha256()
    for obj in sorted(bpy.data.objects, key=lambda o: o.name):
        digest.update(f"{obj.name}:{obj.type}".encode())
        digest.update(np.array(obj.matrix_world, np.float64).tobytes())
        if obj.type == "MESH":
            mesh = obj.data
            for collection, name, dtype, width in (
                (mesh.vertices, "co", np.float32, 3),
                (mesh.loops, "vertex_index", np.int32, 1),
                (mesh.polygons, "loop_total", np.int32, 1),
                (mesh.polygons, "material_index", np.int32, 1),
            ):
                values = np.empty(width * len(collection), dtype)
                collection.foreach_get(name, values)
                digest.update(values.tobytes())
            digest.update(repr([m.name for m in mesh.materials]).encode())
        elif obj.type == "LIGHT":
            light = obj.data
            digest.update(repr((light.type, light.shape, light.size, light.size_y, light.energy)).encode())
            digest.update(repr(tuple(light.color)).encode())
        elif obj.type == "CAMERA":
            digest.update(repr(obj.data.lens).encode())
    for material in sorted(bpy.data.materials, key=lambda m: m.name):
        for node in sorted(material.node_tree.nodes, key=lambda n: n.name):
            digest.update(f"{material.name}/{node.bl_idname}".encode())
            for socket in node.inputs:
                value = getattr(socket, "default_value", None)
                digest.update(repr(tuple(value) if hasattr(value, "__len__") else value).encode())
    return digest.hexdigest()


def test_generate_reproduces_the_committed_samples(tmp_path):
    process = subprocess.run(
        [sys.executable, str(SAMPLES / "generate.py"), "--output-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert process.returncode == 0, process.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(f"{name}.blend" for name in NAMES)
    for name in NAMES:
        assert content_digest(tmp_path / f"{name}.blend") == content_digest(SAMPLES / f"{name}.blend"), name


@pytest.mark.parametrize("name", NAMES)
def test_check_scene_and_build_skeleton_on_every_sample(registered_addon, name):
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLES / f"{name}.blend"))
    user_data = user_data_fingerprint(ROLE_PROPERTY)
    assert bpy.ops.visrad.check_scene() == {"FINISHED"}
    session = store.get(bpy.context.scene)
    assert session.source_map.warnings == [], "the samples use only what the add-on reads exactly"
    assert len(session.scene.lights) >= 1
    assert bpy.ops.visrad.build_skeleton() == {"FINISHED"}
    assert store.get(bpy.context.scene) is session and session.state[stages.STATS]["skeleton_built"]
    assert user_data_fingerprint(ROLE_PROPERTY) == user_data


def test_coarse_lighting_and_write_results_on_the_village(registered_addon):
    bpy.ops.wm.open_mainfile(filepath=str(SAMPLES / "village.blend"))
    user_data = user_data_fingerprint(ROLE_PROPERTY)
    assert bpy.ops.visrad.coarse_lighting() == {"FINISHED"}
    assert bpy.ops.visrad.write_results() == {"FINISHED"}
    session = store.get(bpy.context.scene)
    written = session.state[stages.WRITTEN]
    assert written["objects"] and written["triangles"] >= session.state[stages.STATS]["leaf_triangles"]
    assert len([obj for obj in result_objects(bpy.context.scene) if obj.type == "MESH"]) == len(written["objects"])
    assert user_data_fingerprint(ROLE_PROPERTY) == user_data
