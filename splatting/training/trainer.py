"""`python -m splatting train --views OUT/bikes/ID/views/PART [--out FILE.ply]`: fit one part's Gaussians.

Vanilla 3DGS on CPU: Adam on means / log-scales / quaternions / logit-opacity / SH, loss
0.8 L1 + 0.2 (1 - SSIM) on RGBA (RGB composited over a random background each step, plus alpha
against the mask, so the silhouette is learnt), adaptive density control from splatting.densify.
For speed: coarse-to-fine resolution, every render cropped to the object's box in that view, and
a stop once held-out PSNR no longer improves.  See docs/training.md for the numbers behind the
defaults.
"""
import dataclasses
import math
import os
import sys
import time
from dataclasses import dataclass, field

import torch
import torch.nn.functional as F

from cyclist_formats.atomic import write_json
from splatting.raster.camera import Camera
from splatting.training.strategy import DensifyConfig, DensifyStrategy
from cyclist_formats.errors import UserError
from splatting.gaussians.container import Gaussians, write_ply
from splatting.raster.sparse import rasterize
from splatting.gaussians.sh import rgb_to_sh0
from splatting.training.views import Views, load_views

DEFAULT_HOLDOUT = (3, 12, 21, 30)


@dataclass
class TrainConfig:
    iterations: int = 3000
    time_budget_s: float = 600.0
    sh_degree: int = 0
    holdout: tuple = DEFAULT_HOLDOUT
    seed: int = 0
    threads: int = None              # torch.set_num_threads; None leaves torch's default
    # coarse-to-fine: (first iteration, image scale); renders are always cropped to the object
    resolution_schedule: tuple = ((0, 1.0),)
    crop_margin_px: int = 8          # at full resolution
    # INRIA learning rates; the means' rate is x extent (object bounding-box diagonal, metres)
    lr_means: float = 1.6e-4
    lr_means_final: float = 1.6e-6
    lr_sh0: float = 2.5e-3
    lr_shN: float = 2.5e-3 / 20
    lr_opacity: float = 0.05
    lr_scales: float = 5e-3
    lr_quats: float = 1e-3
    lambda_dssim: float = 0.2
    init_max_points: int = 10000     # subsample points.ply beyond this
    init_opacity: float = 0.1
    hull_prune: bool = True          # drop Gaussians whose centre leaves the dilated silhouettes
    eval_every: int = 200
    patience: int = 3                # evaluations without a min_delta gain before stopping
    min_delta_db: float = 0.05
    progress: bool = True
    densify: DensifyConfig = field(default_factory=DensifyConfig)


# -- data preparation ----------------------------------------------------------------------------

def split_views(views: Views, holdout):
    """Hold out views by index in the ring (camera0003 -> 3); the rest train."""
    hold = sorted({i for i in holdout if 0 <= i < len(views)})
    train = [i for i in range(len(views)) if i not in hold]
    if not train:
        raise UserError(f"no training views left after holding out {list(holdout)} of {len(views)}")
    return train, hold


def crop_camera(cam: Camera, box):
    """The sub-image [x0, x1) x [y0, y1) of cam as a camera of its own (pixel centres unchanged)."""
    x0, y0, x1, y1 = box
    K = cam.K.clone()
    K[0, 2] -= x0
    K[1, 2] -= y0
    return Camera(cam.R, cam.T, K, x1 - x0, y1 - y0, cam.name)


