"""Build the per-platform VisRad extension zips and validate them with Blender's own extension validator.

    .venv/bin/python tools/build_extension.py [--platforms linux-x64 ...] [--no-validate] [--dist DIR]

For each Blender platform the script downloads, with `pip download --only-binary=:all: --no-deps`, the
unmodified wheels of scipy, numba, llvmlite and pythoncdt for CPython 3.11 (Blender 4.2-5.0) and 3.13
(Blender 5.1+) into wheels/<platform>/ (git-ignored; never committed), at the versions pinned in
requirements.txt. numpy is not bundled: Blender ships it. It then writes a copy of blender_manifest.toml
listing those wheels and the platform, zips the extension into dist/visrad-<version>-<platform>.zip, and runs
`blender_ext.py validate` (the code behind `blender --command extension validate`, bundled in the bpy
module) on the zip in a subprocess. A platform for which some wheel does not exist on PyPI is skipped with a
message naming the missing wheel; the exit status is non-zero when a platform was skipped or failed
validation.
"""

from __future__ import annotations

import argparse
import importlib.util
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MANIFEST = ROOT / "blender_manifest.toml"
REQUIREMENTS = ROOT / "requirements.txt"
WHEEL_DIR = ROOT / "wheels"
DIST_DIR = ROOT / "dist"
PACKAGE_DIRS = ("core", "visrad_addon")

BUNDLED = ("scipy", "numba", "llvmlite", "pythoncdt")
PYTHON_VERSIONS = ("3.11", "3.13")

# pip platform tags per Blender platform. pip expands a macOS tag to every older macOS version of the same
# architecture, so the tag is the newest macOS a wheel may require: Blender 4.2 runs on macOS 11.2 (arm64) and
# 10.15 (x64), and scipy's newest wheels need macOS 12 (arm64) / 10.14 (x64).
PIP_PLATFORMS = {
    "linux-x64": ("manylinux_2_28_x86_64", "manylinux_2_17_x86_64", "manylinux2014_x86_64"),
    "windows-x64": ("win_amd64",),
    "macos-arm64": ("macosx_12_0_arm64",),
    "macos-x64": ("macosx_10_15_x86_64",),
}

# A fixed timestamp makes the zips byte-identical from one build to the next.
ZIP_DATE = (2024, 1, 1, 0, 0, 0)


class MissingWheel(RuntimeError):
    """No wheel on PyPI for one package, Python version and platform."""


def pinned_versions(requirements: Path = REQUIREMENTS) -> dict[str, str]:
    """The `name==version` pins of the bundled packages in requirements.txt."""
    pins = {}
    for line in requirements.read_text().splitlines():
        requirement = line.split("#", 1)[0].strip()
        name, separator, version = requirement.partition("==")
        if separator and name.strip().lower() in BUNDLED:
            pins[name.strip().lower()] = version.strip()
    missing = [name for name in BUNDLED if name not in pins]
    if missing:
        raise SystemExit(f"{requirements}: no '==' pin for {', '.join(missing)}")
    return pins


def download_wheels(platform: str, pins: dict[str, str]) -> list[Path]:
    """Download the bundled wheels of one Blender platform for every Python version; returns their paths."""
    target = WHEEL_DIR / platform
    target.mkdir(parents=True, exist_ok=True)
    wheels: list[Path] = []
    for python_version in PYTHON_VERSIONS:
        for name in BUNDLED:
            requirement = f"{name}=={pins[name]}"
            command = [sys.executable, "-m", "pip", "download", "--quiet", "--disable-pip-version-check"]
            command += ["--only-binary=:all:", "--no-deps", "--python-version", python_version, "-d", str(target)]
            for tag in PIP_PLATFORMS[platform]:
                command += ["--platform", tag]
            before = set(target.glob("*.whl"))
            completed = subprocess.run([*command, requirement], capture_output=True, text=True)
            if completed.returncode != 0:
                errors = [line for line in completed.stderr.splitlines() if line.startswith("ERROR")]
                raise MissingWheel(
                    f"no wheel of {requirement} for CPython {python_version} on {platform} "
                    f"(pip platforms {', '.join(PIP_PLATFORMS[platform])}); pip says: "
                    + (" ".join(errors) or completed.stderr.strip()[-300:])
                )
            wheels.append(_downloaded_wheel(target, name, pins[name], python_version, before))
    return wheels


def _downloaded_wheel(target: Path, name: str, version: str, python_version: str, before: set[Path]) -> Path:
    """The wheel pip just fetched (or had already fetched earlier) for `name` and the Python version."""
    new = set(target.glob("*.whl")) - before
    if len(new) == 1:
        return new.pop()
    # pip reports success without downloading when a matching wheel is already in the folder
    python_tag = "cp" + python_version.replace(".", "")
    candidates = [
        wheel
        for wheel in target.glob(f"{name}-{version}-*.whl")
        if python_tag in wheel.name.split("-")[2].split(".") or "py3" in wheel.name.split("-")[2].split(".")
    ]
    if len(candidates) != 1:
        raise MissingWheel(f"expected one {name} {version} wheel for {python_tag} in {target}, found {candidates}")
    return candidates[0]


