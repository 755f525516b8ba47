"""Headless bake (DESIGN.md section 3): open a .blend, bake it with the add-on's operators, save a copy.

    blender -b in.blend -P visrad_addon/batch.py -- --output out.blend [options]
    python visrad_addon/batch.py in.blend --output out.blend [options]        (with the bpy module)

Options: --preset accurate|fast, --max-bounces N (0 = full global illumination, 1 = direct light only),
--jnd X, --max-iterations N (the file's own VisRad settings are used for what is not given), --stats FILE.json
(times, counts, memory), --render FILE.png (a Cycles render of the result meshes alone, from the scene's
camera), --render-samples N (default 16: the results are pure emission, samples only anti-alias),
--render-percent P (resolution scale), --render-exposure EV|auto (auto puts the area-weighted mean luminance
of the results at middle grey; default the scene's colour management), --render-discontinuities FILE.png (the
same render with the inserted discontinuity curves drawn over it as thin red tubes), --scene NAME (default:
the active scene).

The script runs the same operator as the panel's Bake button (`visrad.bake`: visibility, coarse lighting,
refinement until converged or --max-iterations, then the result meshes), so the saved file holds exactly what
an interactive bake makes. When the visrad extension is installed and enabled in this Blender, its operators
are used; otherwise the add-on is registered from the checkout this script lives in (as the package `visrad`).

Safety: the input file is never written. An output path equal to the input (or any of the outputs equal to
one another) is refused before anything is done; the baked file is saved with `copy=True`, so Blender's
notion of the open file does not change either. The render runs after the .blend was saved: it hides the
original meshes from render only while it renders and restores them and every render setting it changed.
Lights stay as they are; they light nothing in that render (the result meshes are pure emission).

Exit status: 0 on success; 1 with one readable line on stderr ("visrad batch: error: ...") when the file
cannot be opened, the scene cannot be baked (no light, no mesh, a broken polygon, ...) or an output cannot be
written; 2 for bad command-line arguments.
"""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import os
import sys
import time
from pathlib import Path

CHECKOUT = Path(__file__).resolve().parent.parent
# the package name the checkout is registered under when the extension is not installed (the tests use it too,
# so both share the numba cache in <checkout>/__pycache__/numba/visrad)
PACKAGE = "visrad"
PRESETS = ("accurate", "fast")


class BatchError(Exception):
    """A failure with a message meant for the user."""


