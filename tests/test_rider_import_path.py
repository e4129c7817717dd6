"""An imported rider through the whole path, at tiny settings: `rider import` of a rigged human made from the
roster body (tests/rigged_humans.py: Mixamo names, a colour-ramp texture), then as the built-in riders take
it: `rider-avatar` (36 views drawn from the rider file's own texture, Gaussians trained, skinning),
`relight-fit` on the avatar, `cyclist` on a bike (the IK seats it), and `dataset` samples (COCO-17 person
keypoints from its mesh, appearance variety, relit under a sun).  Every step is the command a user runs."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest
import torch

from helpers import CITY_KEYPOINTS, make_bike, random_relight_files, small_config, write_yaml

bpy = pytest.importorskip("bpy")
from rigged_humans import ROOT, SOURCE_RIDER, build_rigged_human, expected_colors, export, write_texture  # noqa: E402

RIDER_ID = "imported_path"
PAIRS = ("left_wrist->handle_left", "right_wrist->handle_right", "pelvis->seat", "left_ankle->pedal_left",
         "right_ankle->pedal_right")


def run(env, *args):
    r = subprocess.run([sys.executable, "-m", "splatting", *map(str, args)], capture_output=True, text=True, cwd=ROOT,
                       env=env)
    assert r.returncode == 0, (args[:2], r.stderr[-2500:])
    return r


@pytest.fixture(scope="module")
def path(tmp_path_factory):
    """The imported rider's avatar (trained, relight-fitted) and a bike with relight channels."""
    from addon.core.scene import reset_scene
    from splatting.rider.roster import load_rider
    torch.set_num_threads(1)
    d = tmp_path_factory.mktemp("path")
    reset_scene()
    build_rigged_human(load_rider(SOURCE_RIDER), "mixamo", write_texture(d / "ramp.png"))
    export(d / "person.glb")
    reset_scene()
    env = dict(os.environ, PYTHONPATH=ROOT, OMP_WAIT_POLICY="PASSIVE", OMP_NUM_THREADS="1",
               ARTICCYCLISTS_DATA=str(d / "data"))
    run(env, "rider", "import", "--model", d / "person.glb", "--id", RIDER_ID)
    riders = d / "riders"
    av = riders / RIDER_ID
    run(env, "rider-avatar", "--id", RIDER_ID, "--out", av, "--samples", "1", "--size", "128", "--iterations", "60",
        "--max-gaussians", "4000")
    run(env, "relight-fit", "--views", av / "views", "--ply", av / "rider.ply", "--iterations", "30", "--max-size", "96",
        "--quiet")
    bike = make_bike(str(d / "bikes"), "city_rl", n=300, sh_degree=1, kp=CITY_KEYPOINTS)
    random_relight_files([os.path.join(bike, "gaussians", p + ".ply") for p in ("frame", "steering", "crank")])
    return {"root": d, "env": env, "avatar": av, "riders": riders, "bikes": d / "bikes",
            "rider_file": d / "data" / "imported_riders" / RIDER_ID / "rider.npz"}


def test_avatar_is_trained_from_the_riders_own_texture(path):
    """The training views are the textured rider (the ramp's green channel climbs with height in the
    rendered pixels), the avatar is trained on them and skinned with the imported rider's weights,
    and its relight albedo is the texture's colour where each Gaussian sits."""
    from PIL import Image
    from splatting.gaussians.container import read_ply
    from splatting.gaussians.sh import C0
    from splatting.relight.avatar import RelightableAvatar
    from splatting.rider.avatar import RiderAvatar
    av = path["avatar"]
    metrics = json.load(open(av / "rider.json"))
    assert metrics["psnr"] > 20 and 500 < metrics["gaussians"] <= 4000, metrics
    img = np.asarray(Image.open(av / "views" / "rgba" / "camera0000" / "0000.png")).astype(float)
    body = img[..., 3] > 250
    rows = np.nonzero(body)[0]
    top, bottom = rows < np.percentile(rows, 30), rows > np.percentile(rows, 70)
    g_top, g_bottom = img[body][top, 1].mean(), img[body][bottom, 1].mean()  # image rows grow downwards
    assert g_top > g_bottom + 60, (g_top, g_bottom)  # the ramp: green = height on the body
    avatar = RiderAvatar.load(str(av))
    a = np.load(path["rider_file"])
    assert np.abs(avatar.rest_joints.numpy() - a["joints"]).max() < 1e-6
    relit = RelightableAvatar.load(str(av))
    g = read_ply(str(av / "rider.ply"))
    V = a["vertices"]
    near = torch.cdist(g.means.double(), torch.as_tensor(V, dtype=torch.float64)).argmin(1).numpy()
    want = expected_colors(V)[near]  # the ramp texture's colour at each Gaussian, sRGB
    albedo = np.asarray(relit.albedo, np.float64)
    albedo = np.where(albedo <= 0.0031308, 12.92 * albedo, 1.055 * np.clip(albedo, 0, None) ** (1 / 2.4) - 0.055)
    seen = g.opacities.numpy() > 0.05  # after 60 steps most Gaussians are still faint
    assert seen.sum() > 1000
    for colour in (C0 * g.sh[:, 0].numpy() + 0.5, albedo):  # the trained colour and the fitted albedo
        r = np.corrcoef(colour[seen, 1], want[seen, 1])[0, 1]
        assert r > 0.9, r


def test_cyclist_rides_the_bike(path):
    out = path["root"] / "cyclist"
    run(path["env"], "cyclist", "--rider", RIDER_ID, "--bike", "city_rl", "--bikes-root", path["bikes"],
        "--riders-root", path["riders"], "--frames", "2", "--views=0,90", "--size", "64", "--synthetic", "never",
        "--out", out)
    for i in range(2):
        rec = json.load(open(out / f"frame_{i:05d}.json"))
        assert set(rec["ik"]["residual_m"]) == set(PAIRS)
        assert max(rec["ik"]["residual_m"].values()) < 0.03, rec["ik"]["residual_m"]  # steering and leaning too
        j, kp = rec["rider_joints"], rec["bike_keypoints"]
        for joint, target in (("left_wrist", "handle_left"), ("right_ankle", "pedal_right")):
            assert np.linalg.norm(np.subtract(j[joint], kp[target])) < 0.03, (joint, target)
    from PIL import Image
    mask = np.asarray(Image.open(out / "view_0" / "00001_mask.png"))
    assert (mask == 4).sum() > 50  # the rider is drawn


@pytest.mark.parametrize("lighting", ["baked", "relit"])
def test_dataset_samples_of_the_imported_rider(path, tmp_path, lighting):
    """COCO samples: the rider's COCO-17 points come from its own mesh, the appearance variety (which
    cannot recolour regions an imported rider does not have) changes its gain, and relit samples shade it
    from its relight channels."""
    cfg = small_config(str(path["bikes"]), bikes=["city_rl"], riders=[RIDER_ID], riders_root=str(path["riders"]),
                       synthetic_assets="never", count=2, image_size=96, appearance={"enabled": True},
                       lighting={"mode": lighting})
    cfg_path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    run(path["env"], "dataset", "--config", cfg_path, "--out", tmp_path / "o", "--quiet")
    ann = json.load(open(tmp_path / "o" / "annotations.json"))
    people = [a for a in ann["annotations"] if a["category_id"] == 2]
    assert len(ann["images"]) == 2 and len(people) == 2
    for p in people:
        kp = np.asarray(p["keypoints"]).reshape(17, 3)
        assert (kp[:, 2] > 0).sum() >= 8 and p["area"] > 50, kp
