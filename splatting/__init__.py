"""3DArticCyclists torch side: Gaussian splatting on CPU, parametric bike, rider, datasets.

Never imports bpy.  Meets the Blender side only through files (DESIGN.md formats).
"""
