"""Real spherical harmonics, degrees 0-3, in the INRIA 3DGS basis and coefficient order.

colour = max(0, sum_k sh[k] * Y_k(d) + 0.5) with d the unit direction camera -> Gaussian.
"""
import torch

from cyclist_formats.sh_basis import C0, C1, C2, C3, sh_terms  # noqa: F401 (C1-C3 re-exported)


def sh_basis(dirs, degree):
    """dirs (..., 3) unit vectors -> basis values (..., (degree+1)**2)."""
    x, y, z = dirs.unbind(-1)
    return torch.stack(sh_terms(x, y, z, torch.full_like(x, C0), degree), -1)


def eval_sh(sh, dirs, degree=None):
    """sh (N, K, 3), dirs (N, 3) unit -> RGB (N, 3), +0.5 offset and clamped at 0 (INRIA)."""
    if degree is None:
        degree = int(round(sh.shape[1] ** 0.5)) - 1
    basis = sh_basis(dirs, degree)  # (N, K')
    rgb = (basis.unsqueeze(-1) * sh[:, : basis.shape[-1]]).sum(1)
    return torch.clamp_min(rgb + 0.5, 0.0)


def rgb_to_sh0(rgb):
    return (rgb - 0.5) / C0