def parse_args(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(
        prog="visrad batch",
        description="Bake radiosity into a copy of a .blend file with the VisRad add-on.",
        epilog="With Blender: blender -b in.blend -P visrad_addon/batch.py -- --output out.blend [options]",
    )
    parser.add_argument(
        "input", nargs="?", type=Path, help="the .blend file to bake (default: the file Blender has opened)"
    )
    parser.add_argument("--output", required=True, type=Path, help="where to save the baked .blend (not the input)")
    parser.add_argument("--preset", choices=PRESETS, help="solver preset (default: the file's VisRad settings)")
    parser.add_argument("--max-bounces", type=int, metavar="N", help="0 = full global illumination, 1 = direct only")
    parser.add_argument("--jnd", type=float, metavar="X", help="just noticeable difference, in (0, 1)")
    parser.add_argument("--max-iterations", type=int, metavar="N", help="most refinement iterations (>= 1)")
    parser.add_argument("--stats", type=Path, metavar="FILE.json", help="write times, counts and memory as JSON")
    parser.add_argument("--render", type=Path, metavar="FILE.png", help="render the baked result meshes (Cycles)")
    parser.add_argument("--render-samples", type=int, default=16, metavar="N", help="Cycles samples (default 16)")
    parser.add_argument("--render-percent", type=int, default=100, metavar="P", help="resolution scale (default 100)")
    parser.add_argument(
        "--render-exposure",
        type=_exposure,
        metavar="EV|auto",
        help="exposure of the render in stops, or auto (mean radiance of the results at middle grey); "
        "default: the scene's own colour management",
    )
    parser.add_argument(
        "--render-discontinuities",
        type=Path,
        metavar="FILE.png",
        help="the same render with the discontinuity curves drawn in red (needs a camera)",
    )
    parser.add_argument("--scene", metavar="NAME", help="the scene to bake (default: the file's active scene)")
    args = parser.parse_args(argv)
    if args.max_bounces is not None and args.max_bounces < 0:
        parser.error("--max-bounces must be 0 (full global illumination) or more")
    if args.jnd is not None and not 0.0 < args.jnd < 1.0:
        parser.error("--jnd must lie between 0 and 1")
    if args.max_iterations is not None and args.max_iterations < 1:
        parser.error("--max-iterations must be 1 or more")
    if args.render_samples < 1 or not 1 <= args.render_percent <= 400:
        parser.error("--render-samples must be 1 or more and --render-percent between 1 and 400")
    return args


def _exposure(text: str) -> float | str:
    if text == "auto":
        return text
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of stops or auto, got {text!r}") from None


def script_arguments(argv: list[str]) -> list[str]:
    """The script's own arguments: after "--" under Blender, everything after the script name otherwise."""
    return argv[argv.index("--") + 1 :] if "--" in argv else argv[1:]


def main(argv: list[str] | None = None) -> int:
    started = time.perf_counter()
    args = parse_args(script_arguments(sys.argv if argv is None else argv))
    try:
        stats = bake(args, started)
    except BatchError as error:
        print(f"visrad batch: error: {error}", file=sys.stderr, flush=True)
        return 1
    print(
        f"visrad batch: baked {stats['input']} -> {stats['output']} in {stats['seconds']['total']:.1f} s "
        f"({stats['counts']['triangles_written']:,} triangles, {stats['counts']['result_objects']} result meshes)",
        file=sys.stderr,
        flush=True,
    )
    return 0


def bake(args: argparse.Namespace, started: float) -> dict:
    """Everything the script does; returns the statistics (also written to --stats)."""
    try:
        import bpy
    except ImportError:
        raise BatchError(
            "the bpy module is not available: run this script with `blender -b in.blend -P visrad_addon/batch.py "
            "-- --output out.blend` or with a Python that has the bpy module (pip install bpy)"
        ) from None
    source = _input_path(args, bpy)
    output = _absolute(args.output)
    _check_outputs(source, output, args)

    seconds = {}
    clock = time.perf_counter()
    if not bpy.data.filepath or not _same_file(Path(bpy.data.filepath), source):
        try:
            bpy.ops.wm.open_mainfile(filepath=str(source), load_ui=False)
        except RuntimeError as error:
            raise BatchError(f"cannot open {source}: {_operator_message(error)}") from None
    seconds["open"] = time.perf_counter() - clock
    blender_scene = _scene(bpy, args.scene)
    if bpy.context.window is not None:
        bpy.context.window.scene = blender_scene
    addon, origin = ensure_addon(bpy)
    print(f"visrad batch: using the add-on {origin}", file=sys.stderr, flush=True)
    settings = apply_settings(addon, blender_scene.visrad, args)

    clock = time.perf_counter()
    with bpy.context.temp_override(scene=blender_scene):
        try:
            outcome = bpy.ops.visrad.bake()
        except RuntimeError as error:
            raise BatchError(_operator_message(error)) from None
    seconds["bake"] = time.perf_counter() - clock
    if outcome != {"FINISHED"}:
        raise BatchError(f"the bake did not finish ({', '.join(sorted(outcome))})")
    session = addon.session.store.get(blender_scene)
    solver_stats = dict(session.state[addon.stages.STATS])
    written = dict(session.state[addon.stages.WRITTEN])

    clock = time.perf_counter()
    output.parent.mkdir(parents=True, exist_ok=True)
    filepaths = bpy.context.preferences.filepaths
    versions, filepaths.save_version = filepaths.save_version, 0  # no out.blend1 backup beside the output
    try:
        bpy.ops.wm.save_as_mainfile(filepath=str(output), copy=True, compress=True)
    except RuntimeError as error:
        raise BatchError(f"cannot save {output}: {_operator_message(error)}") from None
    finally:
        filepaths.save_version = versions
    seconds["save"] = time.perf_counter() - clock

    if args.render is not None:
        clock = time.perf_counter()
        render = _absolute(args.render)
        exposure = render_results(
            bpy, blender_scene, addon, render, args.render_samples, args.render_percent, args.render_exposure
        )
        seconds["render"] = time.perf_counter() - clock
    if args.render_discontinuities is not None:
        clock = time.perf_counter()
        render_results(
            bpy, blender_scene, addon, _absolute(args.render_discontinuities), args.render_samples,
            args.render_percent, args.render_exposure, curves=True,
        )  # fmt: skip
        seconds["render_discontinuities"] = time.perf_counter() - clock

    seconds["stages"] = solver_stats.pop("seconds", {})
    seconds["write_results"] = written["seconds"]
    seconds["total"] = time.perf_counter() - started
    stats = {
        "input": str(source),
        "output": str(output),
        "output_bytes": output.stat().st_size,
        "render": str(_absolute(args.render)) if args.render is not None else None,
        "render_bytes": _absolute(args.render).stat().st_size if args.render is not None else None,
        "render_exposure": exposure if args.render is not None else None,
        "render_discontinuities": (
            str(_absolute(args.render_discontinuities)) if args.render_discontinuities is not None else None
        ),
        "scene": blender_scene.name,
        "blender": bpy.app.version_string,
        "addon": origin,
        "settings": settings,
        "seconds": seconds,
        "counts": {
            "polygons": len(session.source_map.polygon_object),
            "convex_polygons": session.scene.n_polygons,
            "objects": sum(source.kind == "mesh" for source in session.source_map.objects),
            "area_lights": sum(source.kind == "area light" for source in session.source_map.objects),
            "emitting_polygons": len(session.scene.lights),
            "links": solver_stats.get("links"),
            "vertices": solver_stats.get("vertices"),
            "triangles": solver_stats.get("leaf_triangles"),
            "iterations": solver_stats.get("iterations"),
            "converged": solver_stats.get("converged"),
            "result_objects": len(written["objects"]),
            "triangles_written": written["triangles"],
            "discontinuity_segments": written["segments"],
        },
        "memory": {"peak_bytes": solver_stats.get("peak_bytes")},
        "refinement": solver_stats.get("refinement", []),
        "warnings": list(session.source_map.warnings),
    }
    if args.stats is not None:
        path = _absolute(args.stats)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(stats, indent=2) + "\n")
        except OSError as error:
            raise BatchError(f"cannot write the statistics to {path}: {error}") from None
    return stats


