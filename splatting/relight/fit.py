"""Fit per-Gaussian albedo and normal of trained Gaussians to a views folder's albedo/normal passes.

`python -m splatting relight-fit --views OUT/bikes/ID/views/PART [--ply gaussians/PART.ply]` writes
gaussians/PART.relight.npz (cyclist_formats.bike_folder.relight_path).  The geometry (means,
scales, rotations, opacities) is the colour training's and stays fixed, so every view's projection
and pair list is computed once and each step is only the compositing of two 3-channel features
with its backward: seconds, not minutes.  Loss: L1 of the composited (premultiplied) linear albedo
and of the composited unit normals against the passes, in the object's box of each training view.
"""
import math
import os
import time
from dataclasses import dataclass

import torch
import torch.nn.functional as F

from cyclist_formats import bike_folder
from cyclist_formats.errors import UserError
from splatting.gaussians.container import read_ply
from splatting.progress import Progress
from splatting.raster.sparse import composite
from splatting.relight.render import composite_features, prepare
from splatting.gaussians.sh import C0
from splatting.relight.shading import srgb_decode
from splatting.rotations import quat_to_rotmat
from splatting.training.trainer import DEFAULT_HOLDOUT, _box, crop_camera, split_views
from splatting.training.views import load_views


@dataclass
class RelightFitConfig:
    iterations: int = 300
    lr: float = 0.05
    max_size: int = 256        # fit at most at this image size (premultiplied passes area-averaged)
    holdout: tuple = DEFAULT_HOLDOUT
    seed: int = 0
    progress: bool = True


def load_pass_targets(views, scale):
    """(V, H, W, 3) linear albedo and normal targets of views (premultiplied), resized by scale."""
    albs, nrms = [], []
    for name in views.names:
        a, n = bike_folder.read_passes(bike_folder.pass_paths(views.folder, name))
        albs.append(torch.from_numpy(a))
        nrms.append(torch.from_numpy(n))
    A, N = torch.stack(albs).permute(0, 3, 1, 2), torch.stack(nrms).permute(0, 3, 1, 2)
    if scale != 1.0:
        size = (round(A.shape[2] * scale), round(A.shape[3] * scale))
        A, N = F.interpolate(A, size=size, mode="area"), F.interpolate(N, size=size, mode="area")
    return A.permute(0, 2, 3, 1).contiguous(), N.permute(0, 2, 3, 1).contiguous()


def initial_normals(g, items):
    """Each Gaussian's shortest axis (a flat splat's normal), its sign taken from the normal passes:
    summed over the views, the target normal at the pixel under the Gaussian's centre votes.  (An
    exactly reversed normal is a stationary point of the loss through the normalisation: the
    gradient is parallel to it, so the fit alone could not flip it.)"""
    R = quat_to_rotmat(g.quats / g.quats.norm(dim=-1, keepdim=True))  # columns are the local axes
    k = g.log_scales.argmin(-1)
    n = R[torch.arange(len(g)), :, k].float()
    vote = torch.zeros(len(g))
    # metres: "at the visible surface" -- tighter than a thin tube is thick (its back is ~2 radii behind)
    tol = g.scales.min(-1).values.float() + 0.004
    for prep, _, tn in items:
        H, W = tn.shape[:2]
        with torch.no_grad():
            _, alpha, depth = composite(prep["m2"], prep["conics"], prep["opac"], torch.zeros(len(g), 3), prep["z"],
                                        None, prep["pairs"], H, W)
        surface = depth / alpha.clamp_min(1e-4)
        u, v = prep["m2"][:, 0].floor().long(), prep["m2"][:, 1].floor().long()
        ok = (u >= 0) & (u < W) & (v >= 0) & (v < H) & (prep["z"] > 0)
        ok[ok.clone()] &= (alpha[v[ok], u[ok]] > 0.5) & ((prep["z"][ok] - surface[v[ok], u[ok]]).abs() < tol[ok])
        t = torch.zeros(len(g), 3)
        t[ok] = tn[v[ok], u[ok]]  # only where the Gaussian is the surface seen there (not occluded)
        vote += (n * t).sum(-1)
    return torch.where(vote[:, None] < 0, -n, n)


def _views_at(g, views, idx, albedo_t, normal_t, scale, margin=4):
    """Per view: cropped camera, fixed projection + pairs, and the cropped targets."""
    out = []
    for i in idx:
        cam = views.cameras[i].scaled(scale) if scale != 1.0 else views.cameras[i]
        cover = (albedo_t[i].abs().sum(-1) + (normal_t[i].abs().sum(-1) > 0.02)) > 0
        box = _box(cover.float(), margin)
        x0, y0, x1, y1 = box
        c = crop_camera(cam, box)
        out.append((prepare(g, c), albedo_t[i, y0:y1, x0:x1], normal_t[i, y0:y1, x0:x1]))
    return out


