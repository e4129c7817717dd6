"""Street scenes (issue 12): driving cameras with non-square K, several cyclists in one
rasterization (near hides far: masks, visible fraction, keypoint visibility), amodal masks,
truncation at the border, a 3DGS wall that hides or not, photo backgrounds, resume."""
import json
import os

import numpy as np
import pytest

from helpers import RIDER, fixed_scene, street_config  # noqa: F401
from splatting.dataset.config_models import Camera

KITTI_K = (721.5377, 609.5593, 172.854)


def sample(cfg, assets=None):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    cfg = resolve_assets(validate(cfg))
    return make_sample(cfg, 0, assets or Assets(cfg)), cfg


def by_instance(anns, key):
    from splatting.dataset.labels import CATEGORY_IDS
    return {a["instance"]: a for a in anns if a["category_id"] == CATEGORY_IDS[key]}


def decode(seg):
    from pycocotools import mask as mu
    return mu.decode(seg).astype(bool)


# ---------------------------------------------------------------- cameras

def test_kitti_projection_matches_a_hand_computation():
    import torch
    from splatting.cyclist.render import project_points
    from splatting.dataset import camera_presets
    spec = camera_presets.resolve(Camera(preset="kitti", pitch_deg=0.0, roll_deg=0.0, scale=1.0))
    assert (spec["width"], spec["height"]) == (1242, 375)
    f, cx, cy = KITTI_K
    X = np.array([[-2.0, 0.5, 10.0]])  # 2 m to the camera's right (world -X), 1.15 m below it, 10 m ahead
    u, v = f * 2.0 / 10.0 + cx, f * (1.65 - 0.5) / 10.0 + cy  # by hand: 753.867, 255.836
    uv, z = camera_presets.project(X, spec)
    assert np.allclose(uv[0], [u, v], atol=1e-6) and z[0] == pytest.approx(10.0)
    cam = camera_presets.street_camera(spec)
    uv2, _ = project_points(X, cam)
    assert np.allclose(uv2[0], [u, v], atol=1e-3)
    # the rasterizer puts a small Gaussian's mass there too (pixel centres at +0.5)
    from splatting.dataset.backgrounds import contact_shadows  # noqa: F401  (module imports cleanly)
    from splatting.cyclist.scene_render import render_scene
    from splatting.gaussians.container import Gaussians
    g = Gaussians(means=torch.tensor(X, dtype=torch.float32), quats=torch.tensor([[1.0, 0, 0, 0]]),
                  log_scales=torch.full((1, 3), np.log(0.02)), opacity_logits=torch.tensor([3.0]),
                  sh=torch.ones(1, 1, 3))
    L = render_scene(g, torch.ones(1, dtype=torch.long), 2, cam)
    a = L["alpha"]
    assert a.shape == (375, 1242)
    ys, xs = np.mgrid[0:375, 0:1242] + 0.5
    assert (a * xs).sum() / a.sum() == pytest.approx(u, abs=0.05)
    assert (a * ys).sum() / a.sum() == pytest.approx(v, abs=0.05)


def test_presets_pitch_and_custom_camera():
    from splatting.dataset import camera_presets
    base = {"pitch_deg": 0.0, "roll_deg": 0.0, "scale": 1.0}
    d = camera_presets.resolve(Camera(**base, preset="dashcam"))
    assert d["fx"] == pytest.approx(960.0) and (d["cx"], d["cy"]) == (960.0, 540.0)  # 90 deg HFOV
    n = camera_presets.resolve(Camera(**base, preset="nuscenes"))
    w = camera_presets.resolve(Camera(**base, preset="waymo"))
    assert (n["width"], n["height"], w["width"], w["height"]) == (1600, 900, 1920, 1280)
    # pitched down by atan(h / d): the road point d ahead lands on the principal point
    p = camera_presets.resolve(Camera(**dict(base, preset="kitti", pitch_deg=float(np.degrees(np.arctan2(1.65, 20.0))))))
    uv, _ = camera_presets.project([[0.0, 0.0, 20.0]], p)
    assert np.allclose(uv[0], [p["cx"], p["cy"]], atol=1e-6)
    c = camera_presets.resolve(Camera(**dict(base, preset="custom", width=640, height=480, fx=500.0, cx=300.0, cy=200.0,
                                             height_m=1.2, scale=0.5)))
    assert (c["width"], c["height"], c["fx"], c["fy"], c["cx"], c["cy"]) == (320, 240, 250.0, 250.0, 150.0, 100.0)


# ---------------------------------------------------------------- occlusion and masks

@pytest.fixture(scope="module")
def assets_for(bikes):
    cache = {}

    def get(cfg):
        from splatting.dataset.config import resolve_assets, validate
        from splatting.dataset.generate import Assets
        key = "one"  # every test here uses the same bike, rider and keypoint kind: load them once
        if key not in cache:
            cache[key] = Assets(resolve_assets(validate(cfg)))
        cache[key].cfg = resolve_assets(validate(cfg))
        return cache[key]
    return get