# ---------------------------------------------------------------------------------------------------------
# Paths


def _absolute(path: Path) -> Path:
    return Path(os.path.abspath(path.expanduser()))


def _same_file(a: Path, b: Path) -> bool:
    if _absolute(a) == _absolute(b):
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _input_path(args, bpy) -> Path:
    if args.input is not None:
        source = _absolute(args.input)
    elif bpy.data.filepath:
        source = _absolute(Path(bpy.data.filepath))
    else:
        raise BatchError("no input .blend: give it as the first argument (or open it with blender -b in.blend)")
    if not source.is_file():
        raise BatchError(f"the input file {source} does not exist")
    return source


def _check_outputs(source: Path, output: Path, args) -> None:
    if output.suffix.lower() != ".blend":
        raise BatchError(f"--output must be a .blend file, got {output}")
    named = [("--output", output)]
    if args.stats is not None:
        named.append(("--stats", _absolute(args.stats)))
    if args.render is not None:
        named.append(("--render", _absolute(args.render)))
    if args.render_discontinuities is not None:
        named.append(("--render-discontinuities", _absolute(args.render_discontinuities)))
    for option, path in named:
        if _same_file(path, source):
            raise BatchError(f"{option} {path} is the input file: batch.py never overwrites its input")
    for index, (option, path) in enumerate(named):
        for other, other_path in named[index + 1 :]:
            if _same_file(path, other_path):
                raise BatchError(f"{option} and {other} are the same file {path}")


def _scene(bpy, name: str | None):
    if name is None:
        return bpy.context.scene
    scene = bpy.data.scenes.get(name)
    if scene is None:
        names = ", ".join(repr(s.name) for s in bpy.data.scenes)
        raise BatchError(f"the file has no scene {name!r} (scenes: {names})")
    return scene


