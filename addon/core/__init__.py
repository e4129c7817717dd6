"""bpy-side core of 3DArticCyclists: used by the add-on operators and the headless scripts.

Laid out by stage (docs/architecture.md): curation/, rider/, splats/, export/, render/, procedural/,
rig/, over the shared basics here (frames, contract, script, scene, bike_asset).

Modules that do not import bpy at module level (frames, contract, the procedural layout) are also importable
from plain Python for tests.
"""
