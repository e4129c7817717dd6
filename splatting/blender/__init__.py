"""The Blender stages (blender_scripts/) as `python -m splatting blender STAGE` commands (command.py)."""
