"""Articulated export of a bike folder for simulators and engines (blender_scripts/export_bike.py).

numpy-only modules (importable without Blender): `articulation` (joints from keypoints.json),
`mass` (volume, centre of mass and inertia of triangle meshes), `urdf` (URDF + OBJ meshes),
`gltf` (binary glTF 2.0 with pivot nodes and a clip).  `parts` is the bpy side: it reads the
part meshes out of bike.blend.
"""
