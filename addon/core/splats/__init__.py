"""Trained Gaussians back into Blender: the import (splat_import) and its three modes (Gaussian
proxies, camera-facing quads, preview spheres), over one module of node helpers (splat_nodes)."""
