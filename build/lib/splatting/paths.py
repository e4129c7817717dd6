"""Where the project's non-Python resources live: one place instead of path arithmetic per module.

The checkout holds them beside the packages (blend_assets/ recipes, blender_scripts/ for the
Blender stages, data/ for caches and built assets).  An installed copy of the package finds the
checkout through ARTICCYCLISTS_ROOT; the data folder can be moved with ARTICCYCLISTS_DATA.
"""
import os
from pathlib import Path

ROOT = Path(os.environ.get("ARTICCYCLISTS_ROOT") or Path(__file__).resolve().parents[1])
BLEND_ASSETS = ROOT / "blend_assets"
BLENDER_SCRIPTS = ROOT / "blender_scripts"
DATA = Path(os.environ.get("ARTICCYCLISTS_DATA") or ROOT / "data")


def blender_script(name):
    """Path (str) of a headless Blender stage script, e.g. blender_script("render_views.py")."""
    return str(BLENDER_SCRIPTS / name)
