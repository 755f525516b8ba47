"""Make the repository importable as the package `visrad`, the way Blender imports the extension.

Inside Blender the add-on is `bl_ext.<repo>.visrad` and reaches the engine with relative imports
(`from ..core.scene import Scene`). The checkout's folder name need not be a valid package name, so this
conftest loads the repository root's __init__.py under the name `visrad` with the root as its search path:
`import visrad.visrad_addon.convert` then resolves `..core` to `visrad.core`, exactly as in Blender.
Note that `visrad.core` and the top-level `core` (which bench/scenes.py uses) are distinct module objects:
tests catch `visrad.core.errors.SceneError`. The add-on is imported here, before any test module, because
importing it gives `visrad.core`'s numba kernels a cache directory of their own (visrad_addon/numba_cache.py):
sharing core/__pycache__ with the plain `core` package would break loading the cache under either name.
"""

import importlib.util
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
PACKAGE = "visrad"

if PACKAGE not in sys.modules:
    spec = importlib.util.spec_from_file_location(PACKAGE, ROOT / "__init__.py", submodule_search_locations=[str(ROOT)])
    package = importlib.util.module_from_spec(spec)
    sys.modules[PACKAGE] = package
    spec.loader.exec_module(package)
    if importlib.util.find_spec("bpy") is not None:
        importlib.import_module(f"{PACKAGE}.visrad_addon")


if importlib.util.find_spec("bpy") is not None:
    import pytest

    @pytest.fixture(scope="session")
    def registered_addon():
        """The add-on registered (operators, panels, properties, handlers) for the whole test session."""
        addon = importlib.import_module(f"{PACKAGE}.visrad_addon")
        addon.register()
        yield addon
        addon.unregister()
