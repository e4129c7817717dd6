"""The extension as users install it: Blender's strict manifest check, and a Blender without numpy.

The validator is the one `blender --command extension validate` runs (bl_pkg/cli/blender_ext.py
bundled with the bpy module, with Blender's tags list); the limits the tests rely on (64
characters for the tagline and each permission reason) are Blender's, written out here.
"""
import os
import shutil
import subprocess
import sys
import zipfile

import pytest

from addon.core.script import UserError
from blender_scripts import build_addon
from ci_needs import missing

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
BLENDER = "/usr/bin/blender"

# Raises ModuleNotFoundError for numpy before any other finder runs: what a Python without the
# package does (the add-on's own check and any stray `import numpy` both see it).
BLOCK_NUMPY = r'''
import sys
class _NoNumpy:
    def find_spec(self, name, path=None, target=None):
        if name == "numpy" or name.startswith("numpy."):
            raise ModuleNotFoundError("No module named 'numpy'", name="numpy")
        return None
if BLOCK:
    sys.meta_path.insert(0, _NoNumpy())
    for _m in [m for m in sys.modules if m == "numpy" or m.startswith("numpy.")]:
        del sys.modules[_m]
'''

# After the add-on is enabled: what the panel draws (through a layout that records labels),
# whether the message panel polls, and what two operators (one in the Curate panel, one in
# Render) answer.
PROBE = r'''
import json
import bpy

class _Rec:
    def __init__(self, out):
        self.out, self.alert = out, False
    def box(self):
        return self
    def column(self, **kw):
        return self
    def label(self, text="", icon="NONE"):
        self.out.append(text)

out = {"poll": bpy.types.ARTICCYC_PT_requirements.poll(bpy.context) if hasattr(bpy.types, "ARTICCYC_PT_requirements") else None}
labels = []
if out["poll"]:
    class _Self:
        layout = _Rec(labels)
    bpy.types.ARTICCYC_PT_requirements.draw(_Self(), bpy.context)
out["labels"] = labels
out["ops"] = {}
for name, op in (("auto_curate", bpy.ops.articcyc.auto_curate), ("build_rig", bpy.ops.articcyc.build_rig)):
    try:
        out["ops"][name] = ["FINISHED?", sorted(op())]
    except Exception as e:
        out["ops"][name] = [type(e).__name__, str(e)]
with open(RESULT, "w") as f:
    json.dump(out, f)
'''


def _validator_or_skip():
    try:
        return build_addon.blender_ext_tool()
    except UserError as e:
        pytest.skip(str(e))


def test_built_zip_and_folder_pass_blenders_strict_validation(tmp_path):
    _validator_or_skip()
    z = build_addon.build(str(tmp_path), check=True)
    assert os.listdir(tmp_path) == [os.path.basename(z)]
    ok, lines = build_addon.validate(z)
    assert ok and any(ln.startswith("Success") for ln in lines), lines
    ok, lines = build_addon.validate(os.path.join(ROOT, "addon"))
    assert ok, lines
    with zipfile.ZipFile(z) as f:  # one package folder: an extension for 4.2+, a legacy add-on for 3.x
        names = f.namelist()
    assert "articcyclists/blender_manifest.toml" in names and "articcyclists/__init__.py" in names
    assert not [n for n in names if "__pycache__" in n or n.endswith(".pyc")]


def test_validator_rejects_the_old_manifest_and_nothing_is_written(tmp_path):
    """The manifest as it was (67-character tagline, 91-character files reason) must fail."""
    _validator_or_skip()
    src = tmp_path / "addon"
    shutil.copytree(os.path.join(ROOT, "addon"), src, ignore=shutil.ignore_patterns("__pycache__"))
    m = src / "blender_manifest.toml"
    text = m.read_text()
    old_tagline = "Curate, articulate and render bicycle models for synthetic cyclists"
    old_files = "Import bicycle models and write bike folders (bike.blend, keypoints.json, meta.json, views)"
    assert (len(old_tagline), len(old_files)) == (67, 91)
    import re
    text = re.sub(r'^tagline = ".*"$', f'tagline = "{old_tagline}"', text, flags=re.M)
    text = re.sub(r'^files = ".*"$', f'files = "{old_files}"', text, flags=re.M)
    m.write_text(text)
    ok, lines = build_addon.validate(str(src))
    assert not ok
    joined = " ".join(lines)
    assert "tagline" in joined and "found 67" in joined and "found 91" in joined, lines
    out = tmp_path / "dist"
    with pytest.raises(UserError, match="tagline"):
        build_addon.build(str(out), addon_dir=str(src), check=True)
    assert list(out.iterdir()) == []  # no zip, no temporary


