"""visrad_addon/batch.py end to end, as a user runs it with the bpy module: `python visrad_addon/batch.py
in.blend --output out.blend ...` in a separate process (it registers the add-on from the checkout).

The Cornell box sample is baked with one refinement iteration (a few seconds): the output exists and holds the
result meshes, the input is untouched, the statistics JSON has the times, counts and memory, the render is a
PNG. Failures exit non-zero with one readable line: a scene without light, output == input, an unreadable
file; bad arguments exit 2.
"""

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

bpy = pytest.importorskip("bpy")

from visrad.visrad_addon.write_back import RADIANCE_ATTRIBUTE, ROLE_PROPERTY, ROLE_RESULT_OBJECT  # noqa: E402

from tests.addon.blender_scenes import box, diffuse_material  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
BATCH = ROOT / "visrad_addon" / "batch.py"
CORNELL = ROOT / "sample_blends" / "cornell_box.blend"
TIMEOUT = 300


def run_batch(*args, cwd) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(BATCH), *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=TIMEOUT
    )


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def error_line(process: subprocess.CompletedProcess) -> str:
    lines = [line for line in process.stderr.splitlines() if line.startswith("visrad batch: error: ")]
    assert len(lines) == 1, process.stderr
    return lines[0]


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """One batch run on a copy of the Cornell box: (process, paths)."""
    folder = tmp_path_factory.mktemp("batch")
    source = folder / "cornell_box.blend"
    shutil.copyfile(CORNELL, source)
    paths = {
        "input": source,
        "output": folder / "out" / "baked.blend",
        "stats": folder / "out" / "stats.json",
        "render": folder / "out" / "render.png",
    }
    before = (digest(source), source.stat().st_mtime_ns)
    process = run_batch(
        source,
        "--output", paths["output"],
        "--max-iterations", 1,
        "--max-bounces", 2,
        "--stats", paths["stats"],
        "--render", paths["render"],
        "--render-samples", 2,
        "--render-percent", 20,
        "--render-exposure", "auto",
        cwd=folder,
    )  # fmt: skip
    return process, paths, before


def test_batch_bakes_saves_and_leaves_the_input_alone(baked, registered_addon):
    process, paths, before = baked
    assert process.returncode == 0, process.stderr
    assert "using the add-on from the checkout" in process.stderr
    assert (digest(paths["input"]), paths["input"].stat().st_mtime_ns) == before
    assert sorted(p.name for p in paths["output"].parent.iterdir()) == ["baked.blend", "render.png", "stats.json"]

    bpy.ops.wm.open_mainfile(filepath=str(paths["output"]))
    results = [obj for obj in bpy.data.objects if obj.get(ROLE_PROPERTY) == ROLE_RESULT_OBJECT]
    names = {"floor", "ceiling", "back_wall", "right_wall", "left_wall", "short_block", "tall_block"}
    assert {obj.name for obj in results} == {f"{name}.visrad" for name in names}
    assert all(RADIANCE_ATTRIBUTE in obj.data.color_attributes for obj in results)
    assert not any(bpy.data.objects[name].hide_render for name in names), "the render's hiding is not saved"
    props = bpy.context.scene.visrad
    assert (props.max_iterations, props.max_bounces, props.preset) == (1, 2, "CUSTOM")


def test_batch_statistics(baked):
    process, paths, _ = baked
    stats = json.loads(paths["stats"].read_text())
    assert stats["input"] == str(paths["input"]) and stats["output"] == str(paths["output"])
    assert stats["output_bytes"] == paths["output"].stat().st_size
    assert stats["render_bytes"] == paths["render"].stat().st_size
    assert stats["settings"] == {
        "preset": "custom",
        "jnd": 0.02,
        "max_iterations": 1,
        "max_bounces": 2,
        "form_factors": "exact",
        "discontinuities": True,
        "source_refinement": False,
    }
    seconds = stats["seconds"]
    assert set(seconds["stages"]) == {"build_skeleton", "coarse_lighting", "refine"}
    assert all(value > 0.0 for value in seconds["stages"].values())
    assert seconds["total"] >= seconds["bake"] + seconds["save"] + seconds["render"]
    counts = stats["counts"]
    assert counts["polygons"] == 16 and counts["area_lights"] == 1 and counts["objects"] == 7
    assert counts["iterations"] == 1 and counts["result_objects"] == 7
    assert counts["links"] > 0 and counts["vertices"] > 0 and counts["triangles"] > 32
    assert counts["triangles_written"] >= counts["triangles"]
    assert stats["memory"]["peak_bytes"] > 50 * 2**20
    assert [record["iteration"] for record in stats["refinement"]] == [1]


