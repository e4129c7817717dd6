"""Initial Gaussians of a part: from points.ply when the views folder has it, else carved from the
masks (visual hull); the hull test that the densification strategy prunes with; the object extent
every length is tied to."""
import math

import torch

from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh import rgb_to_sh0
from splatting.training.views import Views


def _knn_scale(points, k=3, chunk=2048):
    """sqrt of the mean squared distance to the k nearest neighbours (INRIA's distCUDA2 init)."""
    out = torch.empty(len(points))
    for i in range(0, len(points), chunk):
        d = torch.cdist(points[i:i + chunk], points)
        d2 = d.topk(min(k + 1, len(points)), largest=False).values[:, 1:] ** 2
        out[i:i + chunk] = d2.mean(1).clamp_min(1e-14).sqrt() if d2.shape[1] else 1e-3
    return out


def _project(points, cam):
    p = points @ cam.R.T + cam.T
    z = p[:, 2]
    zs = torch.where(z > 1e-6, z, torch.ones_like(z))
    u = cam.K[0, 0] * p[:, 0] / zs + cam.K[0, 2]
    v = cam.K[1, 1] * p[:, 1] / zs + cam.K[1, 2]
    return u, v, z > 1e-6


def hull_mask(points, masks, cams):
    """(N,) bool: centre projects inside masks[i] (bool (H, W)) in every camera."""
    keep = torch.ones(len(points), dtype=torch.bool)
    for m, cam in zip(masks, cams):
        u, v, front = _project(points, cam)
        H, W = m.shape
        ui, vi = torch.floor(u).long(), torch.floor(v).long()
        inside = front & (ui >= 0) & (ui < W) & (vi >= 0) & (vi < H)
        hit = torch.zeros_like(keep)
        hit[inside] = m[vi[inside], ui[inside]]
        keep &= hit
    return keep


def _carve_init(views: Views, n, gen):
    """No points.ply: sample the cube the silhouettes span around the orbit centre, keep the visual hull."""
    centre = views.orbit_centre
    if centre is None:  # where the optical axes meet (least squares)
        A, b = torch.zeros(3, 3), torch.zeros(3)
        for c in views.cameras:
            d = c.R[2] / c.R[2].norm()
            P = torch.eye(3) - torch.outer(d, d)
            A += P
            b += P @ c.centre
        centre = torch.linalg.solve(A, b)
    half = 0.0
    for c, img in zip(views.cameras, views.images):
        ys, xs = torch.nonzero(img[..., 3] > 0, as_tuple=True)
        if len(xs):
            dist = float((c.centre - centre).norm())
            off = max(float((xs + 0.5 - c.K[0, 2]).abs().max()) / float(c.K[0, 0]),
                      float((ys + 0.5 - c.K[1, 2]).abs().max()) / float(c.K[1, 1]))
            half = max(half, 1.2 * off * dist)
    masks = [img[..., 3] > 0 for img in views.images]
    pts = torch.empty(0, 3)
    for _ in range(20):
        cand = centre + (torch.rand(20 * n, 3, generator=gen) * 2 - 1) * half
        pts = torch.cat([pts, cand[hull_mask(cand, masks, views.cameras)]])
        if len(pts) >= n:
            break
    if len(pts) == 0:
        raise UserError(f"{views.folder}: the silhouettes have no common volume (cameras and masks disagree)")
    return pts[:n]


def init_gaussians(views: Views, cfg, gen):
    """cfg: a TrainConfig (init_max_points, init_opacity, sh_degree, densify.max_gaussians)."""
    if views.points is not None:
        pts, cols = views.points, views.point_colors
        n = min(len(pts), cfg.init_max_points, cfg.densify.max_gaussians)
        if n < len(pts):
            idx = torch.randperm(len(pts), generator=gen)[:n]
            pts = pts[idx]
            cols = None if cols is None else cols[idx]
    else:
        pts = _carve_init(views, min(5000, cfg.densify.max_gaussians), gen)
        cols = None
    pts = pts.float()
    n = len(pts)
    if cols is None:
        cols = torch.full((n, 3), 0.5)
    k = (cfg.sh_degree + 1) ** 2
    sh = torch.zeros(n, k, 3)
    sh[:, 0] = rgb_to_sh0(cols.float())
    scale = _knn_scale(pts)
    return Gaussians(
        means=pts.clone(),
        quats=torch.tensor([1.0, 0.0, 0.0, 0.0]).repeat(n, 1),
        log_scales=torch.log(scale)[:, None].repeat(1, 3),
        opacity_logits=torch.full((n,), math.log(cfg.init_opacity / (1 - cfg.init_opacity))),
        sh=sh,
    )


def object_extent(points):
    lo, hi = points.min(0).values, points.max(0).values
    return max(float((hi - lo).norm()), 1e-3)