def _box(alpha, margin, min_size=16):
    """Bounding box (x0, y0, x1, y1) of alpha > 0 plus margin, at least min_size (SSIM's 11 px window)."""
    H, W = alpha.shape
    ys, xs = torch.nonzero(alpha > 0, as_tuple=True)
    if len(xs) == 0:
        x0, x1, y0, y1 = W // 2, W // 2, H // 2, H // 2
    else:
        x0, x1, y0, y1 = int(xs.min()), int(xs.max()) + 1, int(ys.min()), int(ys.max()) + 1
    x0, y0, x1, y1 = max(0, x0 - margin), max(0, y0 - margin), min(W, x1 + margin), min(H, y1 + margin)

    def grow(a, b, n):  # widen [a, b) to min_size around its centre, inside [0, n)
        if b - a >= min_size or n <= min_size:
            return 0 if n <= min_size else a, n if n <= min_size else b
        a = min(max(0, (a + b) // 2 - min_size // 2), n - min_size)
        return a, a + min_size

    x0, x1 = grow(x0, x1, W)
    y0, y1 = grow(y0, y1, H)
    return max(0, x0), max(0, y0), min(W, x1), min(H, y1)


class Targets:
    """Per-scale premultiplied RGBA targets, cameras and object crop boxes for a set of views."""

    def __init__(self, views: Views, margin_px):
        self.views = views
        self.margin_px = margin_px
        rgba = views.images.permute(0, 3, 1, 2)  # (V, 4, H, W)
        self.premult = torch.cat([rgba[:, :3] * rgba[:, 3:], rgba[:, 3:]], 1)
        self._cache = {}

    def at(self, scale):
        if scale not in self._cache:
            H, W = self.views.height, self.views.width
            if scale == 1.0:
                img = self.premult
            else:  # area-average premultiplied colour, so edges blend as the renderer's do
                img = F.interpolate(self.premult, size=(round(H * scale), round(W * scale)), mode="area")
            cams = [c.scaled(scale) if scale != 1.0 else c for c in self.views.cameras]
            m = max(2, int(round(self.margin_px * scale)))
            boxes = [_box(img[i, 3], m) for i in range(len(cams))]
            self._cache[scale] = (img, cams, boxes)
        return self._cache[scale]


# -- initialisation ------------------------------------------------------------------------------

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


def init_gaussians(views: Views, cfg: TrainConfig, gen):
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


# -- training ------------------------------------------------------------------------------------

def _params_from(g: Gaussians):
    p = {"means": g.means, "quats": g.quats, "log_scales": g.log_scales,
         "opacity_logits": g.opacity_logits, "sh0": g.sh[:, :1], "shN": g.sh[:, 1:]}
    return {k: torch.nn.Parameter(v.detach().clone().contiguous()) for k, v in p.items()}


def gaussians_of(params) -> Gaussians:
    return Gaussians(params["means"], params["quats"], params["log_scales"], params["opacity_logits"],
                     torch.cat([params["sh0"], params["shN"]], 1))


def _render(params, cam, background=None, sh_degree=None):
    return rasterize(params["means"], params["quats"], torch.exp(params["log_scales"]),
                     torch.sigmoid(params["opacity_logits"]), torch.cat([params["sh0"], params["shN"]], 1),
                     cam, background=background, sh_degree=sh_degree)


def _ssim(a, b):
    from pytorch_msssim import ssim

    return ssim(a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None], data_range=1.0, size_average=True)


def psnr(a, b):
    mse = float(((a - b) ** 2).mean())
    return 10 * math.log10(1.0 / max(mse, 1e-12))


@torch.no_grad()
def evaluate(g_or_params, targets: Targets, background=(1.0, 1.0, 1.0), crop=False):
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
        out = _render(params, cam, background=bg)
        pred = out["rgb"].clamp(0, 1)
        ps.append(psnr(pred, gt_rgb))
        ss.append(float(_ssim(pred, gt_rgb)))
    return sum(ps) / len(ps), sum(ss) / len(ss)


def _adam(params, cfg, extent):
    lrs = {"means": cfg.lr_means * extent, "quats": cfg.lr_quats, "log_scales": cfg.lr_scales,
           "opacity_logits": cfg.lr_opacity, "sh0": cfg.lr_sh0, "shN": cfg.lr_shN}
    groups = [{"params": [params[k]], "lr": lrs[k], "name": k} for k in params]
    return torch.optim.Adam(groups, lr=0.0, eps=1e-15)


def _finite_grads(params):
    return all(p.grad is None or bool(torch.isfinite(p.grad).all()) for p in params.values())


class Progress:
    def __init__(self, enabled, total):
        self.enabled, self.total = enabled, total
        self.tty = enabled and sys.stderr.isatty()
        self.last = 0.0

    def update(self, it, loss, n, psnr_db, wall, force=False):
        if not self.enabled:
            return
        now = time.time()
        if not force and now - self.last < (0.5 if self.tty else 15.0):
            return
        self.last = now
        p = "  -.-- " if psnr_db is None else f"{psnr_db:6.2f}"
        line = f"train {it:5d}/{self.total} loss {loss:.4f} gaussians {n:6d} held-out PSNR {p} dB {wall:6.1f}s"
        sys.stderr.write(("\r" + line) if self.tty else line + "\n")
        sys.stderr.flush()

    def close(self):
        if self.tty:
            sys.stderr.write("\n")


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
    dens = DensifyStrategy(cfg.densify, extent)
    # silhouettes at half resolution, dilated ~4 full-res pixels: a Gaussian centred outside them
    # sits where every training image is empty
    hull_scale = 0.5
    himg, hcams, _ = tr.at(hull_scale)
    hmasks = [m > 0 for m in F.max_pool2d(himg[:, 3:], 5, 1, 2)[:, 0]]
    hull = (lambda: hull_mask(params["means"].detach(), hmasks, hcams)) if cfg.hull_prune else (lambda: None)

    gamma = (cfg.lr_means_final / cfg.lr_means) ** (1.0 / max(1, cfg.iterations))
    sched = sorted(cfg.resolution_schedule)
    order = []
    history, rejected = [], []
    best, since_best, stopped = -1.0, 0, "iterations"
    progress = Progress(cfg.progress, cfg.iterations)
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
        out = _render(params, cam, sh_degree=cfg.sh_degree)
        bg = torch.rand(3, generator=gen)  # random background: colour and alpha are both pinned down
        pred = torch.cat([out["rgb"] + (1 - out["alpha"])[..., None] * bg, out["alpha"][..., None]], -1)
        target = torch.cat([gt[..., :3] + (1 - gt[..., 3:]) * bg, gt[..., 3:]], -1)
        loss = (1 - cfg.lambda_dssim) * (pred - target).abs().mean() + cfg.lambda_dssim * (1 - _ssim(pred, target))

        ok = bool(torch.isfinite(loss))
        if ok:
            loss.backward()
            ok = _finite_grads(params) and (out["means2d"].grad is None or bool(torch.isfinite(out["means2d"].grad).all()))
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
        with torch.no_grad():
            dens.accumulate(out["means2d"].grad, out["radii"], cams[v].width, cams[v].height)
            dens.step(it, params, opt, keep_mask=hull() if dens.is_densify_step(it) else None)

        if ho is not None and (it % cfg.eval_every == 0 or it == cfg.iterations):
            last_psnr, _ = evaluate(params, ho, crop=True)
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

    with torch.no_grad():
        if cfg.hull_prune:
            dens.prune(params, opt, hull())
        if cfg.densify.min_opacity > 0:  # invisible Gaussians only cost render time
            keep = torch.sigmoid(params["opacity_logits"]) >= cfg.densify.min_opacity
            if keep.any():
                dens.prune(params, opt, keep)
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
        "max_gaussians": cfg.densify.max_gaussians,
        "extent_m": round(extent, 4),
        "threads": torch.get_num_threads(),
        "rejected_steps": len(rejected),
        "rejected_iterations": rejected[:100],
        "densify": dens.stats,
        "psnr_history": history,
        "psnr_history_fields": ["iteration", "wall_s", "psnr_crop", "gaussians"],
        "config": _config_dict(cfg),
    }
    if ho is not None:
        metrics["psnr"], metrics["ssim"] = [round(x, 4) for x in evaluate(g, ho)]
        metrics["psnr_crop"] = round(evaluate(g, ho, crop=True)[0], 4)
    metrics["eval_s"] = round(time.time() - t0 - train_wall, 2)
    return g, metrics


