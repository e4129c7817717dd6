"""The project installs: pyproject.toml declares the packages and the console command, and the
command works the way an installed one is called (not through `python -m`)."""
import os
import subprocess
import sys
import tomllib

from helpers import ROOT


def test_pyproject_declares_packages_and_command():
    with open(os.path.join(ROOT, "pyproject.toml"), "rb") as f:
        meta = tomllib.load(f)
    assert meta["project"]["scripts"]["articcyclists"] == "splatting.cli:main"
    assert {"splatting*", "cyclist_formats*"} <= set(meta["tool"]["setuptools"]["packages"]["find"]["include"])
    pins = [d for d in meta["project"]["dependencies"] if d.startswith("torch")]
    assert pins == ["torch==2.13.0"]  # an unpinned torch pulls the CUDA build


def test_console_entry_point_help_without_dash_m():
    # -S: no site hooks (the editable install's finder would import importlib.util for us)
    code = "import sys; from splatting.cli import main; sys.argv = ['articcyclists', '--help']; main()"
    r = subprocess.run([sys.executable, "-S", "-c", code], capture_output=True, text=True, cwd="/",
                       env=dict(os.environ, PYTHONPATH=ROOT))
    assert r.returncode == 0 and "pose-bike" in r.stdout and "dataset" in r.stdout, r.stderr[-1500:]


def test_installed_command_runs():
    exe = os.path.join(os.path.dirname(sys.executable), "articcyclists")
    assert os.path.isfile(exe), "make setup installs the project (pip install -e .)"
    r = subprocess.run([exe, "train", "--help"], capture_output=True, text=True, cwd="/")
    assert r.returncode == 0 and "--max-gaussians" in r.stdout, r.stderr[-1500:]
