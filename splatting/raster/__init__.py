"""Rendering Gaussians on the CPU. The one entry is `splatting.raster.api.rasterization()` (one
camera or several; several in one pass of the C++ back end); behind it the one-camera dispatch
between the back ends (sparse.py), the EWA projection (projection.py), the pure-torch compositor
with its hand-written backward (torch_composite.py), the fused, tiled, OpenMP C++ back end
(cpu_project.py / cpu_tiles.py + csrc/, built once by `make setup` via
`python -m splatting.raster.build` or on first use), the plain reference renderer the tests
compare both against (reference.py) and the camera (camera.py)."""
