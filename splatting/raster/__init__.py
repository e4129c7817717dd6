"""Rasterizer back ends. `cpu_tiles`: the fused, tiled, OpenMP C++ compositor (csrc/tiles.cpp),
built once by `make setup` (`python -m splatting.raster.build`) or on first use."""
