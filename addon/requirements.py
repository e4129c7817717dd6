"""Whether the add-on's Python has what it needs (numpy), checked once by register(); the panel shows
the message and every operator refuses with it.  Its own module so that the panel and the operators
read it without importing the add-on's package back (one direction of imports)."""
import sys

_MISSING = []  # register() stores the missing-numpy message here, or nothing


def missing_numpy_message():
    """None when numpy imports; else one line naming the package and how to install it."""
    try:
        import numpy  # noqa: F401
    except ImportError as e:  # absent, or built for another Python (a broken system copy)
        why = "is not installed" if getattr(e, "name", None) == "numpy" else f"fails to import ({e})"
        return (f"3DArticCyclists needs the Python package numpy, which {why} in this Blender's Python: "
                f"install it (Debian/Ubuntu: sudo apt install python3-numpy; other Blenders: "
                f"{sys.executable} -m pip install numpy) and restart Blender")
    return None


def requirements_problem():
    """The message the panel shows and the operators refuse with, or None (checked at register)."""
    return _MISSING[0] if _MISSING else None
