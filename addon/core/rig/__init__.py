"""The bike's rig in Blender: the armature of part and keypoint bones (armature) and the 8-DoF
pose applied to it (articulation)."""
