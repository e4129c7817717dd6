"""Fine-tune a bike's part Gaussians together, through the 8-DoF pose, on Blender renders of the posed bike.

Each part is first trained alone at rest on its ring (training/trainer.py): 36 horizontal views of
that part, lit as it sits in the canonical bike.  A random pose changes what those parts never saw:
the crank and steering turn under the suns (a pedal at 90 degrees shows its face to the key light),
the other parts shadow and hide them, and roll/pitch look at the bike from above or below the ring.
Here the whole bike's mesh is rendered by Blender at random 8-DoF poses from random ring cameras
(blender_scripts/render_pose.py --batch, suns following the global pose as in the ground truth),
and every step renders the composed parts re-posed by BikeModel's rigid part transforms; the loss
flows back into each part's canonical means, rotations, scales, opacities and colours (as
splatting/rider/posed_train.py does for riders).  The whole bike's rest-pose ring (views/whole)
stays in the mix.  By default no densification: the per-part training placed the Gaussians.  With
--densify each part runs the trainer's adaptive density control (training/strategy.py) on its own
Gaussians during the first half of the fine-tune, fed with the screen-space gradients of the posed
renders (rigid transforms move a Gaussian's centre, they leave its pixel gradient as it is), up to
--densify-max Gaussians per part: room at the silhouettes the rest-trained budget turned away.

    python -m splatting bike-posed-train --bike OUT/bikes/ID [--poses 144 --iterations 6000 --sh-degree 1]

writes OUT/bikes/ID/gaussians/<part>.ply in place (the rest-trained ones kept as <part>_rest.ply)
and gaussians/posed_train.json (config, held-out-pose scores before/after); with --from-rest (the
library's posed:<bike> task) it starts from gaussians/<part>_rest.{ply,json} as the library's train
tasks left them and never writes those.  Parts of the fine-tune's own --sh-degree (a fine-tuned
bike's, copied without its posed_train.json) are continued from where they are, every SH band
included (e.g. a few low-rate steps at another --eps2d).  Training poses come
from seeds 1000, 1001, ... of splatting.bike.pose.sample_poses (48 a seed): never the checks' poses
(seed 0).
"""
import os
import shutil
import subprocess
import sys
import time
from PIL import Image
import numpy as np
import torch

from cyclist_formats import bike_folder, ring
from cyclist_formats.atomic import read_json_or_none, write_json
from cyclist_formats.errors import UserError
from cyclist_formats.typed_config import record_of
from splatting import paths
from splatting.bike.model import BikeModel
from splatting.bike.posed_config import HELD_OUT, PosedTrainConfig
from splatting.bike.pose import check_poses, sample_poses
from splatting.progress import Progress
from splatting.raster.camera import from_numpy
from splatting.raster.api import rasterize
from splatting.training.trainer import finite_grads, rgba_loss
from splatting.gaussians.container import Gaussians, read_ply, write_ply
from splatting.gaussians.sh_rotation import BANDS, sh_band_matrices
from splatting.training.metrics import box_psnr, mask_iou
from splatting.training.strategy import DensifyConfig, DensifyStrategy
from splatting.training.targets import crop_box, crop_camera, Targets
from splatting.training.views import load_views

RENDER_SCRIPT = paths.blender_script("render_pose.py")
POSE_SEED = 1000
POSE_BLOCK = 48


