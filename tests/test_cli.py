"""One command surface (splatting/cli.py): `python -m splatting --help` lists every stage, the torch-side
ones and the Blender scripts; every command's parsing lives in a command module, not in the
implementation; a Blender stage runs its script through the surface (its --help, its one-line
errors and exit codes passed through)."""
import ast
import glob
import os
import shutil
import subprocess
import sys

import pytest

from helpers import ROOT, SCRIPTS
from splatting import cli
from splatting.blender.command import STAGES, split_blender

ENV = dict(os.environ, PYTHONPATH=ROOT)
# modules that keep their own `if __name__ == "__main__"`, and why
OWN_MAIN = {
    "splatting/__main__.py": "the surface itself",
    "splatting/raster/build.py": "the build step of `make raster-lib`, run before any command can import the rasterizer",
    "splatting/dataset/frames/sheet.py": "parses its own arguments; reachable as `dataset frames-sheet`",
    "splatting/dataset/sequences/strip.py": "parses its own arguments; reachable as `dataset strip`",
}


def splatting(*args, **kw):
    return subprocess.run([sys.executable, "-m", "splatting", *args], capture_output=True, text=True, cwd=ROOT,
                          env=ENV, timeout=300, **kw)


def one_error_line(r):
    lines = [ln for ln in r.stderr.splitlines() if ln.strip()]
    assert r.returncode not in (0, None), r
    assert len(lines) == 1 and "error" in lines[0] and "Traceback" not in r.stderr, r.stderr
    return lines[0]


def test_help_lists_every_command_and_every_blender_script():
    r = splatting("--help")
    assert r.returncode == 0, r.stderr
    listed = {ln.strip().split("  ")[0] for ln in r.stdout.splitlines() if ln.startswith("    ") and ln.strip()}
    assert set(cli.COMMANDS) <= listed, set(cli.COMMANDS) - listed
    scripts = sorted(os.path.basename(f) for f in glob.glob(os.path.join(SCRIPTS, "*.py")))
    assert sorted(s.script for s in STAGES.values()) == scripts  # a new script needs its stage
    for script in scripts:
        assert f"blender {script[:-3].replace('_', '-')}" in listed, script
    for stage in ("train", "bike-posed-train", "rider-avatar", "relight-fit", "cyclist", "dataset", "library build",
                  "blender make-bikes", "blender render-views", "blender curate", "blender import-splats"):
        assert stage in listed, stage


def test_blender_alone_lists_its_stages_and_refuses_an_unknown_one():
    r = splatting("blender")
    assert r.returncode == 0 and all(name in r.stdout for name in STAGES), r.stdout
    assert "no Blender stage 'render-everything'" in one_error_line(splatting("blender", "render-everything"))


def _command_modules():
    """Every module of splatting that builds a command line parser (add_arguments or ArgumentParser)."""
    found = {}
    for path in glob.glob(os.path.join(ROOT, "splatting", "**", "*.py"), recursive=True):
        tree = ast.parse(open(path).read())
        rel = os.path.relpath(path, ROOT)
        parses = any(isinstance(n, ast.FunctionDef) and n.name == "add_arguments" for n in ast.walk(tree)) or \
            any(isinstance(n, ast.Attribute) and n.attr == "ArgumentParser" for n in ast.walk(tree))
        own_main = any(isinstance(n, ast.If) and "__main__" in ast.unparse(n.test) for n in tree.body)
        found[rel] = (parses, own_main)
    return found


def test_commands_live_in_command_modules():
    mods = _command_modules()
    parsing = sorted(m for m, (parses, _) in mods.items() if parses)
    allowed = {"splatting/cli.py", "splatting/demo.py", "splatting/rider/import_command.py"} | set(OWN_MAIN)
    stray = [m for m in parsing if not m.endswith("/command.py") and m not in allowed]
    assert not stray, f"command line parsing outside a command module: {stray}"
    mains = sorted(m for m, (_, own) in mods.items() if own)
    assert sorted(set(mains) - set(OWN_MAIN)) == [], "modules with their own __main__"
    # and the check sees one: the scan reads what a module does, not its name
    tree = ast.parse('import argparse\nif __name__ == "__main__":\n    argparse.ArgumentParser()\n')
    assert any(isinstance(n, ast.Attribute) and n.attr == "ArgumentParser" for n in ast.walk(tree))