def test_batch_render_is_a_png_of_the_scaled_resolution(baked):
    _, paths, _ = baked
    data = paths["render"].read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    width, height = int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")
    assert (width, height) == (160, 120)  # 20 % of the sample's 800 x 600


def test_batch_refuses_to_overwrite_its_input(tmp_path):
    source = tmp_path / "scene.blend"
    shutil.copyfile(CORNELL, source)
    before = digest(source)
    for output in (source, tmp_path / "." / "scene.blend"):
        process = run_batch(source, "--output", output, cwd=tmp_path)
        assert process.returncode == 1
        assert "never overwrites its input" in error_line(process)
    process = run_batch(source, "--output", tmp_path / "out.blend", "--stats", source, cwd=tmp_path)
    assert process.returncode == 1 and "--stats" in error_line(process)
    assert digest(source) == before and sorted(p.name for p in tmp_path.iterdir()) == ["scene.blend"]


def test_batch_reports_a_scene_without_light(tmp_path, registered_addon):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    box("Box", (0, 0, 0), (1, 1, 1), diffuse_material("grey", (0.5, 0.5, 0.5)))
    source = tmp_path / "dark.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(source), copy=True)
    process = run_batch(source, "--output", tmp_path / "out.blend", "--stats", tmp_path / "s.json", cwd=tmp_path)
    assert process.returncode == 1
    assert 'scene "Scene" has no light' in error_line(process)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dark.blend"], "nothing is written"


def test_batch_reports_unreadable_and_missing_files(tmp_path):
    (tmp_path / "junk.blend").write_text("not a blend file")
    process = run_batch(tmp_path / "junk.blend", "--output", tmp_path / "out.blend", cwd=tmp_path)
    assert process.returncode == 1 and "cannot open" in error_line(process)
    process = run_batch(tmp_path / "missing.blend", "--output", tmp_path / "out.blend", cwd=tmp_path)
    assert process.returncode == 1 and "does not exist" in error_line(process)
    assert not (tmp_path / "out.blend").exists()


@pytest.mark.parametrize(
    "arguments",
    [["--jnd", "2"], ["--max-iterations", "0"], ["--preset", "slow"], ["--max-bounces", "-1"], []],
    ids=["jnd", "iterations", "preset", "bounces", "no output"],
)
def test_batch_rejects_bad_arguments(tmp_path, arguments):
    output = [] if not arguments else ["--output", tmp_path / "out.blend"]
    process = run_batch(CORNELL, *output, *arguments, cwd=tmp_path)
    assert process.returncode == 2 and "usage:" in process.stderr


def _pixels(path: Path):
    import numpy as np

    image = bpy.data.images.load(str(path))
    try:
        return np.array(image.pixels[:], dtype=np.float64).reshape(image.size[1], image.size[0], 4)[:, :, :3]
    finally:
        bpy.data.images.remove(image)


def test_render_with_discontinuities_draws_the_curves_and_takes_them_back(registered_addon, tmp_path):
    import numpy as np
    from visrad.visrad_addon import batch
    from visrad.visrad_addon.session import store
    from visrad.visrad_addon.write_back import ROLE_DISCONTINUITY_OBJECT

    bpy.ops.wm.open_mainfile(filepath=str(CORNELL))
    store.clear()
    scene = bpy.context.scene
    scene.visrad.max_iterations = 3
    assert bpy.ops.visrad.bake() == {"FINISHED"}
    curves = [obj for obj in scene.objects if obj.get(ROLE_PROPERTY) == ROLE_DISCONTINUITY_OBJECT]
    assert curves, "three iterations insert discontinuities on the floor"
    before = [(obj.data.bevel_depth, len(obj.data.materials), obj.visible_camera) for obj in curves]
    materials = set(bpy.data.materials.keys())
    plain, drawn = tmp_path / "plain.png", tmp_path / "drawn.png"
    exposure = batch.render_results(bpy, scene, registered_addon, plain, 2, 25, "auto")
    assert batch.render_results(bpy, scene, registered_addon, drawn, 2, 25, "auto", curves=True) == exposure
    assert [(obj.data.bevel_depth, len(obj.data.materials), obj.visible_camera) for obj in curves] == before
    assert set(bpy.data.materials.keys()) == materials
    a, b = _pixels(plain), _pixels(drawn)
    changed = np.abs(a - b).max(axis=2) > 0.1
    assert 10 < changed.sum() < 0.05 * changed.size
    # the tubes add red light over whatever they cover (blended at their anti-aliased edges)
    added = (b - a)[changed]
    assert np.all(added[:, 0] > np.maximum(added[:, 1], added[:, 2]))
