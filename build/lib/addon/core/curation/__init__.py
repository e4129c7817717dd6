"""Curation of imported bicycle models: clean up, find the canonical pose and scale, estimate
and validate keypoints, split into the three rigid parts.

The geometry (mesh.py, wheels.py, pose.py, keypoints.py, split.py, pipeline.py) is numpy only, so
it is unit-tested without Blender; importers.py and scene_io.py are the bpy side.
"""
