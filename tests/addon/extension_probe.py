"""Install, enable, use, disable and uninstall a built VisRad extension zip; print what was seen as JSON.

    BLENDER_USER_RESOURCES=<temporary dir> python extension_probe.py ZIP BLEND

Run by test_extension_install.py in a subprocess with a throw-away user resource directory, so the real
user's extensions are never touched and the add-on is imported from the installed zip, not the checkout.
The last line of output is "PROBE <json>".
"""

import importlib
import json
import os
import sys

import bpy

REPO = "user_default"
MODULE = f"bl_ext.{REPO}.visrad"


def main(archive: str, blend: str) -> dict:
    seen = {}
    result = bpy.ops.extensions.package_install_files(filepath=archive, repo=REPO, enable_on_install=True)
    seen["install"] = sorted(result)
    seen["enabled"] = MODULE in bpy.context.preferences.addons
    seen["operators"] = sorted(name for name in dir(bpy.types) if name.startswith("VISRAD_"))
    seen["panels"] = [name for name in seen["operators"] if "_PT_" in name]

    bpy.ops.wm.open_mainfile(filepath=blend)
    seen["check_scene"] = sorted(bpy.ops.visrad.check_scene())
    session = sys.modules[f"{MODULE}.visrad_addon.session"].store.get(bpy.context.scene)
    seen["summary"] = session.summary

    visibility = importlib.import_module(f"{MODULE}.core.visibility")
    from numba.core.registry import CPUDispatcher

    kernels = [k for k in vars(visibility).values() if isinstance(k, CPUDispatcher)]
    seen["kernel_cache_dirs"] = sorted({k._cache._cache_path for k in kernels})
    seen["extension_user_dir"] = bpy.utils.extension_path_user(MODULE)
    seen["core_file"] = visibility.__file__
    seen["numba_cache_env_after_import"] = os.environ.get("NUMBA_CACHE_DIR")

    repo_directory = bpy.utils.user_resource("EXTENSIONS", path=REPO)
    bpy.ops.preferences.addon_disable(module=MODULE)
    seen["disabled"] = MODULE not in bpy.context.preferences.addons
    seen["operators_after_disable"] = sorted(name for name in dir(bpy.types) if name.startswith("VISRAD_"))
    seen["uninstall"] = sorted(bpy.ops.extensions.package_uninstall(repo_directory=repo_directory, pkg_id="visrad"))
    seen["installed_after_uninstall"] = os.path.exists(os.path.join(repo_directory, "visrad"))
    return seen


if __name__ == "__main__":
    print("PROBE " + json.dumps(main(*sys.argv[1:3])))
