"""Build the add-on zip: dist/articcyclists-<version>.zip (plain Python, no bpy).

    .venv/bin/python blender_scripts/build_addon.py [--out dist]

The zip holds one folder `articcyclists/` with the package (addon/ minus caches): Blender 4.2+
installs it as an extension (blender_manifest.toml; the manual allows the files inside one
folder of the archive) and Blender 3.x as a legacy add-on (bl_info; a legacy zip must hold the
package folder).  The version comes from blender_manifest.toml and must match bl_info.
"""
import argparse
import ast
import os
import re
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


def build(out_dir, addon_dir=os.path.join(ROOT, "addon")):
    manifest_v, bl_v = versions(addon_dir)
    if manifest_v != bl_v:
        raise UserError(f"version mismatch: blender_manifest.toml {manifest_v} vs bl_info {bl_v}")
    os.makedirs(out_dir, exist_ok=True)
    path = os.path.join(out_dir, f"{PKG}-{manifest_v}.zip")
    tmp = path + ".tmp"
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as z:
        for d, dirs, files in os.walk(addon_dir):
            dirs[:] = sorted(x for x in dirs if x not in SKIP_DIRS)
            for f in sorted(files):
                if f.endswith(SKIP_EXT):
                    continue
                full = os.path.join(d, f)
                z.write(full, os.path.join(PKG, os.path.relpath(full, addon_dir)))
    os.replace(tmp, path)
    return path


def main(argv):
    p = argparse.ArgumentParser(prog="build_addon.py", description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=os.path.join(ROOT, "dist"), help="output folder (default dist/)")
    args = p.parse_args(argv)
    from cyclist_formats import checks
    checks.output_dir("out", args.out)
    print(build(args.out))
    return 0


if __name__ == "__main__":
    run_main(main, "build_addon.py")