def test_near_cyclist_hides_far_one(bikes, assets_for, monkeypatch):
    # side-on (riding along camera +x), the far one straight behind the near one
    fixed_scene(monkeypatch, [(RIDER, 180.0, 0.3, 7.0), (RIDER, 180.0, 0.0, 11.0)])
    cfg = street_config(bikes)
    (rgb, image, anns, extras), _ = sample(cfg, assets_for(cfg))
    cyc = by_instance(anns, "cyclist")
    near, far = cyc[1], cyc[2]
    assert near["visibility"] > 0.97 and near["occlusion"] == 0
    assert far["visibility"] < 0.75 and far["occlusion"] >= 1
    vn, vf = decode(near["segmentation"]), decode(far["segmentation"])
    af = decode(far["segmentation_amodal"])
    assert not (vn & vf).any()
    assert (af | vf).sum() == af.sum()  # amodal contains visible
    missing = af & ~vf
    assert missing.sum() > 0.25 * af.sum() and (missing & vn).sum() > 0.9 * missing.sum()  # hidden by the near one
    assert far["area_amodal"] > far["area"] / far["visibility"] - 1
    # a far keypoint on the near cyclist's pixels is occluded; near ones there are visible (mostly)
    for key in ("rider", "bicycle"):
        kf = np.array(by_instance(anns, key)[2]["keypoints"]).reshape(-1, 3)
        on_near = [v for x, y, v in kf if v > 0 and vn[int(y), int(x)]]
        assert on_near and all(v == 1 for v in on_near), key
    # the same scene listed far-first gives the same pixels (depth, not order, decides)
    fixed_scene(monkeypatch, [(RIDER, 180.0, 0.0, 11.0), (RIDER, 180.0, 0.3, 7.0)])
    (rgb2, _, anns2, _), _ = sample(cfg, assets_for(cfg))
    cyc2 = by_instance(anns2, "cyclist")
    assert (decode(cyc2[2]["segmentation"]) == vn).all() and (decode(cyc2[1]["segmentation"]) == vf).all()
    assert np.abs(rgb.astype(int) - rgb2).max() <= 1


def test_truncation_at_the_border(bikes, assets_for, monkeypatch):
    from splatting.dataset import camera_presets
    cfg = street_config(bikes)
    spec = camera_presets.resolve(Camera(**dict(cfg["camera"], pitch_deg=0.0, roll_deg=0.0)))  # cfg: the raw YAML mapping
    z = 8.0
    x = -(0.0 - spec["cx"]) * z / spec["fx"]  # crank axle on the left image border
    fixed_scene(monkeypatch, [(RIDER, 180.0, x, z)])
    (_, image, anns, extras), _ = sample(cfg, assets_for(cfg))
    c = by_instance(anns, "cyclist")[1]
    assert 0.2 < c["truncation"] < 0.8
    assert c["bbox"][0] == 0.0  # cut by the border
    kp = np.array(by_instance(anns, "bicycle")[1]["keypoints"]).reshape(-1, 3)
    assert (kp[:, 2] == 0).any() and (kp[:, 2] > 0).any()
    assert extras["kitti"][0]["truncated"] == pytest.approx(c["truncation"], abs=0.01)


def write_wall(path, z, half=4.0, step=0.1):
    """A wall of opaque grey Gaussians in the plane Z = z (INRIA layout .ply)."""
    import torch
    from splatting.gaussians.container import Gaussians, write_ply
    from splatting.gaussians.sh import rgb_to_sh0
    xs = np.arange(-half, half + 1e-9, step)
    ys = np.arange(0.0, 3.0 + 1e-9, step)
    X, Y = np.meshgrid(xs, ys)
    pts = np.column_stack([X.ravel(), Y.ravel(), np.full(X.size, z)])
    n = len(pts)
    g = Gaussians(means=torch.tensor(pts, dtype=torch.float32), quats=torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                  log_scales=torch.log(torch.tensor([[step, step, 0.01]])).repeat(n, 1),
                  opacity_logits=torch.full((n,), 4.0), sh=rgb_to_sh0(torch.full((n, 3), 0.5))[:, None, :])
    write_ply(g, path)
    return path


@pytest.mark.parametrize("wall_z, hidden", [(5.0, True), (16.0, False)])
def test_3dgs_wall_hides_the_cyclist_only_when_in_front(bikes, assets_for, monkeypatch, tmp_path, wall_z, hidden):
    ply = write_wall(str(tmp_path / "wall.ply"), wall_z)
    fixed_scene(monkeypatch, [(RIDER, 180.0, 0.0, 10.0)], kind="scene")
    cfg = street_config(bikes, backgrounds={"kinds": ["scene"], "scene_ply": ply,
                                            "scene_transform": {"rotation_deg": [0, 0, 0], "translation_m": [0, 0, 0],
                                                                "scale": 1.0}})
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    (rgb, image, anns, extras) = make_sample(resolve_assets(validate(cfg)), 0, Assets(resolve_assets(validate(cfg))))
    cyc = by_instance(anns, "cyclist")
    if hidden:
        assert 1 not in cyc  # nothing visible: no COCO annotation
        assert extras["kitti"] == []
    else:
        assert cyc[1]["visibility"] > 0.97
        kp = np.array(by_instance(anns, "rider")[1]["keypoints"]).reshape(-1, 3)
        assert (kp[:, 2] == 2).sum() >= 5


