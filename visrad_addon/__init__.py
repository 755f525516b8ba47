"""VisRad Blender layer: Blender scene -> core.Scene, results -> result meshes and curves, operators and UI.

The numba cache is configured before anything imports core's kernels (see numba_cache.py).
"""

from . import numba_cache

numba_cache.configure(__package__.rpartition(".")[0])

from . import operators, properties, session, stages, ui  # noqa: E402

_modules = (properties, session, operators, stages, ui)


def register():
    for module in _modules:
        module.register()


def unregister():
    for module in reversed(_modules):
        module.unregister()
