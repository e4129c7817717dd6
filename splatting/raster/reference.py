"""Deliberately simple 3DGS renderer for tests: loops over Gaussians, dense over pixels.

Written from the formulas (not from splatting/raster/sparse.py) so the two can check each other.
Tiny images only: cost is O(H * W * N) with a Python loop over N.
"""
import math

import torch

from splatting.gaussians.sh import eval_sh


def _rotmat(q):
    q = q / q.norm()
    w, x, y, z = q.tolist()
    return torch.tensor([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                         [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                         [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]],
                        dtype=torch.float64)


@torch.no_grad()
def render_reference(means, quats, scales, opacities, sh, camera, background=None, sh_degree=None,
                     near=0.01, eps2d=0.3, features=None, antialiased=False):
    """Same contract as rasterize() (rgb, alpha, depth, and features (H, W, F) when features (N, F)
    are given: composited like the colour, over a zero background), computed in float64.
    antialiased: opacity x sqrt(det S / det(S + eps2d I)), S the projected covariance."""
    f64 = lambda t: t.detach().to("cpu", torch.float64)
    means, quats, scales, opacities, sh = map(f64, (means, quats, scales, opacities, sh))
    feats = None if features is None else f64(features)
    R, T, K = f64(camera.R), f64(camera.T), f64(camera.K)
    W, H = camera.width, camera.height
    fx, fy, cx, cy = K[0, 0].item(), K[1, 1].item(), K[0, 2].item(), K[1, 2].item()
    centre = -R.T @ T
    # pixel centres
    us = torch.arange(W, dtype=torch.float64) + 0.5
    vs = torch.arange(H, dtype=torch.float64) + 0.5
    pv, pu = torch.meshgrid(vs, us, indexing="ij")  # (H, W)

    layers = []  # (camera z, alpha image, colour, )
    for i in range(means.shape[0]):
        xc = R @ means[i] + T
        z = xc[2].item()
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
        cov2 = cov2_raw + eps2d * torch.eye(2, dtype=torch.float64)
        det = torch.linalg.det(cov2).item()
        if det <= 0:
            continue
        inv = torch.linalg.inv(cov2)
        lam_max = 0.5 * (cov2[0, 0] + cov2[1, 1]).item() + math.sqrt(max(0.1, (0.5 * (cov2[0, 0] + cov2[1, 1]).item()) ** 2 - det))
        r = math.ceil(3.0 * math.sqrt(lam_max))
        du, dv = pu - mx, pv - my
        in_box = (du.abs() <= r) & (dv.abs() <= r)
        sigma = 0.5 * (inv[0, 0] * du * du + 2 * inv[0, 1] * du * dv + inv[1, 1] * dv * dv)
        o = opacities[i]
        if antialiased:
            o = o * math.sqrt(max(0.0, torch.linalg.det(cov2_raw).item() / det))
        a = torch.clamp(o * torch.exp(-sigma), max=0.99)
        a = torch.where(in_box & (a >= 1.0 / 255.0), a, torch.zeros_like(a))
        d = means[i] - centre
        col = eval_sh(sh[i:i + 1], (d / d.norm())[None], sh_degree)[0]
        if feats is not None:
            col = torch.cat([col, feats[i]])
        layers.append((z, a, col))

    layers.sort(key=lambda l: l[0])  # stable: equal depths keep index order, as the rasterizers do
    Timg = torch.ones(H, W, dtype=torch.float64)
    done = torch.zeros(H, W, dtype=torch.bool)
    rgb = torch.zeros(H, W, 3 + (0 if feats is None else feats.shape[1]), dtype=torch.float64)
    depth = torch.zeros(H, W, dtype=torch.float64)
    for z, a, col in layers:  # front to back
        test_T = Timg * (1 - a)
        done = done | (test_T < 1e-4)
        w = torch.where(done, torch.zeros_like(a), a * Timg)
        rgb += w[..., None] * col
        depth += w * z
        Timg = torch.where(done, Timg, test_T)
    alpha = 1 - Timg
    if background is not None:
        rgb[..., :3] += Timg[..., None] * f64(background)
    out = {"rgb": rgb[..., :3], "alpha": alpha, "depth": depth}
    if feats is not None:
        out["features"] = rgb[..., 3:]
    return out
