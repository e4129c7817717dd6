import os
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)


@pytest.fixture
def fresh_scene():
    """An empty Blender scene per test (bpy module), as MolecularNodes does."""
    bpy = pytest.importorskip("bpy")
    from addon.core.scene import reset_scene

    reset_scene()
    yield bpy.context.scene
    reset_scene()


@pytest.fixture(autouse=True)
def _torch_threads():
    """Two shared cores: keep torch from oversubscribing during tests."""
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    yield
