"""Deliberately simple 3DGS renderer for tests: loops over Gaussians, dense over pixels.

Written from the formulas (not from splatting/raster/sparse.py) so the two can check each other.
Tiny images only: cost is O(H * W * N) with a Python loop over N.
"""
import math

import torch

from splatting.gaussians.sh import eval_sh
from splatting.raster.sparse import EPS2D


def _rotmat(q):
    q = q / q.norm()
    w, x, y, z = q.tolist()
    return torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]],
                        dtype=torch.float64)


@torch.no_grad()
def project_reference(means, quats, scales, camera, near=0.01, eps2d=EPS2D):
    """Stage 1, per Gaussian, float64: means2d (N, 2), conics (N, 3) = (a, b, c) of the inverse 2D
    covariance, z (N,), radii (N,) long (0 = culled: behind `near` or degenerate), and the
    antialiasing factor det(S) / det(S + eps2d I) (N,).  eps2d: a number or one per Gaussian (N,)."""
    f64 = lambda t: t.detach().to("cpu", torch.float64)
    means, quats, scales = map(f64, (means, quats, scales))
    R, T, K = f64(camera.R), f64(camera.T), f64(camera.K)
    W, H = camera.width, camera.height
    fx, fy, cx, cy = K[0, 0].item(), K[1, 1].item(), K[0, 2].item(), K[1, 2].item()
    n = means.shape[0]
    m2, conics = torch.zeros(n, 2, dtype=torch.float64), torch.zeros(n, 3, dtype=torch.float64)
    zs, radii, aa = torch.zeros(n, dtype=torch.float64), torch.zeros(n, dtype=torch.long), torch.zeros(n, dtype=torch.float64)
    for i in range(n):
        xc = R @ means[i] + T
        z = xc[2].item()
        zs[i] = z
        if z <= near:
            continue
        mx, my = fx * xc[0].item() / z + cx, fy * xc[1].item() / z + cy
        # Jacobian of (fx x/z + cx, fy y/z + cy), x/z and y/z clamped to 1.3 times the half-FOV
        lx_hi, lx_lo = (W - cx) / fx + 0.15 * W / fx, cx / fx + 0.15 * W / fx
        ly_hi, ly_lo = (H - cy) / fy + 0.15 * H / fy, cy / fy + 0.15 * H / fy
        tx = min(max(xc[0].item() / z, -lx_lo), lx_hi) * z
        ty = min(max(xc[1].item() / z, -ly_lo), ly_hi) * z
        J = torch.tensor([[fx / z, 0.0, -fx * tx / z ** 2], [0.0, fy / z, -fy * ty / z ** 2]], dtype=torch.float64)
        Rq = _rotmat(quats[i])
        cov3 = Rq @ torch.diag(scales[i] ** 2) @ Rq.T
        cov2_raw = J @ R @ cov3 @ R.T @ J.T
        e = float(eps2d[i]) if torch.is_tensor(eps2d) else eps2d
        cov2 = cov2_raw + e * torch.eye(2, dtype=torch.float64)
        det = torch.linalg.det(cov2).item()
        if det <= 0:
            continue
        inv = torch.linalg.inv(cov2)
        tr = 0.5 * (cov2[0, 0] + cov2[1, 1]).item()
        lam_max = tr + math.sqrt(max(0.1, tr ** 2 - det))
        m2[i] = torch.tensor([mx, my], dtype=torch.float64)
        conics[i] = torch.stack([inv[0, 0], inv[0, 1], inv[1, 1]])
        radii[i] = math.ceil(3.0 * math.sqrt(lam_max))
        aa[i] = max(0.0, torch.linalg.det(cov2_raw).item() / det)
    return m2, conics, zs, radii, aa


@torch.no_grad()
def alpha_reference(means2d, conics, radii, opacities, W, H, aa=None):
    """Stage 2, dense: (N, H, W) alpha of every Gaussian at every pixel centre: o exp(-sigma)
    capped at 0.99, zero outside its 3-sigma box or below 1/255 (aa: the antialiasing factor,
    opacity x sqrt(aa))."""
    opac = opacities.detach().to("cpu", torch.float64)
    us = torch.arange(W, dtype=torch.float64) + 0.5
    vs = torch.arange(H, dtype=torch.float64) + 0.5
    pv, pu = torch.meshgrid(vs, us, indexing="ij")  # (H, W)
    out = torch.zeros(len(radii), H, W, dtype=torch.float64)
    for i in range(len(radii)):
        r = int(radii[i])
        if r <= 0:
            continue
        du, dv = pu - means2d[i, 0], pv - means2d[i, 1]
        a_, b_, c_ = conics[i].tolist()
        sigma = 0.5 * (a_ * du * du + 2 * b_ * du * dv + c_ * dv * dv)
        o = opac[i] * (math.sqrt(aa[i]) if aa is not None else 1.0)
        a = torch.clamp(o * torch.exp(-sigma), max=0.99)
        out[i] = torch.where((du.abs() <= r) & (dv.abs() <= r) & (a >= 1.0 / 255.0), a, torch.zeros_like(a))
    return out


@torch.no_grad()
def composite_reference(alphas, colors, z, radii, background=None):
    """Stage 3: front to back by camera z (stable), stopping a pixel before its transmittance would
    drop below 1e-4 -> colour (H, W, C), alpha (H, W), depth (H, W) = sum w z."""
    C = colors.shape[1]
    _, H, W = alphas.shape
    order = sorted((i for i in range(len(radii)) if int(radii[i]) > 0), key=lambda i: float(z[i]))
    Timg = torch.ones(H, W, dtype=torch.float64)
    done = torch.zeros(H, W, dtype=torch.bool)
    col = torch.zeros(H, W, C, dtype=torch.float64)
    depth = torch.zeros(H, W, dtype=torch.float64)
    for i in order:
        a = alphas[i]
        test_T = Timg * (1 - a)
        done = done | (test_T < 1e-4)
        w = torch.where(done, torch.zeros_like(a), a * Timg)
        col += w[..., None] * colors[i].to(torch.float64)
        depth += w * float(z[i])
        Timg = torch.where(done, Timg, test_T)
    if background is not None:
        col[..., :3] += Timg[..., None] * background.detach().to(torch.float64)
    return col, 1 - Timg, depth


@torch.no_grad()
def render_reference(means, quats, scales, opacities, sh, camera, background=None, sh_degree=None,
                     near=0.01, eps2d=EPS2D, features=None, antialiased=False):
    """Same contract as rasterize() (rgb, alpha, depth, and features (H, W, F) when features (N, F)
    are given: composited like the colour, over a zero background), computed in float64 by the
    three stages above.  antialiased: opacity x sqrt(det S / det(S + eps2d I)), S the projected
    covariance."""
    f64 = lambda t: t.detach().to("cpu", torch.float64)
    m2, conics, z, radii, aa = project_reference(means, quats, scales, camera, near, eps2d)
    alphas = alpha_reference(m2, conics, radii, opacities, camera.width, camera.height, aa if antialiased else None)
    R, T = f64(camera.R), f64(camera.T)
    d = f64(means) + R.T @ T  # means - camera centre (centre = -R^T T)
    colors = eval_sh(f64(sh), d / d.norm(dim=-1, keepdim=True).clamp_min(1e-300), sh_degree)
    if features is not None:
        colors = torch.cat([colors, f64(features)], 1)
    col, alpha, depth = composite_reference(alphas, colors, z, radii, None if background is None else f64(background))
    out = {"rgb": col[..., :3], "alpha": alpha, "depth": depth}
    if features is not None:
        out["features"] = col[..., 3:]
    return out