def platform_manifest(manifest_text: str, platform: str, wheel_names: list[str]) -> str:
    """The manifest text with `platforms` and `wheels` added as top-level keys (before the first table)."""
    existing = tomllib.loads(manifest_text)
    for key in ("platforms", "wheels"):
        if key in existing:
            raise SystemExit(f"{MANIFEST} already sets `{key}`: the build script owns that key")
    wheels = ",\n".join(f'  "./wheels/{name}"' for name in sorted(set(wheel_names)))
    added = f'platforms = ["{platform}"]\nwheels = [\n{wheels},\n]\n\n'
    lines = manifest_text.splitlines(keepends=True)
    first_table = next((i for i, line in enumerate(lines) if line.lstrip().startswith("[")), len(lines))
    text = "".join(lines[:first_table]) + added + "".join(lines[first_table:])
    parsed = tomllib.loads(text)
    assert parsed["platforms"] == [platform] and len(parsed["wheels"]) == len(set(wheel_names))
    return text


def extension_files() -> list[tuple[Path, str]]:
    """(file, archive name) of the add-on's own sources: the root __init__.py, core/ and visrad_addon/."""
    files = [(ROOT / "__init__.py", "__init__.py")]
    for package in PACKAGE_DIRS:
        for path in sorted((ROOT / package).rglob("*")):
            if path.is_file() and "__pycache__" not in path.parts and path.suffix != ".pyc":
                files.append((path, path.relative_to(ROOT).as_posix()))
    return files


def write_zip(archive: Path, manifest_text: str, wheels: list[Path]) -> None:
    archive.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(archive, "w") as zf:

        def add(name: str, data: bytes, compress: bool) -> None:
            info = zipfile.ZipInfo(name, date_time=ZIP_DATE)
            info.compress_type = zipfile.ZIP_DEFLATED if compress else zipfile.ZIP_STORED
            info.external_attr = 0o644 << 16
            zf.writestr(info, data)

        add("blender_manifest.toml", manifest_text.encode(), True)
        for path, name in extension_files():
            add(name, path.read_bytes(), True)
        # wheels are zip files already: storing them saves time and changes nothing in size
        for wheel in sorted(set(wheels)):
            add(f"wheels/{wheel.name}", wheel.read_bytes(), False)


def blender_extension_validator() -> tuple[Path, Path]:
    """Paths of blender_ext.py (the `blender --command extension` implementation) and of Blender's valid tags
    list, both from the bpy module's bundled scripts."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or spec.origin is None:
        raise SystemExit("the bpy module is not installed: .venv/bin/pip install -r requirements-blender.txt")
    bpy_dir = Path(spec.origin).parent
    scripts = sorted(bpy_dir.glob("*/scripts/addons_core/bl_pkg/cli/blender_ext.py"))
    if not scripts:
        raise SystemExit(f"blender_ext.py not found under {bpy_dir}/*/scripts/addons_core/bl_pkg/cli")
    script = scripts[-1]
    tags = script.parents[4] / "modules" / "_bpy_internal" / "extensions" / "tags.py"
    return script, tags


def validate(archive: Path) -> tuple[bool, str]:
    """Run Blender's validator on one zip, with Blender's valid tags, as `blender --command extension
    validate` does. Returns (passed, its output)."""
    script, tags = blender_extension_validator()
    command = [sys.executable, str(script), "validate", str(archive)]
    if tags.is_file():
        command += ["--valid-tags", str(tags)]
    completed = subprocess.run(command, capture_output=True, text=True)
    return completed.returncode == 0, (completed.stdout + completed.stderr).strip()


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--platforms", nargs="+", choices=sorted(PIP_PLATFORMS), default=list(PIP_PLATFORMS))
    parser.add_argument("--no-validate", action="store_true", help="build the zips without validating them")
    parser.add_argument("--dist", type=Path, default=DIST_DIR, help=f"where the zips go (default {DIST_DIR})")
    args = parser.parse_args(argv)

    manifest_text = MANIFEST.read_text()
    version = tomllib.loads(manifest_text)["version"]
    pins = pinned_versions()
    failures = 0
    for platform in args.platforms:
        try:
            wheels = download_wheels(platform, pins)
        except MissingWheel as missing:
            print(f"SKIPPED {platform}: {missing}")
            failures += 1
            continue
        archive = args.dist / f"visrad-{version}-{platform}.zip"
        write_zip(archive, platform_manifest(manifest_text, platform, [w.name for w in wheels]), wheels)
        size = archive.stat().st_size / 2**20
        print(f"built {archive} ({size:.1f} MiB, {len(set(wheels))} wheels)")
        for wheel in sorted({w.name for w in wheels}):
            print(f"    {wheel}")
        if args.no_validate:
            continue
        passed, output = validate(archive)
        print(f"    Blender validator: {'passed' if passed else 'FAILED'}" + (f"\n{output}" if output else ""))
        failures += not passed
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