def test_photo_background_is_scaled_cropped_and_deterministic(tmp_path):
    from PIL import Image
    from splatting.dataset.backgrounds import list_images, photo
    d = tmp_path / "photos"
    d.mkdir()
    grad = np.tile(np.linspace(0, 255, 300).astype(np.uint8)[None, :, None], (100, 1, 3))
    Image.fromarray(grad).save(d / "a.png")
    Image.fromarray(np.full((50, 40, 3), 77, np.uint8)).save(d / "b.jpg")
    files = list_images(str(d))
    assert [os.path.basename(f) for f in files] == ["a.png", "b.jpg"]
    for seed in range(6):
        img, rec = photo(files, seed, 160, 90)
        again, rec2 = photo(files, seed, 160, 90)
        assert img.shape == (90, 160, 3) and (img == again).all() and rec == rec2
        if rec["file"] == "b.jpg":
            assert img.dtype == np.uint8 and np.abs(img.astype(int) - 77).max() < 3
        else:  # a 300x100 photo covers 160x90 at scale 0.9: a crop 177.8 px wide of the gradient
            assert rec["crop_xywh_source"][2] == pytest.approx(100 * 160 / 90, abs=0.1)
            assert (np.diff(img[45, :, 0].astype(int)) >= 0).all()


def test_street_dataset_resumes_byte_identical(bikes, tmp_path):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    # LOD and new looks on: far instances (~40 px at 15 m here) thinned, every instance recoloured
    cfg = validate(street_config(bikes, count=3, labels={"formats": ["coco", "kitti"]}, depth_maps=True,
                                 lod={"enabled": True, "levels": [{"below_px": 60, "keep": 0.5}]},
                                 appearance={"enabled": True}))
    a, b = str(tmp_path / "a"), str(tmp_path / "b")
    generate(cfg, a, log=lambda m: None, progress=False)
    generate(cfg, b, log=lambda m: None, progress=False)
    os.remove(os.path.join(b, "shards", "000001.json"))
    os.remove(os.path.join(b, "kitti", "training", "label_2", "000002.txt"))
    os.remove(os.path.join(b, "annotations.json"))
    r = generate(cfg, b, log=lambda m: None, progress=False)
    assert r["generated"] == 2
    for rel in ("annotations.json", "images/000001.png", "kitti/training/label_2/000002.txt",
                "kitti/training/calib/000000.txt", "kitti/ImageSets/train.txt"):
        with open(os.path.join(a, rel), "rb") as fa, open(os.path.join(b, rel), "rb") as fb:
            assert fa.read() == fb.read(), rel
    with open(os.path.join(a, "annotations.json")) as f:
        doc = json.load(f)
    im = doc["images"][0]
    assert (im["width"], im["height"]) == (621, 188)  # kitti at scale 0.5, non-square
    assert 2 <= sum(i["kind"] == "cyclist" for i in im["instances"]) <= 3
    assert all("appearance" in i and "lod_keep" in i for i in im["instances"])
    assert any(i["lod_keep"] < 1 for m in doc["images"] for i in m["instances"])  # a thinned one resumed too
    # depth map: non-square, millimetres of camera z; a cyclist's pixels lie at its distance
    from PIL import Image
    depth = np.asarray(Image.open(os.path.join(a, "depth", "000000.png")))
    assert depth.shape == (188, 621) and depth.dtype == np.uint16
    for ann in (x for x in doc["annotations"] if x["image_id"] == 1 and x["category_id"] == 3):
        m = decode(ann["segmentation"])
        z = np.median(depth[m & (depth > 0)]) / 1000.0
        assert abs(z - ann["pose_3d"]["location_cam_m"][2]) < 1.0


def test_reduced_resolution_amodal_masks_match_the_full_ones(bikes, assets_for, monkeypatch):
    """amodal_max_px renders big parts' amodal masks smaller and resamples them: the masks must
    agree with the full-resolution ones except along their edges."""
    fixed_scene(monkeypatch, [(RIDER, 150.0, 0.0, 4.0)])
    cfg = street_config(bikes)
    (_, _, full, _), _ = sample(cfg, assets_for(cfg))
    (_, _, small, _), _ = sample(dict(cfg, amodal_max_px=40), assets_for(cfg))
    assert len(full) == len(small) > 0, (len(full), len(small))  # zip() would hide a missing annotation
    for a, b in zip(full, small):
        assert (a["category_id"], a["instance"]) == (b["category_id"], b["instance"])
        ma, mb = decode(a["segmentation_amodal"]), decode(b["segmentation_amodal"])
        assert (decode(a["segmentation"]) == decode(b["segmentation"])).all()  # visible: untouched
        assert a["bbox_amodal"][3] > 50  # really larger than 40 px
        assert (ma ^ mb).sum() < 0.15 * ma.sum()  # thin tubes at 1/3 of the resolution: ~10 %
