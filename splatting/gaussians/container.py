"""The Gaussian set; its INRIA 3DGS .ply layout is cyclist_formats.ply's (docs/contract.md).

Tensor shapes (N Gaussians, K = (sh_degree + 1)**2 SH coefficients per colour channel):
  means        (N, 3)  canonical frame, metres
  quats        (N, 4)  wxyz, not necessarily normalised (normalise before use)
  log_scales   (N, 3)  natural log of the per-axis standard deviations
  opacity_logits (N,)  logit of opacity
  sh           (N, K, 3)  sh[:, 0] is the DC term (f_dc), sh[:, 1:] the rest (f_rest)
"""
import os
from dataclasses import dataclass, fields, replace

import numpy as np
import torch

from cyclist_formats import ply
from cyclist_formats.errors import UserError

PLY_SH_REST = 45  # always written zero-padded to degree 3


def sh_coeffs(degree):
    return (degree + 1) ** 2


@dataclass
class Gaussians:
    means: torch.Tensor
    quats: torch.Tensor
    log_scales: torch.Tensor
    opacity_logits: torch.Tensor
    sh: torch.Tensor

    def __post_init__(self):
        n = self.means.shape[0]
        shapes = {"means": (n, 3), "quats": (n, 4), "log_scales": (n, 3), "opacity_logits": (n,)}
        for name, shape in shapes.items():
            if tuple(getattr(self, name).shape) != shape:
                raise ValueError(f"Gaussians.{name} has shape {tuple(getattr(self, name).shape)}, expected {shape}")
        k = self.sh.shape[1] if self.sh.dim() == 3 else -1
        if self.sh.dim() != 3 or self.sh.shape[0] != n or self.sh.shape[2] != 3 or k not in (1, 4, 9, 16):
            raise ValueError(f"Gaussians.sh has shape {tuple(self.sh.shape)}, expected ({n}, 1|4|9|16, 3)")

    def __len__(self):
        return self.means.shape[0]

    @property
    def sh_degree(self):
        return int(round(self.sh.shape[1] ** 0.5)) - 1

    @property
    def opacities(self):
        return torch.sigmoid(self.opacity_logits)

    @property
    def scales(self):
        return torch.exp(self.log_scales)

    def map(self, fn):
        """Apply fn to every tensor field (e.g. .to(device), indexing, detach)."""
        return Gaussians(**{f.name: fn(getattr(self, f.name)) for f in fields(self)})

    def to(self, *args, **kwargs):
        return self.map(lambda t: t.to(*args, **kwargs))

    def __getitem__(self, idx):
        return self.map(lambda t: t[idx])

    def with_sh_degree(self, degree):
        """Truncate or zero-pad SH to `degree`."""
        k = sh_coeffs(degree)
        if k <= self.sh.shape[1]:
            return replace(self, sh=self.sh[:, :k])
        pad = self.sh.new_zeros(len(self), k - self.sh.shape[1], 3)
        return replace(self, sh=torch.cat([self.sh, pad], 1))

    @staticmethod
    def cat(parts):
        """Concatenate Gaussian sets (SH padded to the highest degree among them)."""
        deg = max(p.sh_degree for p in parts)
        parts = [p.with_sh_degree(deg) for p in parts]
        return Gaussians(**{f.name: torch.cat([getattr(p, f.name) for p in parts], 0) for f in fields(Gaussians)})


def _ply_dtype():
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
    names += [f"f_rest_{i}" for i in range(PLY_SH_REST)]
    names += ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    return [(n, "<f4") for n in names]


def write_ply(g: Gaussians, path):
    """Binary little-endian float32 INRIA layout, f_rest channel-major, zero-padded to degree 3."""
    n = len(g)
    sh = g.with_sh_degree(3).sh.detach().cpu().float().numpy()  # (N, 16, 3)
    arr = np.zeros(n, dtype=_ply_dtype())
    m = g.means.detach().cpu().float().numpy()
    arr["x"], arr["y"], arr["z"] = m[:, 0], m[:, 1], m[:, 2]
    for c in range(3):
        arr[f"f_dc_{c}"] = sh[:, 0, c]
        for j in range(15):  # channel-major: all of R's rest coefficients, then G's, then B's
            arr[f"f_rest_{c * 15 + j}"] = sh[:, 1 + j, c]
    arr["opacity"] = g.opacity_logits.detach().cpu().float().numpy()
    s = g.log_scales.detach().cpu().float().numpy()
    q = g.quats.detach().cpu().float().numpy()
    for i in range(3):
        arr[f"scale_{i}"] = s[:, i]
    for i in range(4):
        arr[f"rot_{i}"] = q[:, i]
    ply.write_ply(path, arr)


def read_ply(path, sh_degree=None) -> Gaussians:
    """Read an INRIA-layout .ply. sh_degree=None infers the highest band with non-zero values."""
    v = ply.read_gaussians(os.fspath(path))  # UserError for missing, corrupt, non-3DGS or non-finite
    names = v.dtype.names
    n_rest = sum(1 for k in names if k.startswith("f_rest_"))
    if n_rest % 3 or (n_rest // 3 + 1) not in (1, 4, 9, 16):
        raise UserError(f"{path}: {n_rest} f_rest fields is not a whole SH degree")
    per = n_rest // 3
    col = lambda k: torch.from_numpy(np.ascontiguousarray(v[k], dtype=np.float32))
    sh = torch.zeros(len(v), 1 + per, 3)
    for c in range(3):
        sh[:, 0, c] = col(f"f_dc_{c}")
        for j in range(per):
            sh[:, 1 + j, c] = col(f"f_rest_{c * per + j}")
    g = Gaussians(
        means=torch.stack([col("x"), col("y"), col("z")], 1),
        quats=torch.stack([col(f"rot_{i}") for i in range(4)], 1),
        log_scales=torch.stack([col(f"scale_{i}") for i in range(3)], 1),
        opacity_logits=col("opacity"),
        sh=sh,
    )
    for f in fields(g):
        if not torch.isfinite(getattr(g, f.name)).all():
            raise UserError(f"{path}: non-finite values in {f.name}")
    if sh_degree is None:
        sh_degree = 0
        for d in (1, 2, 3):
            if sh.shape[1] >= sh_coeffs(d) and bool((sh[:, sh_coeffs(d - 1):sh_coeffs(d)] != 0).any()):  # (none: empty)
                sh_degree = d
    return g.with_sh_degree(sh_degree)