def _config_dict(cfg):
    d = dataclasses.asdict(cfg)
    d["holdout"] = list(d["holdout"])
    d["resolution_schedule"] = [list(x) for x in d["resolution_schedule"]]
    return d


def default_out(views_dir):
    """.../<bike>/views/<part> -> .../<bike>/gaussians/<part>.ply (DESIGN.md)."""
    d = os.path.abspath(views_dir)
    part, parent = os.path.basename(d), os.path.dirname(d)
    if os.path.basename(parent) != "views":
        raise UserError(f"{views_dir} is not .../<bike>/views/<part>; pass --out")
    return os.path.join(os.path.dirname(parent), "gaussians", part + ".ply")


def train(views_dir, out_ply=None, config: TrainConfig = None):
    """Load a views folder, train, write <out>.ply and <out>.json atomically. Returns the metrics."""
    cfg = config or TrainConfig()
    out_ply = out_ply or default_out(views_dir)
    views = load_views(views_dir)
    g, metrics = train_views(views, cfg)
    metrics["part"] = os.path.basename(os.path.abspath(views_dir))
    write_ply(g, out_ply)
    write_json(os.path.splitext(out_ply)[0] + ".json", metrics)
    return metrics


# -- command line --------------------------------------------------------------------------------

def _int_list(s):
    try:
        return tuple(int(x) for x in s.split(",") if x.strip())
    except ValueError:
        raise UserError(f"--holdout wants comma-separated view indices, got {s!r}")


