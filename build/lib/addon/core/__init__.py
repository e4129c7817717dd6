"""bpy-side core of 3DArticCyclists: used by the add-on operators and the headless scripts.

Modules that do not import bpy at module level (frames, contract, the procedural layout) are also importable
from plain Python for tests.
"""
