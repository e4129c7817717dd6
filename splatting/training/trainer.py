"""`python -m splatting train --views OUT/bikes/ID/views/PART [--out FILE.ply]`: fit one part's Gaussians.

Vanilla 3DGS on CPU: Adam on means / log-scales / quaternions / logit-opacity / SH, loss
0.8 L1 + 0.2 (1 - SSIM) on RGBA (RGB composited over a random background each step, plus alpha
against the mask, so the silhouette is learnt), densification from the configured strategy (strategy.py).
For speed: coarse-to-fine resolution, every render cropped to the object's box in that view, and
a stop once held-out PSNR no longer improves.  See docs/training.md for the numbers behind the
defaults.
"""
import os
import time

import torch
import torch.nn.functional as F

from cyclist_formats.atomic import write_json
from cyclist_formats.typed_config import record_of
from splatting.training.config import TrainConfig
from splatting.training.strategy import make_strategy
from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians, write_ply
from splatting.raster.api import EPS2D, rasterize
from splatting.training.views import Views, load_views
from splatting.training.metrics import psnr, ssim
from splatting.training.targets import Targets, crop_camera, split_views  # noqa: F401
from splatting.training.initialisation import hull_mask, init_gaussians, object_extent  # noqa: F401
from splatting.progress import Progress



# -- training ------------------------------------------------------------------------------------

def _params_from(g: Gaussians):
    p = {"means": g.means, "quats": g.quats, "log_scales": g.log_scales,
         "opacity_logits": g.opacity_logits, "sh0": g.sh[:, :1], "shN": g.sh[:, 1:]}
    return {k: torch.nn.Parameter(v.detach().clone().contiguous()) for k, v in p.items()}


def gaussians_of(params) -> Gaussians:
    return Gaussians(params["means"], params["quats"], params["log_scales"], params["opacity_logits"],
                     torch.cat([params["sh0"], params["shN"]], 1))


def _render(params, cam, background=None, sh_degree=None, antialiased=False, eps2d=EPS2D):
    return rasterize(params["means"], params["quats"], torch.exp(params["log_scales"]),
                     torch.sigmoid(params["opacity_logits"]), torch.cat([params["sh0"], params["shN"]], 1),
                     cam, background=background, sh_degree=sh_degree, antialiased=antialiased, eps2d=eps2d)


@torch.no_grad()
def evaluate(g_or_params, targets: Targets, background=(1.0, 1.0, 1.0), crop=False, antialiased=False, eps2d=EPS2D):
    """Held-out quality on RGB composited over `background` (white: the NeRF-synthetic convention).
    crop=False: whole images (the reported numbers); crop=True: the object's box only (cheaper)."""
    params = _params_from(g_or_params) if isinstance(g_or_params, Gaussians) else g_or_params
    img, cams, boxes = targets.at(1.0)
    bg = torch.tensor(background)
    ps, ss = [], []
    for i, cam in enumerate(cams):
        gt = img[i].permute(1, 2, 0)
        if crop:
            x0, y0, x1, y1 = boxes[i]
            cam = crop_camera(cam, boxes[i])
            gt = gt[y0:y1, x0:x1]
        gt_rgb = gt[..., :3] + (1 - gt[..., 3:]) * bg
        out = _render(params, cam, background=bg, antialiased=antialiased, eps2d=eps2d)
        pred = out["rgb"].clamp(0, 1)
        ps.append(psnr(pred, gt_rgb))
        ss.append(float(ssim(pred, gt_rgb)))
    return sum(ps) / len(ps), sum(ss) / len(ss)


def _adam(params, cfg, extent):
    lrs = {"means": cfg.lr_means * extent, "quats": cfg.lr_quats, "log_scales": cfg.lr_scales,
           "opacity_logits": cfg.lr_opacity, "sh0": cfg.lr_sh0, "shN": cfg.lr_shN}
    groups = [{"params": [params[k]], "lr": lrs[k], "name": k} for k in params]
    return torch.optim.Adam(groups, lr=0.0, eps=1e-15)


