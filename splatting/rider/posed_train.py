"""Train an avatar's canonical Gaussians through its skinning, on renders of the rider in cycling poses.

The rest-pose avatar (avatar_build.py) learns from the T-posed rider only, so what a cycling pose
changes -- a thigh folded against the belly, a bent knee -- is never seen.  Here the posed rider
mesh (the same body.pose_vertices as the ground truth) is rendered by Blender from a few ring
cameras at each of several pedalling poses; then every step renders the canonical Gaussians
re-posed by linear blend skinning (RiderAvatar.pose_tensors: means by the blended bone
transform, rotations by its polar factor) and the loss flows back through the skinning into the
canonical means, rotations, scales, opacities and colours -- the way GaussianAvatar / 3DGS-Avatar
learn from posed people.  The rest-pose views stay in the mix (identity pose).  The skinning weights
stay the body model's; no densification (the rest-pose training placed the Gaussians).

    python -m splatting rider-posed-train --avatar AVATAR_DIR [--poses 4 --cameras 8 --iterations 600]

writes AVATAR_DIR/rider.ply (the previous one kept as rider_rest.ply) and posed_train.json.
Poses: pedal_pose at crank angles 45 + 360 k / P degrees, steering 0, no yaw -- never the
rider_gt check poses (random crank angles with steering and yaw, bench/rider.py).
"""
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np
import torch

from cyclist_formats import bike_folder
from cyclist_formats.atomic import atomic_path
from cyclist_formats.errors import UserError
from splatting import paths
from splatting.gaussians.container import write_ply
from splatting.progress import Progress
from splatting.raster.camera import ring_camera
from splatting.raster.api import rasterize
from splatting.rider.avatar import PLY_NAME, RiderAvatar
from splatting.rider.body import export_rider, pose_vertices
from splatting.rider.motion import pedal_pose
from splatting.rider.posed_config import PosedTrainConfig
from splatting.rider.roster import load_rider
from splatting.training.metrics import psnr
from splatting.training.targets import crop_camera, Targets
from splatting.training.trainer import _params_from, finite_grads, gaussians_of, rgba_loss
from splatting.training.views import load_views

RENDER_SCRIPT = paths.blender_script("render_rider.py")


def training_poses(n):
    return [(45.0 + 360.0 * k / n) % 360.0 for k in range(n)]


