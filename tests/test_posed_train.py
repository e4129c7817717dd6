"""Training an avatar through its skinning: the loss on posed views reaches the canonical Gaussians."""
import json
import math
import os

import numpy as np
import torch

from splatting.gaussians.container import Gaussians
from splatting.raster.camera import ring_camera
from splatting.raster.sparse import render_gaussians
from splatting.rider.avatar import RiderAvatar
from splatting.rider.posed_train import PosedTrainConfig, fine_tune

SIZE = 64
FOCAL = 2084.97 * SIZE / 512 * 0.5  # the whole 1.9 m body in 64 px


def _avatar(colour, seed=0):
    from splatting.rider.roster import load_rider

    rider = load_rider("f_teen_slim_150")
    rng = np.random.default_rng(seed)
    V = rider.vertices.double().numpy()
    pts = V[rng.choice(len(V), 400, replace=False)]
    n = len(pts)
    sh = torch.tensor(colour, dtype=torch.float32).sub(0.5).div(0.28209479177387814).expand(n, 1, 3).contiguous()
    g = Gaussians(torch.from_numpy(pts).float(), torch.tensor([[1.0, 0, 0, 0]]).expand(n, 4).contiguous(),
                  torch.full((n, 3), math.log(0.04)), torch.full((n,), 3.0), sh)
    return RiderAvatar.from_rider(g, rider), rider


def _write_views(folder, g, cams, pose=None):
    from PIL import Image

    os.makedirs(folder, exist_ok=True)
    meta = {}
    for cam in cams:
        out = render_gaussians(g, cam)
        a = out["alpha"].clamp(0, 1)
        rgb = torch.where(a[..., None] > 1e-6, out["rgb"] / a[..., None].clamp_min(1e-6), torch.zeros_like(out["rgb"]))
        rgba = torch.cat([rgb.clamp(0, 1), a[..., None]], -1)
        d = os.path.join(folder, "rgba", cam.name)
        os.makedirs(d, exist_ok=True)
        Image.fromarray((rgba.numpy() * 255).round().astype(np.uint8), "RGBA").save(os.path.join(d, "0000.png"))
        meta[cam.name] = {"K": cam.K.tolist(), "R": cam.R.tolist(), "T": cam.T.tolist()}
    with open(os.path.join(folder, "cameras.json"), "w") as f:
        json.dump(meta, f)
    if pose is not None:
        with open(os.path.join(folder, "pose.json"), "w") as f:
            json.dump({"theta_p_deg": 0.0, "local_rotmats": pose[0].tolist(), "root": pose[1].tolist()}, f)


def test_posed_views_train_the_canonical_gaussians(tmp_path):
    torch.set_num_threads(1)
    from splatting.rider.motion import pedal_pose

    target, rider = _avatar((0.8, 0.2, 0.1))   # what the "renders" show: a red rider
    start, _ = _avatar((0.3, 0.3, 0.3))        # the avatar to train: grey
    rot, root, _ = pedal_pose(rider.joints, torch.tensor([math.radians(100.0)]), torch.tensor([0.0]))
    rot, root = rot.float(), (root + torch.tensor([0.0, 1.0, 0.0])).float()
    posed = target.pose(rot, root)
    centre = (0.0, float(posed.means[:, 1].mean()), 0.0)
    cams = [ring_camera(a, centre, size=SIZE, focal=FOCAL, name=f"camera{i:04d}") for i, a in enumerate((0, 90, 180, 270))]
    _write_views(tmp_path / "pose_0", posed, cams, (rot[0], root[0]))
    rest_cams = [ring_camera(a, (0.0, float(target.gaussians.means[:, 1].mean()), 0.0), size=SIZE, focal=FOCAL,
                             name=f"camera{i:04d}") for i, a in enumerate((45, 225))]
    _write_views(tmp_path / "rest", target.gaussians, rest_cams)
    g, m = fine_tune(start, str(tmp_path / "rest"), [str(tmp_path / "pose_0")],
                     PosedTrainConfig(iterations=60, rest_fraction=0.0, lr_sh0=0.05, progress=False))
    # the held-out camera (270 deg, never a training view) of the posed set improves a lot
    assert m["heldout_camera_psnr_after"] > m["heldout_camera_psnr_before"] + 3.0
    # and it did so by changing the canonical Gaussians' colour towards red: the loss on posed
    # renders reached the rest-pose parameters through the re-posing
    col = (g.sh[:, 0] * 0.28209479177387814 + 0.5).mean(0)
    assert float(col[0]) > float(col[2]) + 0.2
