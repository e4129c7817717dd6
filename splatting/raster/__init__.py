"""Rendering Gaussians on the CPU: the functional entry `rasterization()` (api.py), the sparse
torch implementation with its hand-written backward (sparse.py), the plain reference renderer the
tests compare every stage against (reference.py) and the camera (camera.py)."""