def render_posed_views(rider, out_dir, cfg: PosedTrainConfig, log=print):
    """Per pose k: out_dir/pose_k/ a SHERF views folder (cameras.json, rgba/) of the posed mesh,
    plus pose.json (local rotations, root).  Resumable (done views are skipped by render_rider)."""
    thetas = training_poses(cfg.poses)
    rot, root, _ = pedal_pose(rider.joints, torch.tensor(np.radians(thetas)), torch.zeros(len(thetas), dtype=torch.float64))
    root = root + torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)
    verts = pose_vertices(rider, rot, root)
    jobs, folders = [], []
    for k in range(cfg.poses):
        d = os.path.join(out_dir, f"pose_{k}")
        os.makedirs(d, exist_ok=True)
        v = verts[k]
        centre = [0.0, float((v[:, 1].min() + v[:, 1].max()) / 2), 0.0]
        step = 36 // cfg.cameras
        idx = [(c * step + k * max(1, step // max(1, cfg.poses))) % 36 for c in range(cfg.cameras)]
        cams = {f"camera{i:04d}": ring_camera(10.0 * i, centre) for i in idx}
        meta = {n: {"K": c.K.tolist(), "R": c.R.tolist(), "T": c.T.tolist()} for n, c in cams.items()}
        meta["orbit_centre"] = centre
        with open(os.path.join(d, "cameras.json"), "w") as f:
            json.dump(meta, f)
        with open(os.path.join(d, "pose.json"), "w") as f:
            json.dump({"theta_p_deg": thetas[k], "local_rotmats": rot[k].tolist(), "root": root[k].tolist()}, f)
        mesh = os.path.join(d, "posed.ply")
        if not os.path.isfile(mesh):
            export_rider(rider, mesh, vertices=v)
        for n in cams:
            jobs.append({"mesh": mesh, "camera": f"{os.path.join(d, 'cameras.json')}:{n}",
                         "out": os.path.join(d, "rgba", n, "0000.png")})
        folders.append(d)
    todo = [j for j in jobs if not os.path.isfile(j["out"])]
    if todo:
        job_file = os.path.join(out_dir, "jobs.json")
        with open(job_file, "w") as f:
            json.dump(todo, f)
        cmd = [sys.executable, RENDER_SCRIPT, "--batch", job_file, "--threads", "1"]
        if cfg.samples:
            cmd += ["--samples", str(cfg.samples)]
        log(f"rider-posed-train: rendering {len(todo)} posed views")
        r = subprocess.run(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if r.returncode != 0:
            raise UserError(f"Blender rendering of the posed rider failed: {r.stdout.strip().splitlines()[-3:]}")
    return folders


def _posed_set(folder, scale, margin):
    with open(os.path.join(folder, "pose.json")) as f:
        p = json.load(f)
    t = Targets(load_views(folder), margin)
    return {"targets": t.at(scale), "rot": torch.tensor(p["local_rotmats"], dtype=torch.float32),
            "root": torch.tensor(p["root"], dtype=torch.float32), "name": os.path.basename(folder)}


def fine_tune(avatar, rest_views_dir, posed_folders, cfg: PosedTrainConfig):
    """avatar (RiderAvatar, trained at rest) -> (Gaussians fine-tuned through the skinning, metrics)."""
    t0 = time.time()
    gen = torch.Generator().manual_seed(cfg.seed)
    torch.manual_seed(cfg.seed)
    rest = {"targets": Targets(load_views(rest_views_dir), 8).at(cfg.scale), "rot": None, "root": None, "name": "rest"}
    sets = [_posed_set(f, cfg.scale, 8) for f in posed_folders]
    params = _params_from(avatar.gaussians)
    ext = float((params["means"].detach().max(0).values - params["means"].detach().min(0).values).norm())
    lrs = dict(cfg.rates(ext), shN=cfg.lr_sh0 / 20)
    opt = torch.optim.Adam([{"params": [params[k]], "lr": lrs[k]} for k in params], lr=0.0, eps=1e-15)

    def posed(s):
        g = gaussians_of(params)
        if s["rot"] is None:
            return g.means, g.quats, g.sh
        avatar.gaussians = g  # pose_tensors reads the canonical Gaussians from the avatar
        out = avatar.pose_tensors(s["rot"][None], s["root"][None])
        return out["means"][0], out["quats"][0], out["sh"][0]

    def render(s, v, bg):
        img, cams, boxes = s["targets"]
        x0, y0, x1, y1 = boxes[v]
        cam = crop_camera(cams[v], boxes[v])
        m, q, sh = posed(s)
        out = rasterize(m, q, torch.exp(params["log_scales"]), torch.sigmoid(params["opacity_logits"]), sh, cam,
                        background=bg, eps2d=avatar.eps2d)  # the filter it was trained with
        gt = img[v, :, y0:y1, x0:x1].permute(1, 2, 0)
        return out, gt

    def held_out_psnr():
        """Mean PSNR (object box, over white) on the posed sets' last camera, never trained on."""
        with torch.no_grad():
            vals = []
            for s in sets:
                v = len(s["targets"][1]) - 1
                out, gt = render(s, v, torch.ones(3))
                vals.append(psnr(out["rgb"].clamp(0, 1), gt[..., :3] + (1 - gt[..., 3:])))
            return float(np.mean(vals))

    before = held_out_psnr()
    prog = Progress(cfg.progress)
    loss_v = float("nan")
    for it in range(1, cfg.iterations + 1):
        use_rest = float(torch.rand(1, generator=gen)) < cfg.rest_fraction
        s = rest if use_rest else sets[int(torch.randint(len(sets), (1,), generator=gen))]
        n_views = len(s["targets"][1]) - (0 if use_rest else 1)  # the last posed camera is held out
        v = int(torch.randint(n_views, (1,), generator=gen))
        bg = torch.rand(3, generator=gen)
        out, gt = render(s, v, None)
        loss = rgba_loss(out, gt, bg, cfg.lambda_dssim)
        opt.zero_grad(set_to_none=True)
        loss.backward()
        if finite_grads(params):
            opt.step()
        loss_v = float(loss.detach())
        prog.line(f"posed train {it}/{cfg.iterations} loss {loss_v:.4f} {time.time() - t0:6.1f}s")
    prog.close()
    after = held_out_psnr()
    g = gaussians_of({k: v.detach() for k, v in params.items()})
    avatar.gaussians = g
    return g, {"iterations": cfg.iterations, "poses": cfg.poses, "cameras_per_pose": cfg.cameras,
               "theta_p_deg": training_poses(cfg.poses), "scale": cfg.scale, "loss": round(loss_v, 5),
               "heldout_camera_psnr_before": round(before, 3), "heldout_camera_psnr_after": round(after, 3),
               "wall_s": round(time.time() - t0, 1)}


def train_avatar_posed(avatar_dir, cfg: PosedTrainConfig = None, log=print):
    cfg = cfg or PosedTrainConfig()
    torch.set_num_threads(1)
    av = RiderAvatar.load(avatar_dir)
    rider = load_rider(av.rider_id)
    folders = render_posed_views(rider, os.path.join(avatar_dir, "posed_views"), cfg, log)
    g, metrics = fine_tune(av, os.path.join(avatar_dir, "views"), folders, cfg)
    ply = os.path.join(avatar_dir, PLY_NAME)
    rest_copy = os.path.join(avatar_dir, "rider_rest.ply")
    if not os.path.isfile(rest_copy):
        shutil.copyfile(ply, rest_copy)
    write_ply(g, ply)  # same Gaussians, same order: skinning.npz stays valid
    stale = bike_folder.relight_path(ply)  # fitted to the old Gaussians: refit (relight-fit) after this
    if os.path.isfile(stale):
        os.remove(stale)
    with atomic_path(os.path.join(avatar_dir, "posed_train.json")) as tmp:
        with open(tmp, "w") as f:
            json.dump(metrics, f, indent=1)
    log(f"rider-posed-train: {metrics}")
    return metrics