def test_build_cli_validates(tmp_path):
    _validator_or_skip()
    r = subprocess.run([sys.executable, os.path.join(ROOT, "blender_scripts", "build_addon.py"), "--out",
                        str(tmp_path)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr
    assert "passes Blender's extension validate" in r.stdout
    assert [p.name for p in tmp_path.iterdir()] == ["articcyclists-0.1.0.zip"]


def _numpy_probe_bpy(tmp_path, block):
    """Install the zip as an extension in a fresh bpy 5.0 process (numpy blocked or not), probe it."""
    pytest.importorskip("bpy")
    z = build_addon.build(str(tmp_path / "dist"))
    result = tmp_path / f"result_{block}.json"
    script = tmp_path / f"probe_{block}.py"
    script.write_text(f"BLOCK = {block!r}\nRESULT = {str(result)!r}\n" + BLOCK_NUMPY
                      + "import bpy\n"
                      + f"bpy.ops.extensions.package_install_files(filepath={z!r}, repo='user_default', "
                      + "enable_on_install=True)\n" + PROBE)
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / f"res_{block}"))  # not the real user's
    r = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0 and result.exists(), r.stdout[-2000:] + r.stderr[-2000:]
    import json
    return json.loads(result.read_text()), r.stdout + r.stderr


def _check_refusals(res):
    assert res["poll"] is True
    text = "\n".join(res["labels"])
    assert "numpy" in text and "apt install python3-numpy" in text and "pip install numpy" in text, text
    for name, (kind, msg) in res["ops"].items():
        assert kind == "RuntimeError", (name, kind, msg)  # bpy.ops' wrapper of a CANCELLED + ERROR report
        assert "ModuleNotFoundError" not in msg
        assert "needs the Python package numpy" in msg and "sudo apt install python3-numpy" in msg, msg


def test_without_numpy_the_extension_says_what_to_install(tmp_path):
    res, log = _numpy_probe_bpy(tmp_path, True)
    _check_refusals(res)
    import re
    # bpy itself prints numpy's ImportError at start-up; no traceback may come from the add-on
    assert not re.search(r'File "[^"]*articcyclists[^"]*"', log), log[-3000:]


def test_with_numpy_no_message_and_operators_run(tmp_path):
    res, _ = _numpy_probe_bpy(tmp_path, False)
    assert res["poll"] is False and res["labels"] == []
    for name, (kind, msg) in res["ops"].items():  # they get to their own checks (empty scene)
        assert "numpy" not in msg, (name, msg)


@pytest.mark.blender_binary
def test_debian_blender_without_numpy_legacy_addon(tmp_path):
    """Debian's Blender 3.4 with the add-on installed the legacy way, numpy hidden."""
    if not os.path.exists(BLENDER):
        missing("/usr/bin/blender")
    z = build_addon.build(str(tmp_path / "dist"))
    with zipfile.ZipFile(z) as f:  # what "Install add-on" does with a legacy zip
        f.extractall(tmp_path / "scripts" / "addons")
    result = tmp_path / "result.json"
    expr = (f"BLOCK = True\nRESULT = {str(result)!r}\n" + BLOCK_NUMPY
            + "import addon_utils\naddon_utils.enable('articcyclists', default_set=True)\n" + PROBE)
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"))
    r = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr", expr], capture_output=True,
                       text=True, env=env, timeout=300)
    assert result.exists(), r.stdout[-3000:] + r.stderr[-3000:]
    import json
    _check_refusals(json.loads(result.read_text()))


def test_the_vendored_formats_import_themselves_relatively_and_need_no_yaml():
    """cyclist_formats is copied into the add-on zip as articcyclists.cyclist_formats, where an
    absolute `cyclist_formats` import does not resolve and Blender's own Python has no PyYAML: a
    module the add-on loads must import its siblings relatively and yaml only where YAML is read."""
    import ast
    folder = os.path.join(ROOT, "cyclist_formats")
    absolute, yaml_at_top = [], []
    for name in sorted(os.listdir(folder)):
        if not name.endswith(".py"):
            continue
        tree = ast.parse(open(os.path.join(folder, name), encoding="utf-8").read())
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").split(".")[0] == "cyclist_formats":
                absolute.append(f"{name}:{node.lineno}")
            if isinstance(node, ast.Import) and any(a.name.split(".")[0] == "cyclist_formats" for a in node.names):
                absolute.append(f"{name}:{node.lineno}")
        for node in tree.body:  # module level only: a function may import yaml when it reads YAML
            if isinstance(node, ast.Import) and any(a.name == "yaml" for a in node.names):
                yaml_at_top.append(name)
    assert absolute == [], f"absolute imports of cyclist_formats inside it: {absolute}"
    assert yaml_at_top == [], f"yaml imported at module level: {yaml_at_top}"
