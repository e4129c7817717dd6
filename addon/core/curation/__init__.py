"""Curation of imported bicycle models: clean up, find the canonical pose and scale, estimate
and validate keypoints, split into the three rigid parts.

The geometry (mesh.py, wheels.py, pose.py, keypoints.py, split.py, pipeline.py) is numpy only, so
it is unit-tested without Blender.  The bpy side, by job: importers.py (read a model file),
join_source.py (one mesh, curation_source), curate_scene.py (auto curate), face_cuts.py (cut fused
pieces), keypoint_empties.py, part_objects.py (split and paint), rigging.py, saving.py, over the
scene's names and face attributes in scene_state.py.
"""
