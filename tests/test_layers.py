"""Dependencies point one way (docs/architecture.md): the import-linter contracts in .importlinter
hold, a wrong-way import breaks them, the import graph of splatting, cyclist_formats and the
add-on has no circle (checked on the graph, and by importing every module alone), and no module of
the add-on's core takes a private name of another."""
import ast
import json
import os
import shutil
import subprocess
import sys

import grimp
import pytest

from helpers import ROOT

PACKAGES = ("splatting", "cyclist_formats", "addon")
LINT = shutil.which("lint-imports", path=os.path.dirname(sys.executable)) or "lint-imports"


def lint_imports(root):
    """(exit code, output) of import-linter on the packages below root, with root's .importlinter."""
    r = subprocess.run([LINT, "--no-cache", "--config", os.path.join(root, ".importlinter")], cwd=root,
                       capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=root))
    return r.returncode, r.stdout + r.stderr


def test_the_layer_contracts_hold():
    rc, out = lint_imports(ROOT)
    assert rc == 0, out[-4000:]
    assert "6 kept, 0 broken" in out, out[-2000:]


def _copy_packages(dst):
    """The .py files of every package the contracts name, and the contract itself, below dst."""
    for pkg in PACKAGES + ("bench",):
        shutil.copytree(os.path.join(ROOT, pkg), os.path.join(dst, pkg),
                        ignore=lambda d, names: [n for n in names if not (n.endswith(".py") or
                                                                        os.path.isdir(os.path.join(d, n)))
                                                 or n in ("__pycache__", "_build", "csrc")])
    shutil.copy(os.path.join(ROOT, ".importlinter"), dst)


@pytest.mark.parametrize("module, line, broken", [
    # a low layer reaching up: the rasterizer's constants importing the dataset stage
    ("splatting/raster/constants.py", "from splatting.dataset import config", "splatting.raster is not allowed to import splatting.dataset"),
    # a product module importing a benchmark (what looks_sheet did)
    ("splatting/dataset/looks_sheet.py", "from bench import dataset", "splatting is not allowed to import bench"),
    # the add-on importing torch, inside a function
    ("addon/core/frames.py", "def _f():\n    import torch", "addon is not allowed to import torch"),
    # a caller going round the rasterizer's entry (splatting.raster.api) to its dispatch
    ("splatting/cyclist/render.py", "from splatting.raster.sparse import rasterize as _r",
     "splatting.cyclist is not allowed to import splatting.raster.sparse"),
    # the add-on's stages: the renderer reaching up to the rider import, inside a function
    ("addon/core/render/render.py", "def _f():\n    from ..rider import rider_import",
     "addon.core.render is not allowed to import addon.core.rider"),
    # two stages of one layer: the splat import taking the rider's colours
    ("addon/core/splats/splat_import.py", "from ..rider.rider_colours import object_colors",
     "addon.core.splats is not allowed to import addon.core.rider"),
    # a shared basic reaching up to a stage
    ("addon/core/frames.py", "from .rig import articulation", "addon.core.frames is not allowed to import addon.core.rig"),
])
def test_a_wrong_way_import_breaks_the_contract(tmp_path, module, line, broken):
    _copy_packages(str(tmp_path))
    with open(tmp_path / module, "a") as f:
        f.write("\n" + line + "\n")
    rc, out = lint_imports(str(tmp_path))
    assert rc != 0 and broken in out, out[-3000:]


def private_names_taken(root, package="addon.core"):
    """'module: name' for each private name (one leading underscore) a module of `package` takes from
    another project module: `from .x import _f`, or `x._f` on a module `x` it imported."""
    found = []
    top = os.path.join(root, *package.split("."))
    for d, _, files in os.walk(top):
        for f in sorted(files):
            if not f.endswith(".py"):
                continue
            rel = os.path.relpath(os.path.join(d, f), root)[:-3].split(os.sep)
            mod = ".".join(rel[:-1] if rel[-1] == "__init__" else rel)
            here = rel[:-1]  # the package a relative import starts from
            with open(os.path.join(d, f)) as fh:
                tree = ast.parse(fh.read())
            modules = set()  # names bound to project modules
            for n in ast.walk(tree):
                if isinstance(n, ast.ImportFrom):
                    base = here[:len(here) - n.level + 1] if n.level else []
                    src = ".".join(base + (n.module.split(".") if n.module else []))
                    if src.split(".")[0] not in PACKAGES:
                        continue
                    for a in n.names:
                        if a.name.startswith("_") and not a.name.startswith("__"):
                            found.append(f"{mod}: {src}.{a.name}")
                        path = os.path.join(root, *src.split("."), a.name)
                        if os.path.isdir(path) or os.path.isfile(path + ".py"):
                            modules.add(a.asname or a.name)
                elif isinstance(n, ast.Import):
                    modules.update(a.asname for a in n.names if a.asname and a.name.split(".")[0] in PACKAGES)
            for n in ast.walk(tree):
                if (isinstance(n, ast.Attribute) and isinstance(n.value, ast.Name) and n.value.id in modules
                        and n.attr.startswith("_") and not n.attr.startswith("__")):
                    found.append(f"{mod}: {n.value.id}.{n.attr}")
    return sorted(set(found))


