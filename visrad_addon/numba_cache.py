"""Where numba keeps the compiled kernels of core (they are compiled with cache=True).

numba decides a kernel's cache directory when the kernel's module is imported, from `numba.config.CACHE_DIR`
(the NUMBA_CACHE_DIR environment variable; empty means a `__pycache__` folder beside the source). A cache entry
records the module's import name, and numba imports that name again when it loads the entry: one cache
directory must never serve two import names of the same source files, or loading fails ("No module named ...").

The directory for the add-on's core:

* installed as an extension (package `bl_ext.<repo>.visrad`): the extension's user directory,
  `bpy.utils.extension_path_user(package, path="numba")`. The extension's own folder is no place for it: it is
  wiped on upgrade and read-only in system repositories. Kernels compile once per machine, not per session.
* run from a checkout under another package name (the tests' `visrad`, batch runs): `<checkout>/__pycache__/
  numba/<package>` (git-ignored like every `__pycache__`). The checkout's `core/__pycache__` belongs to the
  plain `core` package that tests/core and the benchmarks import.

A NUMBA_CACHE_DIR the user set is respected. Otherwise the directory is set (NUMBA_CACHE_DIR and numba's
config) exactly while a module of `<package>.core` executes, by an import hook, and restored afterwards. So
every core kernel gets it however and whenever core is imported, other users of numba in the process (another
add-on, or the plain `core` package in the same pytest run) keep their own setting, and importing the add-on
does not import numba: that waits until a stage needs core's kernels.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import os
import sys
from contextlib import contextmanager
from pathlib import Path

EXTENSION_PREFIX = "bl_ext."
CHECKOUT_ROOT = Path(__file__).resolve().parent.parent


def configure(root_package: str) -> Path | None:
    """Give the kernels of `root_package`.core (root_package e.g. "bl_ext.user_default.visrad" or "visrad") a
    cache directory of their own; returns it, or None when the user's NUMBA_CACHE_DIR is kept."""
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    if root_package.startswith(EXTENSION_PREFIX):
        import bpy

        path = Path(bpy.utils.extension_path_user(root_package, path="numba", create=True))
    else:
        path = CHECKOUT_ROOT / "__pycache__" / "numba" / root_package
        path.mkdir(parents=True, exist_ok=True)
    prefix = f"{root_package}.core"
    if not any(isinstance(f, _CoreCacheFinder) and f.prefix == prefix for f in sys.meta_path):
        sys.meta_path.insert(0, _CoreCacheFinder(prefix, str(path)))
    return path


class _CoreCacheFinder(importlib.abc.MetaPathFinder):
    """Finds `<prefix>` and its submodules like the normal path finder, with a loader that executes them
    with numba's cache directory set."""

    def __init__(self, prefix: str, cache_dir: str):
        self.prefix = prefix
        self.cache_dir = cache_dir

    def find_spec(self, fullname, path, target=None):
        if fullname != self.prefix and not fullname.startswith(self.prefix + "."):
            return None
        spec = importlib.machinery.PathFinder.find_spec(fullname, path, target)
        if spec is not None and spec.loader is not None:
            spec.loader = _CacheDirLoader(spec.loader, self.cache_dir)
        return spec


class _CacheDirLoader(importlib.abc.Loader):
    """Wraps a module's loader: executes the module inside `_cache_dir`; everything else is delegated (source
    for tracebacks, resources, ...)."""

    def __init__(self, loader, cache_dir: str):
        self._loader = loader
        self._cache_dir = cache_dir

    def create_module(self, spec):
        return self._loader.create_module(spec)

    def exec_module(self, module):
        with _cache_dir(self._cache_dir):
            self._loader.exec_module(module)

    def __getattr__(self, name):
        return getattr(self._loader, name)


@contextmanager
def _cache_dir(path: str):
    """numba's cache directory is `path` inside the block, and what it was after it. numba reads the
    environment variable when it is imported (and again whenever it changed), so the variable is switched;
    if numba is loaded already, its config is switched too. numba itself is never imported here."""
    previous = os.environ.get("NUMBA_CACHE_DIR")
    config = sys.modules.get("numba.core.config")
    previous_config = config.CACHE_DIR if config is not None else (previous or "")
    os.environ["NUMBA_CACHE_DIR"] = path
    if config is not None:
        config.CACHE_DIR = path
    try:
        yield
    finally:
        if previous is None:
            os.environ.pop("NUMBA_CACHE_DIR", None)
        else:
            os.environ["NUMBA_CACHE_DIR"] = previous
        config = sys.modules.get("numba.core.config")
        if config is not None:
            config.CACHE_DIR = previous_config
