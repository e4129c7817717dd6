"""Gaussians: the container (container.py), its .ply (via cyclist_formats.ply), spherical
harmonics (sh.py) and their exact rotation (sh_rotation.py), rotation helpers (rotations.py)."""
