"""EWA projection of 3D Gaussians to the image (the torch path's, differentiable) and the mip
filter's opacity compensation (gsplat's "antialiased" mode), shared by every back end."""
import torch

from splatting.raster.constants import EPS2D, check_eps2d
from splatting.rotations import quat_to_rotmat


def project(means, quats, scales, camera, near=0.01, eps2d=EPS2D):
    """EWA projection (eps2d: a number or a (N,) tensor, check_eps2d). Returns means2d (N,2), conics (N,3) = (a,b,c) of the inverse 2D covariance,
    depths (N,) camera z, radii (N,) long (3 sigma of the largest eigenvalue, 0 = culled),
    boxes (N,4) long pixel ranges [u0, u1, v0, v1] inclusive (empty when u1 < u0)."""
    dt, dev = means.dtype, means.device
    eps2d = check_eps2d(eps2d, means.shape[0], "project")
    if torch.is_tensor(eps2d):
        eps2d = eps2d.to(dev, dt)
    R = camera.R.to(dev, dt)
    T = camera.T.to(dev, dt)
    fx, fy = float(camera.K[0, 0]), float(camera.K[1, 1])
    cx, cy = float(camera.K[0, 2]), float(camera.K[1, 2])
    W, H = camera.width, camera.height

    p = means @ R.T + T
    z = p[:, 2]
    valid = z > near
    zs = torch.where(valid, z, torch.ones_like(z))  # keep culled ones finite
    x, y = p[:, 0], p[:, 1]
    means2d = torch.stack([fx * x / zs + cx, fy * y / zs + cy], -1)

    # perspective Jacobian at the FOV-clamped point (INRIA: 1.3x the half-FOV; gsplat form for any cx)
    limx_pos, limx_neg = (W - cx) / fx + 0.3 * W / (2 * fx), cx / fx + 0.3 * W / (2 * fx)
    limy_pos, limy_neg = (H - cy) / fy + 0.3 * H / (2 * fy), cy / fy + 0.3 * H / (2 * fy)
    tx = torch.clamp(x / zs, -limx_neg, limx_pos) * zs
    ty = torch.clamp(y / zs, -limy_neg, limy_pos) * zs
    q = quats / quats.norm(dim=-1, keepdim=True)
    M = quat_to_rotmat(q) * scales[:, None, :]  # cov3d = M M^T
    # rows of R M via one (3N,3) x (3,3) matmul (batched 3x3 bmm is ~3x slower on CPU)
    RMt = (M.transpose(1, 2).reshape(-1, 3) @ R.T).reshape(-1, 3, 3)
    r0, r1, r2 = RMt[..., 0], RMt[..., 1], RMt[..., 2]
    # A = J R M with the perspective Jacobian J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]]
    iz = 1.0 / zs
    A0 = (fx * iz)[:, None] * r0 - (fx * tx * iz * iz)[:, None] * r2
    A1 = (fy * iz)[:, None] * r1 - (fy * ty * iz * iz)[:, None] * r2
    a = (A0 * A0).sum(-1) + eps2d  # cov2d = A A^T + eps2d I
    b = (A0 * A1).sum(-1)
    c = (A1 * A1).sum(-1) + eps2d
    det = a * c - b * b
    valid = valid & (det > 0)
    det_s = torch.where(valid, det, torch.ones_like(det))
    conics = torch.stack([c / det_s, -b / det_s, a / det_s], -1)

    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.1))
        r = torch.ceil(3.0 * torch.sqrt(lam))
        r = torch.where(valid, r, torch.zeros_like(r))
        # pixel u is touched when its centre u+0.5 lies within [mx - r, mx + r]
        m2 = means2d.detach().clamp(-1e7, 1e7)
        u0 = torch.ceil(m2[:, 0] - r - 0.5).clamp(0, W)
        u1 = torch.floor(m2[:, 0] + r - 0.5).clamp(-1, W - 1)
        v0 = torch.ceil(m2[:, 1] - r - 0.5).clamp(0, H)
        v1 = torch.floor(m2[:, 1] + r - 0.5).clamp(-1, H - 1)
        boxes = torch.stack([u0, u1, v0, v1], -1).long()
        onscreen = valid & (boxes[:, 1] >= boxes[:, 0]) & (boxes[:, 3] >= boxes[:, 2])
        radii = torch.where(onscreen, r, torch.zeros_like(r)).long()
    return means2d, conics, z, radii, boxes


def antialias_opacities(opacities, conics, eps2d, antialiased, who="rasterize"):
    """opacities (N,) x the mip filter's compensation (aa_compensation) where antialiased says: a
    bool for all Gaussians, or a (N,) bool mask (each asset drawn as it was trained).  Shared by
    rasterize and the relight fit's fixed pair list (splatting/relight/render.py prepare), so both
    composite the same alphas.  eps2d: the number or (N,) tensor the conics were projected with."""
    if torch.is_tensor(eps2d):
        eps2d = eps2d.to(conics)
    if torch.is_tensor(antialiased):
        if antialiased.shape != opacities.shape:
            raise ValueError(f"{who}: antialiased mask {tuple(antialiased.shape)} for {tuple(opacities.shape)} "
                             "Gaussians")
        if not bool(antialiased.any()):
            return opacities
        comp = aa_compensation(conics, eps2d)
        return opacities * torch.where(antialiased.to(comp.device), comp, torch.ones_like(comp))
    return opacities * aa_compensation(conics, eps2d) if antialiased else opacities


def aa_compensation(conics, eps2d):
    """sqrt(det S / det(S + eps2d I)) from the conic (S + eps2d I)^-1 = [[A, B], [B, C]]:
    S + eps2d I = [[C, -B], [-B, A]] / d with d = AC - B^2, so det(S + eps2d I) = 1 / d and
    det S = (C/d - eps2d)(A/d - eps2d) - B^2/d^2. 0 where S is degenerate (culled anyway).
    eps2d: a number or a (N,) tensor (per Gaussian, as the conics were projected)."""
    A, B, C = conics.unbind(-1)
    d = A * C - B * B
    d = torch.where(d > 0, d, torch.ones_like(d))
    det_s = (C / d - eps2d) * (A / d - eps2d) - B * B / (d * d)
    return torch.sqrt(torch.clamp_min(det_s * d, 0.0))