def training_poses(n):
    """n random 8-DoF poses and ring-camera indices (the ground-truth check's ranges, other seeds).
    Drawn in blocks of POSE_BLOCK (seeds POSE_SEED, POSE_SEED + 1, ...), so the first n of any larger
    --poses are these same n: more poses reuse the renders already made (block 0 is what 48 poses
    always were, sample_poses(48, 1000))."""
    blocks = [sample_poses(POSE_BLOCK, POSE_SEED + b) for b in range(-(-n // POSE_BLOCK))]
    return np.concatenate([p for p, _ in blocks])[:n], np.concatenate([c for _, c in blocks])[:n]


def render_posed_views(bike_dir, out_dir, cfg: PosedTrainConfig, log=print, threads=None):
    """out_dir/posed_NNN.png for every training pose (resumable) and out_dir/poses.json. Returns the jobs.
    threads: Blender's CPU threads (None: its default, 2); Cycles' pixels do not depend on it, so it is
    no part of the config record."""
    poses, cams = training_poses(cfg.poses)
    cam_file = os.path.abspath(os.path.join(bike_dir, "views", "whole", "cameras.json"))
    if not os.path.isfile(cam_file):
        raise UserError(f"{bike_dir} has no views/whole/cameras.json (render_views.py --parts whole)")
    os.makedirs(out_dir, exist_ok=True)
    jobs = [{"pose": [float(v) for v in p], "camera": f"{cam_file}:camera{int(c):04d}",
             "out": os.path.abspath(os.path.join(out_dir, f"posed_{k:03d}.png"))} for k, (p, c) in enumerate(zip(poses, cams))]
    settings = {"samples": cfg.samples, "denoise": cfg.denoise}

    meta = os.path.join(out_dir, "poses.json")
    old = read_json_or_none(meta)

    def key(j):  # the folder may have moved: compared by file and camera name
        return os.path.basename(j["out"]), tuple(j["pose"]), j["camera"].rpartition(":")[2]

    known = {}
    if isinstance(old, dict):
        if old.get("settings") == settings:
            known = {os.path.basename(j["out"]): j for j in old.get("jobs", [])}
        else:  # renders of other settings: start again
            for j in old.get("jobs", []):
                f = os.path.join(out_dir, os.path.basename(j["out"]))
                if os.path.isfile(f):
                    os.remove(f)
        # a render is reused only when poses.json says it was made for this pose and camera
        for j in jobs:
            o = known.get(os.path.basename(j["out"]))
            if os.path.isfile(j["out"]) and (o is None or key(o) != key(j)):
                os.remove(j["out"])
    # the record describes every render in the folder: these jobs, and those of an earlier, larger
    # --poses (kept for a later run that asks for them again)
    names = {os.path.basename(j["out"]) for j in jobs}
    more = [dict(o, out=os.path.abspath(os.path.join(out_dir, n))) for n, o in sorted(known.items())
            if n not in names and os.path.isfile(os.path.join(out_dir, n))]
    write_json(meta, {"settings": settings, "jobs": jobs + more})
    todo = [j for j in jobs if not os.path.isfile(j["out"])]
    if todo:
        job_file = os.path.join(out_dir, "jobs.json")
        write_json(job_file, todo)
        cmd = [sys.executable, RENDER_SCRIPT, "--bike", bike_dir, "--batch", job_file, "--samples", str(cfg.samples),
               "--denoise", cfg.denoise] + (["--threads", str(threads)] if threads else [])
        log(f"bike-posed-train: rendering {len(todo)} posed views ({cfg.samples} spp)")
        env = dict(os.environ, PYTHONPATH=str(paths.ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
        if r.returncode != 0:
            raise UserError(f"Blender rendering of the posed bike failed: {r.stdout.strip().splitlines()[-3:]}")
        os.remove(job_file)  # Blender's input only (poses.json is the record): no leftover for a rerun to differ by
    return jobs


def _load_posed(jobs, margin):
    """The posed renders as premultiplied RGBA (V, 4, H, W), their cameras and crop boxes."""

    imgs, cams = [], []
    for j in jobs:
        im = torch.from_numpy(np.asarray(Image.open(j["out"]).convert("RGBA")).astype(np.float32) / 255)
        imgs.append(torch.cat([im[..., :3] * im[..., 3:], im[..., 3:]], -1).permute(2, 0, 1))
        path, _, name = j["camera"].rpartition(":")
        K, R, T = ring.camera_entry(path, name)
        cams.append(from_numpy(K, R, T))
    img = torch.stack(imgs)
    return img, cams, [crop_box(img[i, 3], margin) for i in range(len(cams))]


def fine_tune(model, rest_views_dir, jobs, cfg: PosedTrainConfig):
    """model (BikeModel, parts trained at rest) -> ({part: Gaussians}, metrics)."""
    if cfg.sh_degree not in (0, 1, 2):
        raise UserError(f"bike-posed-train: sh_degree must be 0, 1 or 2, got {cfg.sh_degree}")
    if model.sh_degree not in (0, cfg.sh_degree):
        raise UserError(f"bike-posed-train starts from SH degree 0 parts (the training default) or continues "
                        f"parts of its own --sh-degree {cfg.sh_degree}, got SH degree {model.sh_degree}")
    t0 = time.time()
    gen = torch.Generator().manual_seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    rest = Targets(load_views(rest_views_dir), cfg.crop_margin_px).at(1.0)
    posed = _load_posed(jobs, cfg.crop_margin_px)
    rigs = [model._part_rigids(check_poses(torch.tensor(j["pose"], dtype=torch.float64)[None])) for j in jobs]
    c = model.canonical
    ext = float((c.means.max(0).values - c.means.min(0).values).norm())
    lrs = cfg.rates(ext)
    if cfg.sh_degree:
        lrs["shN"] = cfg.lr_shN
    # one parameter dict and one Adam per part (Adam is per element: the same steps as one optimiser
    # over the concatenation), so that densification can grow each part on its own
    parts_p, opts, dens = {}, {}, {}
    for name, (a, e) in zip(model.part_names, model.ranges):
        p = {k: torch.nn.Parameter(v[a:e].detach().clone().contiguous()) for k, v in
             {"means": c.means, "quats": c.quats, "log_scales": c.log_scales, "opacity_logits": c.opacity_logits,
              "sh0": c.sh[:, :1]}.items()}
        if cfg.sh_degree:  # starts view-independent, or where an earlier fine-tune of this degree left it
            p["shN"] = torch.nn.Parameter(c.sh[a:e, 1:].detach().clone().contiguous() if model.sh_degree else
                                          torch.zeros(e - a, (cfg.sh_degree + 1) ** 2 - 1, 3, dtype=c.sh.dtype))
        parts_p[name] = p
        opts[name] = torch.optim.Adam([{"params": [p[k]], "lr": lrs[k], "name": k} for k in p], lr=0.0, eps=1e-15)
        if cfg.densify:
            m = p["means"].detach()
            dens[name] = DensifyStrategy(_densify_config(cfg), float((m.max(0).values - m.min(0).values).norm()))
    aa = model.antialiased


    def world(rig):
        """The canonical parameters moved by one pose's per-part rigid transforms (differentiable):
        means, rotations and, with degree >= 1, the higher bands' SH coefficients (c'_l = D_l c_l per part)."""
        ms, qs, ss = [], [], []
        for name in model.part_names:
            p = parts_p[name]
            if rig is None:
                ms.append(p["means"])
                qs.append(p["quats"])
                if "shN" in p:
                    ss.append(p["shN"])
                continue
            R, t, L = (x[0].to(p["means"].dtype) for x in rig[name])
            ms.append(p["means"] @ R.T + t)
            qs.append(p["quats"] @ L.T)
            if "shN" in p:
                ss.append(torch.cat([torch.einsum("ij,njc->nic", D, p["shN"][:, BANDS[l][0] - 1:BANDS[l][1] - 1])
                                     for l, D in enumerate(sh_band_matrices(R, cfg.sh_degree), start=1)], 1))
        return torch.cat(ms), torch.cat(qs), (torch.cat(ss) if ss else None)

    def render(rig, cam, bg):
        m, q, sh1 = world(rig)
        sh0 = torch.cat([parts_p[n]["sh0"] for n in model.part_names])
        sh = sh0 if sh1 is None else torch.cat([sh0, sh1], 1)
        cat = lambda k, f: torch.cat([f(parts_p[n][k]) for n in model.part_names])  # noqa: E731
        return rasterize(m, q, cat("log_scales", torch.exp), cat("opacity_logits", torch.sigmoid), sh,
                         cam, background=bg, antialiased=aa, eps2d=cfg.eps2d)

    n_train = len(jobs) - HELD_OUT

    def held_out():
        """Box PSNR (RGB on black, union box + 8 px) and IoU on the held-out posed views, full frame."""
        ps, ious = [], []
        with torch.no_grad():
            img, cams, _ = posed
            for v in range(n_train, len(jobs)):
                o = render(rigs[v], cams[v], None)
                gt = img[v].permute(1, 2, 0).double().numpy()
                m, m_gt = o["alpha"].numpy() > 0.5, gt[..., 3] > 0.5
                ps.append(box_psnr(o["rgb"].clamp(0, 1).double().numpy(), gt[..., :3], m, m_gt, pad=8))
                ious.append(mask_iou(m, m_gt))
        return round(float(np.mean(ps)), 3), round(float(np.mean(ious)), 4)

    before = held_out()
    prog = Progress(cfg.progress)
    loss_v = float("nan")
    for it in range(1, cfg.iterations + 1):
        if float(torch.rand(1, generator=gen)) < cfg.rest_fraction:
            (img, cams, boxes), rig = rest, None
            v = int(torch.randint(len(cams), (1,), generator=gen))
        else:
            img, cams, boxes = posed
            v = int(torch.randint(n_train, (1,), generator=gen))
            rig = rigs[v]
        x0, y0, x1, y1 = boxes[v]
        out = render(rig, crop_camera(cams[v], boxes[v]), None)
        gt = img[v, :, y0:y1, x0:x1].permute(1, 2, 0)
        loss = rgba_loss(out, gt, torch.rand(3, generator=gen), cfg.lambda_dssim)  # a random background
        for o in opts.values():
            o.zero_grad(set_to_none=True)
        loss.backward()
        g2d = out["means2d"].grad
        if (bool(torch.isfinite(loss)) and all(finite_grads(p) for p in parts_p.values())
                and (g2d is None or bool(torch.isfinite(g2d).all()))):
            for o in opts.values():
                o.step()
                if cfg.lr_decay != 1.0:  # the next step's rates (lr_rate_factor)
                    f = lr_rate_factor(cfg, it)
                    for grp in o.param_groups:
                        grp["lr"] = lrs[grp["name"]] * f
            if dens and g2d is not None:
                a = 0
                for name in model.part_names:  # each part's slice of the composed render
                    e = a + len(parts_p[name]["means"])
                    dens[name].post_backward(it, parts_p[name], opts[name], g2d[a:e], out["radii"][a:e],
                                             cams[v].width, cams[v].height)
                    a = e
        with torch.no_grad():
            for p in parts_p.values():
                p["quats"] /= p["quats"].norm(dim=-1, keepdim=True).clamp_min(1e-12)
        loss_v = float(loss.detach())
        prog.line(f"bike posed train {it}/{cfg.iterations} loss {loss_v:.4f} {time.time() - t0:6.1f}s")
    prog.close()
    for name, d in dens.items():
        d.finish(parts_p[name], opts[name])
    wall = time.time() - t0
    after = held_out()
    parts = {}
    for name, p in parts_p.items():
        d = {k: v.detach() for k, v in p.items()}
        sh = d["sh0"] if "shN" not in d else torch.cat([d["sh0"], d["shN"]], 1)
        parts[name] = Gaussians(d["means"], d["quats"], d["log_scales"], d["opacity_logits"], sh)
    return parts, {"gaussians": {n: len(g.means) for n, g in parts.items()},
                   "densify": {n: d.stats for n, d in dens.items()},
                   "config": record_of(cfg), "poses": len(jobs), "held_out_poses": HELD_OUT,
                   "held_out_box_psnr_before": before[0], "held_out_iou_before": before[1],
                   "held_out_box_psnr_after": after[0], "held_out_iou_after": after[1],
                   "loss": round(loss_v, 5), "wall_s": round(wall, 1), "antialiased": aa, "eps2d": cfg.eps2d}


def lr_rate_factor(cfg: PosedTrainConfig, it):
    """The rates' factor after step `it` (for step it + 1): 1 until the tail, then lr_decay ** (the
    share of the tail done), reaching lr_decay at the last step.  Decaying over the whole fine-tune
    cost 0.19 dB, a low-rate tail after constant rates gained (docs/training.md, round 4)."""
    tail = cfg.lr_tail if 0 < cfg.lr_tail < cfg.iterations else cfg.iterations
    return cfg.lr_decay ** (max(0, it - (cfg.iterations - tail)) / tail)


def _densify_config(cfg: PosedTrainConfig):
    """The trainer's rules, run over the first half of the fine-tune (the second settles what was
    added); no visual-hull pruning (the posed views' silhouettes move with the pose) and no opacity
    reset (the parts are already trained)."""
    return DensifyConfig(start=100, stop=max(100, cfg.iterations // 2), every=100, reset_every=0,
                         max_gaussians=cfg.densify_max, hull_prune=False)


def done_with(bike_dir, cfg: PosedTrainConfig):
    """The bike's posed_train.json when its parts were fine-tuned with this config, else None."""
    p = os.path.join(bike_dir, "gaussians", "posed_train.json")
    m = read_json_or_none(p)
    if m is None:
        return None
    want = record_of(cfg)
    gdir = os.path.dirname(p)
    # a part retrained since (its file newer than posed_train.json) needs the fine-tune again
    newer = any(f.endswith(".ply") and not f.endswith("_rest.ply")
                and os.path.getmtime(os.path.join(gdir, f)) > os.path.getmtime(p) for f in os.listdir(gdir))
    if not isinstance(m, dict) or not isinstance(m.get("config"), dict):
        return None
    # fine-tunes recorded before --densify existed ran without it: still this config when it is off
    # and before --lr-decay with constant rates
    # and before --eps2d with rasterize's 0.3
    have = {"densify": False, "densify_max": PosedTrainConfig().densify_max, "lr_decay": 1.0, "lr_tail": 0,
            "eps2d": 0.3, **m["config"]}
    return m if have == want and not newer else None


def train_bike_posed(bike_dir, cfg: PosedTrainConfig = None, log=print, from_rest=False, render_threads=None):
    """Render the posed views, fine-tune, write the parts (rest-trained copies kept). Returns the metrics.
    from_rest: start from gaussians/<part>_rest.ply (and its .json) as they are, never copying onto
    them (the library's train tasks own those files; a killed run's <part>.ply is only overwritten).
    render_threads: the posed renders' Blender threads (render_posed_views)."""
    cfg = cfg or PosedTrainConfig()
    torch.set_num_threads(1)
    gdir = os.path.join(bike_dir, "gaussians")
    model = BikeModel.load(bike_dir, suffix="_rest" if from_rest else "")
    meta = os.path.join(gdir, "posed_train.json")
    # a part file no newer than posed_train.json is this stage's own output: start again from the
    # rest-trained copy kept beside it; a newer one (or one never fine-tuned) is the new start
    t_meta = os.path.getmtime(meta) if os.path.isfile(meta) else None
    start = {}
    for p in model.part_names:
        ply, rest = os.path.join(gdir, p + ".ply"), os.path.join(gdir, p + "_rest.ply")
        if not from_rest and (t_meta is None or not os.path.isfile(rest) or os.path.getmtime(ply) > t_meta):
            shutil.copyfile(ply, rest)
        start[p] = rest

    model = BikeModel({p: read_ply(f) for p, f in start.items()}, model_keypoints_doc(bike_dir), model.meta,
                      source=bike_dir, antialiased=model.antialiased, eps2d=model.eps2d)
    jobs = render_posed_views(bike_dir, os.path.join(bike_dir, "views", "posed"), cfg, log, render_threads)
    parts, metrics = fine_tune(model, os.path.join(bike_dir, "views", "whole"), jobs, cfg)
    for p, g in parts.items():
        write_ply(g, os.path.join(gdir, p + ".ply"))  # the same Gaussians in the same order (with --densify: the grown and pruned set)
    write_json(meta, metrics)  # written last: its time marks the part files as this stage's
    log(f"bike-posed-train: held-out poses box PSNR {metrics['held_out_box_psnr_before']:.2f} -> "
        f"{metrics['held_out_box_psnr_after']:.2f} dB, IoU {metrics['held_out_iou_before']:.4f} -> "
        f"{metrics['held_out_iou_after']:.4f}, {metrics['wall_s']:.0f} s")
    return metrics


def model_keypoints_doc(bike_dir):
    return bike_folder.read_json(os.path.join(bike_dir, "keypoints.json"), "keypoints.json")
