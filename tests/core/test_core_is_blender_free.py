"""DESIGN.md section 1: core never imports bpy or mathutils, not even inside a function."""

import ast
import subprocess
import sys
from pathlib import Path

CORE = Path(__file__).resolve().parents[2] / "core"
FORBIDDEN = {"bpy", "mathutils", "bmesh"}


def imported_roots(path: Path) -> set[str]:
    roots = set()
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            roots.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
        elif isinstance(node, ast.Call) and getattr(node.func, "id", "") == "__import__":
            roots.update(arg.value.split(".")[0] for arg in node.args if isinstance(arg, ast.Constant))
    return roots


def test_no_blender_import_anywhere_in_core():
    files = sorted(CORE.rglob("*.py"))
    assert len(files) >= 6
    offenders = {str(f.relative_to(CORE)): imported_roots(f) & FORBIDDEN for f in files}
    assert not {k: v for k, v in offenders.items() if v}


def test_importing_every_core_module_loads_no_blender_module():
    modules = [".".join(f.relative_to(CORE.parent).with_suffix("").parts) for f in sorted(CORE.rglob("*.py"))]
    modules = [m.removesuffix(".__init__") for m in modules]
    code = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n    importlib.import_module(name)\n"
        f"print(sorted(set(sys.modules) & set({sorted(FORBIDDEN)!r})))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], cwd=CORE.parent, capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"