def _evaluate(albedo, normals, items):
    """Mean albedo PSNR (linear, box) and mean angular error (degrees) of the normals where covered."""
    ps, ang = [], []
    with torch.no_grad():
        for prep, ta, tn in items:
            (a, n), alpha = composite_features(prep, [albedo, normals])
            mse = float(((a - ta) ** 2).mean())
            ps.append(10 * math.log10(1.0 / max(mse, 1e-12)))
            m = (tn.norm(dim=-1) > 0.5) & (alpha > 0.5)
            if m.any():
                cos = F.cosine_similarity(n[m], tn[m], dim=-1).clamp(-1, 1)
                ang.append(float(torch.rad2deg(torch.acos(cos)).mean()))
    return sum(ps) / len(ps), (sum(ang) / len(ang) if ang else None)


def fit_relight(g, views, cfg: RelightFitConfig = None):
    """Gaussians g (trained on views) -> (albedo (N, 3) linear, normals (N, 3) unit, metrics)."""
    cfg = cfg or RelightFitConfig()
    t0 = time.time()
    torch.manual_seed(cfg.seed)
    scale = min(1.0, cfg.max_size / max(views.height, views.width))
    A, N = load_pass_targets(views, scale)
    train_idx, hold_idx = split_views(views, cfg.holdout)
    tr = _views_at(g, views, train_idx, A, N, scale)
    ho = _views_at(g, views, hold_idx, A, N, scale) if hold_idx else []

    base = srgb_decode(g.sh[:, 0].float() * C0 + 0.5).clamp(0.02, 0.98)  # SH0 -> colour
    albedo_logit = torch.nn.Parameter(torch.logit(base))
    normal_raw = torch.nn.Parameter(initial_normals(g, tr).clone())
    opt = torch.optim.Adam([albedo_logit, normal_raw], lr=cfg.lr)
    gen = torch.Generator().manual_seed(cfg.seed)
    order, loss_v = [], float("nan")
    prog = Progress(cfg.progress)
    for it in range(1, cfg.iterations + 1):
        if not order:
            order = torch.randperm(len(tr), generator=gen).tolist()
        prep, ta, tn = tr[order.pop()]
        nrm = normal_raw / normal_raw.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        (a, n), _ = composite_features(prep, [torch.sigmoid(albedo_logit), nrm])
        loss = (a - ta).abs().mean() + (n - tn).abs().mean()
        opt.zero_grad(set_to_none=True)
        loss.backward()
        opt.step()
        loss_v = float(loss.detach())
        prog.line(f"relight fit {it}/{cfg.iterations} loss {loss_v:.4f} {time.time() - t0:5.1f}s")
    prog.close()
    albedo = torch.sigmoid(albedo_logit).detach()
    normals = (normal_raw / normal_raw.norm(dim=-1, keepdim=True).clamp_min(1e-6)).detach()
    metrics = {"iterations": cfg.iterations, "loss": round(loss_v, 5), "scale": round(scale, 4),
               "wall_s": round(time.time() - t0, 2)}
    if ho:
        p, ang = _evaluate(albedo, normals, ho)
        metrics.update({"heldout_albedo_psnr": round(p, 3),
                        "heldout_normal_err_deg": None if ang is None else round(ang, 2)})
    return albedo, normals, metrics


def fit_file(views_dir, ply_path=None, cfg: RelightFitConfig = None):
    """Fit and write <ply>.relight.npz beside the Gaussians; returns the metrics."""
    from splatting.training.trainer import default_out

    ply_path = ply_path or default_out(views_dir)
    if not os.path.isfile(ply_path):
        raise UserError(f"{ply_path}: no trained Gaussians (run `python -m splatting train --views {views_dir}` first)")
    views = load_views(views_dir)
    missing = [n for n in views.names if not os.path.isfile(bike_folder.pass_paths(views_dir, n)["albedo"])]
    if missing:
        raise UserError(f"{views_dir}: {len(missing)} views lack the albedo/normal passes (e.g. {missing[0]}); "
                        "render them again with render_views")
    g = read_ply(ply_path)
    albedo, normals, metrics = fit_relight(g, views, cfg)
    metrics["path"] = bike_folder.write_relight(ply_path, albedo.numpy(), normals.numpy())
    return metrics


def add_arguments(p):
    p.add_argument("--views", required=True, help="a part's views folder with albedo/ and normal/ passes")
    p.add_argument("--ply", help="the trained Gaussians (default OUT/bikes/ID/gaussians/PART.ply)")
    p.add_argument("--iterations", type=int, default=RelightFitConfig.iterations, help="optimisation steps (default %(default)s)")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def run(args):
    if args.iterations < 1:
        raise UserError("--iterations must be >= 1")
    if not os.path.isdir(args.views):
        raise UserError(f"views folder not found: {args.views}")
    m = fit_file(args.views, args.ply, RelightFitConfig(iterations=args.iterations, progress=not args.quiet))
    print(f"{m['path']}: albedo PSNR {m.get('heldout_albedo_psnr')} dB, normal error "
          f"{m.get('heldout_normal_err_deg')} deg (held-out views), {m['wall_s']} s")
    return 0