def test_no_addon_module_takes_a_private_name_of_another():
    found = private_names_taken(ROOT)
    assert not found, "private names taken across modules:\n" + "\n".join(found)


@pytest.mark.parametrize("module, line, taken", [
    ("addon/core/splats/splat_gaussian.py", "from .splat_import import _keyframe_visibility",
     "addon.core.splats.splat_gaussian: addon.core.splats.splat_import._keyframe_visibility"),
    ("addon/core/curation/saving.py", "from . import rigging\nX = rigging._y",
     "addon.core.curation.saving: rigging._y"),
])
def test_a_private_name_taken_is_found(tmp_path, module, line, taken):
    _copy_packages(str(tmp_path))
    with open(tmp_path / module, "a") as f:
        f.write("\n" + line + "\n")
    assert private_names_taken(str(tmp_path)) == [taken]


def cycles(graph):
    """The import graph's strongly connected components of more than one module (iterative Tarjan)."""
    index, low, on, stack, found, counter = {}, {}, set(), [], [], [0]
    for root in sorted(graph):
        if root in index:
            continue
        work = [(root, iter(sorted(graph[root])))]
        index[root] = low[root] = counter[0]
        counter[0] += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(graph[w]))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        found.append(sorted(comp))
    return found


def import_graph():
    g = grimp.build_graph(*PACKAGES, cache_dir=None)
    graph = {m: set(g.find_modules_directly_imported_by(m)) & g.modules for m in g.modules}
    # addon/core/contract.py's `from ..cyclist_formats import ...` names the copy of the file contract
    # inside the add-on zip (blender_scripts/build_addon.py); grimp, finding no addon.cyclist_formats
    # in the checkout, records it as an import of `addon` itself
    graph["addon.core.contract"].discard("addon")
    return graph


def test_cycle_finder_sees_a_cycle():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_import_graph_has_no_cycle():
    found = cycles(import_graph())
    assert not found, "import circles:\n" + "\n".join(" <-> ".join(c) for c in found)


def test_every_module_imports_alone():
    """Each module imported first, in an interpreter where none of the project's modules is loaded
    yet (third-party ones stay loaded: their import cost is paid once), so no import order hides a
    circle or a missing import."""
    # the add-on needs bpy; __main__ runs a command
    mods = sorted(m for m in import_graph() if not m.startswith("addon") and not m.endswith("__main__"))
    code = ("import importlib, json, sys, traceback\n"
            "mods = json.loads(sys.argv[1]); bad = []\n"
            "for m in mods:\n"
            "    for k in [k for k in sys.modules if k.split('.')[0] in ('splatting', 'cyclist_formats')]:\n"
            "        del sys.modules[k]\n"
            "    try:\n"
            "        importlib.import_module(m)\n"
            "    except Exception:\n"
            "        bad.append(m + ': ' + traceback.format_exc().strip().splitlines()[-1])\n"
            "print('\\n'.join(bad)); sys.exit(1 if bad else 0)\n")
    r = subprocess.run([sys.executable, "-c", code, json.dumps(mods)], capture_output=True, text=True, cwd=ROOT,
                       env=dict(os.environ, PYTHONPATH=ROOT, OMP_NUM_THREADS="1"))
    assert r.returncode == 0, (r.stdout + r.stderr)[-4000:]


def test_the_stand_in_bike_is_the_generators_city_bike(tmp_path):
    """blend_assets/stand_in_bike/ (looks_sheet's bike without --bike; the product does not import
    the add-on's generator) holds what the procedural generator writes for city bike 0."""
    from bench.dataset import _write_spec_bike
    from splatting.dataset.looks_sheet import STAND_IN_BIKE

    assert _write_spec_bike(str(tmp_path)) == STAND_IN_BIKE
    for f in ("keypoints.json", "meta.json"):
        with open(tmp_path / STAND_IN_BIKE / f, "rb") as a, \
                open(os.path.join(ROOT, "blend_assets", "stand_in_bike", STAND_IN_BIKE, f), "rb") as b:
            assert a.read() == b.read(), f
