"""Build the add-on zip: dist/articcyclists-<version>.zip, checked by Blender's own validator.

    .venv/bin/python blender_scripts/build_addon.py [--out dist] [--no-validate]

The zip holds one folder `articcyclists/` with the package (addon/ minus caches): Blender 4.2+
installs it as an extension (blender_manifest.toml; the manual allows the files inside one
folder of the archive) and Blender 3.x as a legacy add-on (bl_info; a legacy zip must hold the
package folder).  The version comes from blender_manifest.toml and must match bl_info.
"""
import argparse
import ast
import glob
import importlib.util
import os
import re
import subprocess
import sys
import zipfile

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from addon.core.script import UserError, run_main  # noqa: E402

PKG = "articcyclists"
SKIP_DIRS = {"__pycache__", ".pytest_cache"}
SKIP_EXT = (".pyc", ".pyo", ".blend1")


def versions(addon_dir):
    with open(os.path.join(addon_dir, "blender_manifest.toml")) as f:
        m = re.search(r'^version\s*=\s*"([^"]+)"', f.read(), re.M)
    if not m:
        raise UserError("blender_manifest.toml has no version")
    with open(os.path.join(addon_dir, "__init__.py")) as f:
        tree = ast.parse(f.read())
    bl = next((ast.literal_eval(n.value) for n in tree.body if isinstance(n, ast.Assign)
               and any(getattr(t, "id", "") == "bl_info" for t in n.targets)), None)
    if bl is None:
        raise UserError("addon/__init__.py has no bl_info")
    return m.group(1), ".".join(str(v) for v in bl["version"])


def blender_ext_tool():
    """(blender_ext.py, tags.py) bundled with the installed bpy module, found without importing bpy."""
    spec = importlib.util.find_spec("bpy")
    if spec is None or not spec.submodule_search_locations:
        raise UserError("cannot validate: the bpy module is not installed (make setup), or pass --no-validate")
    root = list(spec.submodule_search_locations)[0]
    tools = sorted(glob.glob(os.path.join(root, "*", "scripts", "addons_core", "bl_pkg", "cli", "blender_ext.py")))
    tags = sorted(glob.glob(os.path.join(root, "*", "scripts", "modules", "_bpy_internal", "extensions", "tags.py")))
    if not tools or not tags:
        raise UserError(f"cannot validate: no bl_pkg/cli/blender_ext.py or extensions/tags.py under {root}")
    return tools[-1], tags[-1]


def validate(path):
    """Blender's strict extension check on a zip or a package folder -> (ok, [message lines])."""
    tool, tags = blender_ext_tool()
    r = subprocess.run([sys.executable, tool, "validate", path, "--valid-tags", tags],
                       capture_output=True, text=True, timeout=120)
    lines = [ln.removeprefix("FATAL_ERROR: ").strip() for ln in (r.stdout + r.stderr).splitlines() if ln.strip()]
    return r.returncode == 0, lines


def build(out_dir, addon_dir=os.path.join(ROOT, "addon"), check=False):
    """Write the zip (atomically); with check=True only if Blender's validator accepts it."""
    manifest_v, bl_v = versions(addon_dir)
    if manifest_v != bl_v:
        raise UserError(f"version mismatch: blender_manifest.toml {manifest_v} vs bl_info {bl_v}")
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{PKG}-{manifest_v}.zip")
    tmp = path + ".tmp"
    # the add-on plus its own copy of the file contract (addon/core/contract.py imports it
    # relatively there): an installed extension sees only its folder
    trees = [(addon_dir, PKG), (os.path.join(ROOT, "cyclist_formats"), os.path.join(PKG, "cyclist_formats"))]
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for src, dst in trees:
            for d, dirs, files in os.walk(src):
                dirs[:] = sorted(x for x in dirs if x not in SKIP_DIRS)
                for f in sorted(files):
                    if f.endswith(SKIP_EXT):
                        continue
                    full = os.path.join(d, f)
                    z.write(full, os.path.join(dst, os.path.relpath(full, src)))
    if check:
        ok, lines = validate(tmp)
        if not ok:
            os.remove(tmp)
            raise UserError("Blender's extension validator rejects the add-on: "
                            + "; ".join(ln for ln in lines if not ln.startswith("Error parsing TOML")))
    os.replace(tmp, path)
    return path


def main(argv):
    p = argparse.ArgumentParser(prog="build_addon.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.path.join(ROOT, "dist"), help="output folder (default dist/)")
    p.add_argument("--no-validate", action="store_true",
                   help="skip Blender's strict manifest check (needs the bpy module's bundled tooling)")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.output_dir("out", args.out)
    path = build(args.out, check=not args.no_validate)
    print(path if args.no_validate else f"{path} (passes Blender's extension validate)")
    return 0


if __name__ == "__main__":
    run_main(main, "build_addon.py")