def _operator_message(error: RuntimeError) -> str:
    """An operator's error report without Blender's "Error: " prefix and trailing newline."""
    text = str(error).strip()
    return text.removeprefix("Error: ").strip()


# ---------------------------------------------------------------------------------------------------------
# The add-on


def ensure_addon(bpy):
    """(the add-on package module, where it comes from): the enabled extension's, or this checkout's
    registered under the package name `visrad`."""
    operator = getattr(bpy.types, "VISRAD_OT_bake", None)
    if operator is not None:
        package = operator.__module__.rpartition(".")[0]
        return importlib.import_module(package), f"{package} (installed)"
    root = sys.modules.get(PACKAGE)
    if root is None:
        spec = importlib.util.spec_from_file_location(
            PACKAGE, CHECKOUT / "__init__.py", submodule_search_locations=[str(CHECKOUT)]
        )
        root = importlib.util.module_from_spec(spec)
        sys.modules[PACKAGE] = root
        spec.loader.exec_module(root)
    elif [str(CHECKOUT)] != list(getattr(root, "__path__", [])):
        raise BatchError(f"another module named {PACKAGE!r} is loaded ({root!r}): cannot load the add-on")
    addon = importlib.import_module(f"{PACKAGE}.visrad_addon")
    addon.register()
    return addon, f"from the checkout {CHECKOUT}"


def apply_settings(addon, props, args) -> dict:
    """Put the command line's settings into the scene's VisRad settings; returns them as the add-on reads
    them. A preset sets its values first; --jnd or --max-iterations then make the settings custom."""
    if args.preset is not None:
        props.preset = args.preset.upper()
    if args.jnd is not None or args.max_iterations is not None:
        props.preset = "CUSTOM"
        if args.jnd is not None:
            props.jnd = args.jnd
        if args.max_iterations is not None:
            props.max_iterations = args.max_iterations
    if args.max_bounces is not None:
        props.max_bounces = args.max_bounces
    return addon.properties.solver_settings(props)


# ---------------------------------------------------------------------------------------------------------
# Render


MIDDLE_GREY = 0.18
LUMINANCE = (0.2126, 0.7152, 0.0722)  # Rec. 709 weights of linear RGB


def render_results(
    bpy, blender_scene, addon, path: Path, samples: int, percent: int, exposure=None, curves: bool = False
) -> float:
    """Render the scene's result meshes alone with Cycles into the PNG `path`; the original meshes are hidden
    from render meanwhile and every setting is restored afterwards. exposure: stops, "auto" or None (the
    scene's own). curves: also draw the discontinuity curves, as thin emissive red tubes for this render only.
    Returns the exposure used."""
    if blender_scene.camera is None:
        raise BatchError(f'--render needs a camera: scene "{blender_scene.name}" has none')
    role = addon.write_back.ROLE_PROPERTY
    hidden = [
        obj
        for obj in blender_scene.objects
        if obj.get(role) is None and obj.type not in {"CAMERA", "LIGHT"} and not obj.hide_render
    ]
    render, cycles = blender_scene.render, blender_scene.cycles
    saved = [
        (render, "engine", render.engine),
        (render, "filepath", render.filepath),
        (render, "resolution_percentage", render.resolution_percentage),
        (render.image_settings, "file_format", render.image_settings.file_format),
        (render.image_settings, "color_mode", render.image_settings.color_mode),
        (render.image_settings, "compression", render.image_settings.compression),
        (blender_scene.view_settings, "exposure", blender_scene.view_settings.exposure),
    ]
    if exposure == "auto":
        exposure = auto_exposure(addon, blender_scene)
    elif exposure is None:
        exposure = blender_scene.view_settings.exposure
    drawn = _draw_curves(bpy, blender_scene, addon, exposure) if curves else None
    try:
        for obj in hidden:
            obj.hide_render = True
        render.engine = "CYCLES"
        saved += [(cycles, name, getattr(cycles, name)) for name in ("samples", "use_denoising", "device")]
        cycles.samples, cycles.use_denoising, cycles.device = samples, False, "CPU"
        render.resolution_percentage = percent
        render.image_settings.file_format = "PNG"
        render.image_settings.color_mode = "RGB"
        render.image_settings.compression = 100
        blender_scene.view_settings.exposure = exposure
        path.parent.mkdir(parents=True, exist_ok=True)
        render.filepath = str(path)
        try:
            bpy.ops.render.render(write_still=True, scene=blender_scene.name)
        except RuntimeError as error:
            raise BatchError(f"the render failed: {_operator_message(error)}") from None
    finally:
        for owner, name, value in reversed(saved):
            setattr(owner, name, value)
        for obj in hidden:
            obj.hide_render = False
        if drawn is not None:
            _undraw_curves(bpy, *drawn)
    if not path.is_file():
        raise BatchError(f"the render was not written to {path}")
    return float(exposure)