def finite_grads(params):
    return all(p.grad is None or bool(torch.isfinite(p.grad).all()) for p in params.values())


def rgba_loss(out, gt, bg, lambda_dssim):
    """(1 - lambda) L1 + lambda (1 - SSIM) on RGBA: a render `out` and its premultiplied target gt
    (h, w, 4), both RGB over the background colour bg (3,) (random per step: colour and alpha are
    both pinned down), plus alpha against the mask."""
    pred = torch.cat([out["rgb"] + (1 - out["alpha"])[..., None] * bg, out["alpha"][..., None]], -1)
    target = torch.cat([gt[..., :3] + (1 - gt[..., 3:]) * bg, gt[..., 3:]], -1)
    return (1 - lambda_dssim) * (pred - target).abs().mean() + lambda_dssim * (1 - ssim(pred, target))


class TrainProgress(Progress):
    def update(self, it, loss, n, psnr_db, wall, force=False):
        p = "  -.-- " if psnr_db is None else f"{psnr_db:6.2f}"
        self.line(f"train {it:5d}/{self.total} loss {loss:.4f} gaussians {n:6d} held-out PSNR {p} dB {wall:6.1f}s", force)


def train_views(views: Views, cfg: TrainConfig):
    """Train on an in-memory Views. Returns (Gaussians, metrics dict)."""
    t0 = time.time()
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    torch.manual_seed(cfg.seed)
    gen = torch.Generator().manual_seed(cfg.seed)
    train_idx, hold_idx = split_views(views, cfg.holdout)
    tr = Targets(views.subset(train_idx), cfg.crop_margin_px)
    ho = Targets(views.subset(hold_idx), cfg.crop_margin_px) if hold_idx else None

    g0 = init_gaussians(views, cfg, gen)
    extent = object_extent(views.points if views.points is not None else g0.means)
    params = _params_from(g0)
    opt = _adam(params, cfg, extent)
    # silhouettes at half resolution, dilated ~4 full-res pixels: a Gaussian centred outside them
    # sits where every training image is empty
    hull_scale = 0.5
    himg, hcams, _ = tr.at(hull_scale)
    hmasks = [m > 0 for m in F.max_pool2d(himg[:, 3:], 5, 1, 2)[:, 0]]
    dens = make_strategy(cfg.strategy, cfg.densify, extent, hull=lambda: hull_mask(params["means"].detach(), hmasks, hcams))

    gamma = (cfg.lr_means_final / cfg.lr_means) ** (1.0 / max(1, cfg.iterations))
    sched = sorted(cfg.resolution_schedule)
    order = []
    history, rejected = [], []
    best, since_best, stopped = -1.0, 0, "iterations"
    progress = TrainProgress(cfg.progress)
    progress.total = cfg.iterations
    loss_v, last_psnr, it = float("nan"), None, 0
    for it in range(1, cfg.iterations + 1):
        if time.time() - t0 > cfg.time_budget_s:
            stopped, it = "time_budget", it - 1
            break
        scale = [s for start, s in sched if it > start][-1] if any(it > s for s, _ in sched) else sched[0][1]
        img, cams, boxes = tr.at(scale)
        if not order:
            order = torch.randperm(len(cams), generator=gen).tolist()
        v = order.pop()
        x0, y0, x1, y1 = boxes[v]
        cam = crop_camera(cams[v], boxes[v])
        gt = img[v, :, y0:y1, x0:x1].permute(1, 2, 0)
        out = _render(params, cam, sh_degree=cfg.sh_degree, antialiased=cfg.antialiased, eps2d=cfg.eps2d)
        loss = rgba_loss(out, gt, torch.rand(3, generator=gen), cfg.lambda_dssim)  # a random background

        ok = bool(torch.isfinite(loss))
        if ok:
            loss.backward()
            ok = finite_grads(params) and (out["means2d"].grad is None or bool(torch.isfinite(out["means2d"].grad).all()))
        if not ok:  # reject the step: no parameter or Adam moment is touched
            opt.zero_grad(set_to_none=True)
            rejected.append(it)
            continue
        opt.step()
        opt.zero_grad(set_to_none=True)
        loss_v = float(loss.detach())
        for grp in opt.param_groups:
            if grp["name"] == "means":
                grp["lr"] = cfg.lr_means * extent * gamma ** it
        dens.post_backward(it, params, opt, out["means2d"].grad, out["radii"], cams[v].width, cams[v].height)

        if ho is not None and (it % cfg.eval_every == 0 or it == cfg.iterations):
            last_psnr, _ = evaluate(params, ho, crop=True, antialiased=cfg.antialiased, eps2d=cfg.eps2d)
            history.append([it, round(time.time() - t0, 2), round(last_psnr, 3), len(params["means"])])
            if last_psnr > best + cfg.min_delta_db:
                best, since_best = last_psnr, 0
            else:
                since_best += 1
            # judge only once densification has finished and the full resolution is in use
            if it > cfg.densify.stop and it > sched[-1][0] and since_best >= cfg.patience:
                stopped = "early"
                progress.update(it, loss_v, len(params["means"]), last_psnr, time.time() - t0, force=True)
                break
        progress.update(it, loss_v, len(params["means"]), last_psnr, time.time() - t0)
    progress.close()

    dens.finish(params, opt)
    g = gaussians_of({k: p.detach() for k, p in params.items()})
    train_wall = time.time() - t0
    metrics = {
        "views": os.path.abspath(views.folder),
        "holdout": [views.names[i] for i in hold_idx],
        "psnr": None, "ssim": None, "psnr_crop": None,
        "metric_convention": "held-out views, RGB over white, mean of per-view PSNR; psnr_crop: object box only",
        "gaussians": len(g),
        "wall_s": round(train_wall, 2),
        "iterations": it,
        "stopped": stopped,
        "sh_degree": cfg.sh_degree,
        "antialiased": cfg.antialiased,
        "eps2d": cfg.eps2d,
        "max_gaussians": cfg.densify.max_gaussians,
        "extent_m": round(extent, 4),
        "threads": torch.get_num_threads(),
        "rejected_steps": len(rejected),
        "rejected_iterations": rejected[:100],
        "densify": dens.stats,
        "psnr_history": history,
        "psnr_history_fields": ["iteration", "wall_s", "psnr_crop", "gaussians"],
        "config": record_of(cfg),
    }
    if ho is not None:
        metrics["psnr"], metrics["ssim"] = [round(x, 4) for x in evaluate(g, ho, antialiased=cfg.antialiased,
                                                                          eps2d=cfg.eps2d)]
        metrics["psnr_crop"] = round(evaluate(g, ho, crop=True, antialiased=cfg.antialiased, eps2d=cfg.eps2d)[0], 4)
    metrics["eval_s"] = round(time.time() - t0 - train_wall, 2)
    return g, metrics


def default_out(views_dir):
    """.../<bike>/views/<part> -> .../<bike>/gaussians/<part>.ply (docs/contract.md)."""
    d = os.path.abspath(views_dir)
    part, parent = os.path.basename(d), os.path.dirname(d)
    if os.path.basename(parent) != "views":
        raise UserError(f"{views_dir} is not .../<bike>/views/<part>; pass --out")
    return os.path.join(os.path.dirname(parent), "gaussians", part + ".ply")


def train(views_dir, out_ply=None, config: TrainConfig = None):
    """Load a views folder, train, write <out>.ply and <out>.json atomically. Returns the metrics.
    (Relight channels are fitted after training by their own stage: splatting.relight.fit.)"""
    cfg = config or TrainConfig()
    out_ply = out_ply or default_out(views_dir)
    views = load_views(views_dir)
    g, metrics = train_views(views, cfg)
    metrics["part"] = os.path.basename(os.path.abspath(views_dir))
    write_trained(g, out_ply, metrics)
    return metrics


def write_trained(g, out_ply, metrics):
    """<out>.ply and its training record <out>.json (splatting.training.record reads it)."""
    write_ply(g, out_ply)
    write_json(os.path.splitext(out_ply)[0] + ".json", metrics)
