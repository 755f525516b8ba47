"""The built extension zip installs, enables, works, disables and uninstalls in Blender (the bpy module).

tools/build_extension.py builds the linux-x64 zip into a temporary directory (wheels are downloaded from PyPI
into the git-ignored wheels/ folder once, then reused) and validates it with Blender's own validator; the
probe (extension_probe.py) then runs in a subprocess whose Blender user resources are a temporary directory.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("bpy")

from bench.scenes import SCENES  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).with_name("extension_probe.py")
PLATFORM = "linux-x64"


@pytest.fixture(scope="module")
def extension_zip(tmp_path_factory):
    if not sys.platform.startswith("linux"):
        pytest.skip("the probe installs the linux-x64 zip; this machine is not Linux")
    dist = tmp_path_factory.mktemp("dist")
    command = [sys.executable, str(ROOT / "tools" / "build_extension.py"), "--platforms", PLATFORM, "--dist", str(dist)]
    built = subprocess.run(command, capture_output=True, text=True, cwd=ROOT)
    output = built.stdout + built.stderr
    wheels_cached = any((ROOT / "wheels" / PLATFORM).glob("*.whl"))
    if built.returncode != 0 and "SKIPPED" in output and not wheels_cached:
        pytest.skip(f"cannot build the extension without PyPI (offline?): {output.strip()[-400:]}")
    assert built.returncode == 0, output
    assert "Blender validator: passed" in output
    (archive,) = dist.glob(f"visrad-*-{PLATFORM}.zip")
    return archive


def test_the_built_zip_installs_enables_works_and_uninstalls(extension_zip, tmp_path):
    environment = {**os.environ, "BLENDER_USER_RESOURCES": str(tmp_path / "blender")}
    environment.pop("NUMBA_CACHE_DIR", None)
    blend = ROOT / "sample_blends" / "cornell_box.blend"
    probe = subprocess.run(
        [sys.executable, str(PROBE), str(extension_zip), str(blend)],
        capture_output=True,
        text=True,
        env=environment,
        cwd=tmp_path,
        timeout=300,
    )
    lines = [line for line in probe.stdout.splitlines() if line.startswith("PROBE ")]
    assert probe.returncode == 0 and lines, probe.stdout[-2000:] + probe.stderr[-3000:]
    seen = json.loads(lines[-1].removeprefix("PROBE "))

    assert seen["install"] == ["FINISHED"] and seen["enabled"]
    assert {"VISRAD_OT_check_scene", "VISRAD_OT_clear_results", "VISRAD_PT_main"} <= set(seen["operators"])
    assert seen["check_scene"] == ["FINISHED"]
    assert seen["summary"].startswith(f"{SCENES['cornell-box']().n_polygons} polygons")
    installed = Path(seen["core_file"]).resolve()
    assert installed.is_relative_to((tmp_path / "blender").resolve()), "core must come from the installed zip"
    user_dir = Path(seen["extension_user_dir"]).resolve()
    assert seen["kernel_cache_dirs"] and all(
        Path(path).resolve().is_relative_to(user_dir / "numba") for path in seen["kernel_cache_dirs"]
    )
    assert seen["numba_cache_env_after_import"] is None, "the cache directory is set only while core imports"
    assert seen["disabled"] and seen["operators_after_disable"] == []
    assert seen["uninstall"] == ["FINISHED"] and not seen["installed_after_uninstall"]
