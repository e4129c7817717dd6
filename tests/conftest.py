"""Fixtures for every test.  The packages are imported as installed (`make setup` installs the
project editable); shared factories live in tests/helpers.py."""
import sys

import pytest


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


@pytest.fixture(scope="module")
def bikes(tmp_path_factory):
    """A bikes root holding the stand-in test bike (helpers.write_test_bike), one per test module
    (a module may define its own `bikes`)."""
    from helpers import write_test_bike

    root = tmp_path_factory.mktemp("bikes")
    write_test_bike(str(root))
    return str(root)