def add_arguments(p):
    d = TrainConfig()
    p.add_argument("--views", required=True, help="a part's views folder: OUT/bikes/ID/views/PART")
    p.add_argument("--out", help="output .ply (default OUT/bikes/ID/gaussians/PART.ply; metrics in PART.json beside it)")
    p.add_argument("--iterations", type=int, default=d.iterations)
    p.add_argument("--time-budget-s", type=float, default=d.time_budget_s, help="stop after this much wall time")
    p.add_argument("--max-gaussians", type=int, default=d.densify.max_gaussians, help="hard budget")
    p.add_argument("--sh-degree", type=int, default=d.sh_degree, choices=(0, 1, 2, 3))
    p.add_argument("--holdout", default=",".join(map(str, d.holdout)), help="held-out view indices")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--threads", type=int, default=1,
                   help="torch.set_num_threads; 1 by default: on the shared 2-core machine 2 threads ran 4-7x "
                        "slower per iteration (oversubscription), see docs/training.md")
    p.add_argument("--no-early-stop", action="store_true", help="run all iterations")
    p.add_argument("--quiet", action="store_true", help="no progress line")


def config_from_args(args):
    cfg = TrainConfig(iterations=args.iterations, time_budget_s=args.time_budget_s, sh_degree=args.sh_degree,
                      holdout=_int_list(args.holdout), seed=args.seed, threads=args.threads,
                      progress=not args.quiet)
    cfg.densify.max_gaussians = args.max_gaussians
    if args.no_early_stop:
        cfg.patience = 10 ** 9
    for name in ("iterations", "max_gaussians"):
        if getattr(args, name) < 1:
            raise UserError(f"--{name.replace('_', '-')} must be >= 1")
    return cfg


def check_args(args):
    """Impossible values and unusable paths, refused before any work (cyclist_formats.checks)."""
    from cyclist_formats import checks
    checks.count("iterations", args.iterations)
    checks.positive("time_budget_s", args.time_budget_s)
    checks.gaussians("max_gaussians", args.max_gaussians)
    checks.threads("threads", args.threads)
    checks.integer("seed", args.seed, 0)
    if any(i < 0 for i in _int_list(args.holdout)):
        raise UserError(f"--holdout view indices must be >= 0, got {args.holdout!r}")
    checks.views_folder(args.views)
    checks.output_file("out", args.out if args.out else default_out(args.views), (".ply",))


def run(args):
    cfg = config_from_args(args)
    m = train(args.views, args.out, cfg)
    out = args.out or default_out(args.views)
    print(f"{out}: {m['gaussians']} Gaussians, held-out PSNR {m['psnr']} dB, SSIM {m['ssim']}, "
          f"{m['iterations']} iterations in {m['wall_s']} s ({m['stopped']})")
    return 0