@pytest.mark.parametrize("name", sorted(n for n in cli.COMMANDS if not n.startswith("blender ")))
def test_every_command_answers_help(name, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(name.split() + ["--help"])
    assert e.value.code in (0, None)
    out = capsys.readouterr().out
    assert "usage:" in out and "--" in out, out


def test_a_blender_stage_help_through_the_surface():
    r = splatting("blender", "render-views", "--help")
    assert r.returncode == 0, r.stderr
    assert "blender_scripts/render_views.py" in r.stdout  # the surface's line, then the script's own flags
    assert "--bike" in r.stdout and "--parts" in r.stdout and "--adaptive-threshold" in r.stdout


@pytest.mark.parametrize("args, says", [
    (["render-views", "--bike", "no_such_bike"], "render_views.py: error: --bike: folder not found"),
    (["render-views", "--", "--bike", "no_such_bike"], "render_views.py: error: --bike: folder not found"),
    (["render-views", "--bike", "x", "--size", "100000"], "render_views.py: error:"),
    (["make-bikes", "--out", "o", "--count", "-1"], "make_bikes: error:"),
    (["render-views"], "the following arguments are required: --bike"),
    (["render-views", "--blender", "/no/such/blender", "--", "--bike", "x"], "--blender /no/such/blender: no such executable"),
    (["render-views", "--blender"], "--blender needs a Blender binary"),
    (["build-addon", "--blender", "blender"], "plain Python step"),
])
def test_a_blender_stage_refuses_bad_input_in_one_line(tmp_path, args, says):
    before = sorted(os.listdir(tmp_path))
    r = subprocess.run([sys.executable, "-m", "splatting", "blender", *args], capture_output=True, text=True,
                       cwd=tmp_path, env=ENV, timeout=300)
    assert says in one_error_line(r)
    assert r.returncode == 2
    assert sorted(os.listdir(tmp_path)) == before


def test_a_blender_stage_runs_through_the_surface(tmp_path):
    """The script does its work with the bpy module of this Python; its output comes back as it is."""
    pytest.importorskip("bpy")
    r = splatting("blender", "make-bikes", "--out", str(tmp_path), "--count", "1", "--no-extras")
    assert r.returncode == 0, r.stderr[-2000:]
    assert "make_bikes: 1 bikes in" in r.stdout
    (bike,) = os.listdir(tmp_path / "bikes")
    assert {"bike.blend", "keypoints.json", "meta.json"} <= set(os.listdir(tmp_path / "bikes" / bike))


def test_split_blender():
    assert split_blender(["--bike", "b"]) == (None, ["--bike", "b"])
    assert split_blender(["--blender", "/b", "--", "--bike", "b"]) == ("/b", ["--bike", "b"])
    assert split_blender(["--blender=/b", "--bike", "b"]) == ("/b", ["--bike", "b"])
    # after the `--` everything is the script's, a --blender too
    assert split_blender(["--", "--blender", "x"]) == (None, ["--blender", "x"])
    with pytest.raises(ValueError):
        split_blender(["--blender"])


def test_command_lines_of_both_ways():
    stage = STAGES["render-views"]
    script = os.path.join(ROOT, "blender_scripts", "render_views.py")
    assert stage.command_line(["--bike", "b"]) == [sys.executable, script, "--bike", "b"]
    assert stage.command_line(["--bike", "b"], "/usr/bin/blender") == \
        ["/usr/bin/blender", "-b", "--factory-startup", "-P", script, "--", "--bike", "b"]


@pytest.mark.blender_binary
@pytest.mark.skipif(shutil.which("blender") is None, reason="no Debian blender binary")
def test_a_blender_stage_in_the_blender_binary(tmp_path):
    """--blender PATH: the script runs inside the binary (`blender -b -P script -- ARGS`) and its
    refusal and exit code come back as they are."""
    r = subprocess.run([sys.executable, "-m", "splatting", "blender", "render-views", "--blender", "blender", "--",
                        "--bike", "no_such_bike"], capture_output=True, text=True, cwd=tmp_path, env=ENV, timeout=300)
    assert "render_views.py: error: --bike: folder not found" in one_error_line(r)
    assert r.returncode == 2