# the drawn curves' tube radius, as a fraction of the diagonal of the result meshes' bounding box
_CURVE_RADIUS = 0.0015


def _draw_curves(bpy, blender_scene, addon, exposure: float) -> tuple:
    """Give the scene's discontinuity curve objects a bevel and a red emission bright enough at `exposure`;
    returns what _undraw_curves needs to take it back. Result objects have identity transforms, so their
    bounding boxes are in world space."""
    role = addon.write_back.ROLE_PROPERTY
    objects = [obj for obj in blender_scene.objects if obj.get(role) is not None]
    corners = [tuple(corner) for obj in objects for corner in obj.bound_box]
    extent = [max(c[k] for c in corners) - min(c[k] for c in corners) for k in range(3)] if corners else [0.0] * 3
    diagonal = sum(e * e for e in extent) ** 0.5
    material = bpy.data.materials.new("VisRad discontinuity preview")
    if bpy.app.version < (5, 0, 0):
        material.use_nodes = True
    nodes = material.node_tree.nodes
    nodes.clear()
    emission = nodes.new("ShaderNodeEmission")
    emission.inputs["Color"].default_value = (1.0, 0.02, 0.02, 1.0)
    emission.inputs["Strength"].default_value = 2.0 ** (-exposure)
    output = nodes.new("ShaderNodeOutputMaterial")
    material.node_tree.links.new(emission.outputs["Emission"], output.inputs["Surface"])
    saved = []
    for obj in objects:
        if obj.type != "CURVE":
            continue
        saved.append((obj, obj.data.bevel_depth, obj.visible_camera))
        obj.data.bevel_depth = _CURVE_RADIUS * diagonal
        obj.data.materials.append(material)
        obj.visible_camera = True
    return material, saved


def _undraw_curves(bpy, material, saved) -> None:
    for obj, depth, visible in saved:
        obj.data.materials.pop()
        obj.data.bevel_depth = depth
        obj.visible_camera = visible
    bpy.data.materials.remove(material)


def auto_exposure(addon, blender_scene) -> float:
    """Stops that bring the area-weighted mean luminance of the result meshes' radiance to middle grey."""
    import numpy as np

    role, attribute = addon.write_back.ROLE_PROPERTY, addon.write_back.RADIANCE_ATTRIBUTE
    total_area = total_light = 0.0
    for obj in blender_scene.objects:
        if obj.get(role) != addon.write_back.ROLE_RESULT_OBJECT or obj.type != "MESH":
            continue
        mesh = obj.data
        positions = np.empty(3 * len(mesh.vertices), np.float32)
        mesh.vertices.foreach_get("co", positions)
        corners = np.empty(len(mesh.loops), np.int32)
        mesh.loops.foreach_get("vertex_index", corners)
        colours = np.empty(4 * len(mesh.vertices), np.float32)
        mesh.color_attributes[attribute].data.foreach_get("color", colours)
        luminance = colours.reshape(-1, 4)[:, :3].astype(np.float64) @ np.array(LUMINANCE)
        triangles = corners.reshape(-1, 3)  # result meshes are triangles
        a, b, c = (positions.reshape(-1, 3)[triangles[:, k]].astype(np.float64) for k in range(3))
        areas = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
        total_area += areas.sum()
        total_light += (areas * luminance[triangles].mean(axis=1)).sum()
    if total_light <= 0.0:
        return 0.0
    return float(np.log2(MIDDLE_GREY * total_area / total_light))


if __name__ == "__main__":
    sys.exit(main())
