"""The two worlds meet only through files: splatting/ never imports bpy, the add-on never imports
torch, and the file contract (cyclist_formats/) imports neither (docs/contract.md)."""
import ast
import os
import subprocess
import sys

import pytest

from helpers import ROOT

FORBIDDEN = {
    "splatting": {"bpy", "mathutils", "bmesh"},
    "cyclist_formats": {"bpy", "mathutils", "bmesh", "torch", "roma", "plyfile"},
    "addon": {"torch", "roma", "splatting"},
}


def imported_modules(folder):
    """(file, line, top-level module) of every import statement below folder, lazy ones included."""
    for d, _, files in os.walk(os.path.join(ROOT, folder)):
        for f in files:
            if not f.endswith(".py"):
                continue
            path = os.path.join(d, f)
            tree = ast.parse(open(path).read(), path)
            for node in ast.walk(tree):
                if isinstance(node, ast.Import):
                    for a in node.names:
                        yield path, node.lineno, a.name.split(".")[0]
                elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    yield path, node.lineno, node.module.split(".")[0]


@pytest.mark.parametrize("folder", sorted(FORBIDDEN))
def test_no_forbidden_imports(folder):
    bad = [f"{os.path.relpath(p, ROOT)}:{ln} imports {m}" for p, ln, m in imported_modules(folder)
           if m in FORBIDDEN[folder]]
    assert not bad, "\n".join(bad)


def test_scan_sees_a_forbidden_import(tmp_path, monkeypatch):
    """The scan itself works: an import of bpy inside a function is found."""
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "m.py").write_text("def f():\n    import bpy.types\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", str(tmp_path))
    assert [m for _, _, m in imported_modules("pkg")] == ["bpy"]


def test_importing_every_splatting_module_loads_no_bpy():
    code = ("import pkgutil, importlib, sys, splatting, cyclist_formats\n"
            "for pkg in (splatting, cyclist_formats):\n"
            "    for m in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):\n"
            "        importlib.import_module(m.name)\n"
            "bad = sorted(k for k in sys.modules if k.split('.')[0] in ('bpy', 'mathutils'))\n"
            "print(len(sys.modules)); assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       env=dict(os.environ, OMP_NUM_THREADS="1"))
    assert r.returncode == 0, r.stderr[-2000:]


def test_contract_imports_without_torch():
    code = ("import sys, pkgutil, importlib, cyclist_formats\n"
            "for m in pkgutil.walk_packages(cyclist_formats.__path__, 'cyclist_formats.'):\n"
            "    importlib.import_module(m.name)\n"
            "bad = sorted(k for k in sys.modules if k.split('.')[0] in ('torch', 'bpy', 'plyfile'))\n"
            "assert not bad, bad\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-2000:]
