"""Relightable Gaussians: albedo + normal per Gaussian, shaded per pixel (docs/relighting.md)."""
