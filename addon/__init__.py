"""3DArticCyclists Blender side.

`addon.core` holds the bpy-side core (procedural bikes, articulation, rendering) that the
headless scripts in blender_scripts/ call.  The annotator panel and the extension packaging
(issue "Curate and articulate imported bicycle models") will register operators from here.
"""
