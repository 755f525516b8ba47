"""Make the repository importable as the package `visrad`, the way Blender imports the extension.

Inside Blender the add-on is `bl_ext.<repo>.visrad` and reaches the engine with relative imports
(`from ..core.scene import Scene`). The checkout's folder name need not be a valid package name, so this
conftest loads the repository root's __init__.py under the name `visrad` with the root as its search path:
`import visrad.visrad_addon.convert` then resolves `..core` to `visrad.core`, exactly as in Blender.
Note that `visrad.core` and the top-level `core` (which bench/scenes.py uses) are distinct module objects:
tests catch `visrad.core.errors.SceneError`.
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
