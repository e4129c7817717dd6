"""Rendering Gaussians on the CPU: the functional entry `rasterization()` (api.py); the projection
and the pure-torch sparse compositor with its hand-written backward (sparse.py); the fused, tiled,
OpenMP C++ compositor (cpu_tiles.py + csrc/tiles.cpp, built once by `make setup` via
`python -m splatting.raster.build` or on first use); the plain reference renderer the tests
compare both against (reference.py); the camera (camera.py)."""
