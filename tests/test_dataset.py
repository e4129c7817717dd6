"""`python -m splatting dataset`: COCO output that pycocotools loads (its encoding self-evaluates to 1.0;
masks, boxes and keypoints checked geometrically beside it),
kill-and-resume gives identical bytes, config errors name the field."""
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from helpers import small_config, write_test_bike, write_yaml

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
def cli(*argv):
    return subprocess.run([sys.executable, "-m", "splatting", *argv], cwd=ROOT, capture_output=True, text=True,
                          env=dict(os.environ, OMP_NUM_THREADS="1"))


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    root = tmp_path_factory.mktemp("ds")
    write_test_bike(str(root))
    cfg = small_config(str(root))
    out = str(root / "full")
    generate(validate(cfg), out, log=lambda m: None, progress=False)
    return root, cfg, out


def test_coco_encoding_loads_and_scores_itself_one(built):
    """Proves the ENCODING (pycocotools loads the file, the categories, RLEs and keypoint sigmas, and
    matches each annotation to itself), not the masks: the ground truth is scored against itself.
    The geometry is checked beside it (test_masks_boxes_and_keypoints_are_consistent)."""
    from pycocotools.coco import COCO
    from pycocotools.cocoeval import COCOeval
    _, cfg, out = built
    gt = COCO(os.path.join(out, "annotations.json"))
    assert len(gt.getImgIds()) == cfg["count"]
    cats = {c["name"]: c for c in gt.loadCats(gt.getCatIds())}
    assert {"bicycle", "person", "cyclist", "motorcyclist", "motorcycle", "scooter"} == set(cats)
    assert len(cats["bicycle"]["keypoints"]) == 11 and len(cats["person"]["keypoints"]) == 17
    for img in gt.loadImgs(gt.getImgIds()):
        assert os.path.isfile(os.path.join(out, "images", img["file_name"]))
        names = {gt.loadCats(a["category_id"])[0]["name"] for a in gt.loadAnns(gt.getAnnIds(imgIds=img["id"]))}
        assert names == {"bicycle", "person", "cyclist"}
    dets = [dict(a, score=1.0) for a in gt.dataset["annotations"]]
    dt = gt.loadRes(dets)
    for iou in ("bbox", "segm"):
        ev = COCOeval(gt, dt, iou)
        ev.evaluate(); ev.accumulate(); ev.summarize()
        assert ev.stats[0] == pytest.approx(1.0), iou
    for name, n in (("bicycle", 11), ("person", 17)):
        ev = COCOeval(gt, dt, "keypoints")
        ev.params.catIds = [cats[name]["id"]]
        ev.params.kpt_oks_sigmas = np.array(cats[name]["sigmas"])  # the documented snippet
        assert len(ev.params.kpt_oks_sigmas) == n
        ev.evaluate(); ev.accumulate(); ev.summarize()
        assert ev.stats[0] == pytest.approx(1.0), name


def test_masks_boxes_and_keypoints_are_consistent(built):
    from PIL import Image
    from pycocotools import mask as mu
    from pycocotools.coco import COCO
    _, _, out = built
    gt = COCO(os.path.join(out, "annotations.json"))
    for img in gt.loadImgs(gt.getImgIds()):
        anns = {gt.loadCats(a["category_id"])[0]["name"]: a for a in gt.loadAnns(gt.getAnnIds(imgIds=img["id"]))}
        m = {k: mu.decode(a["segmentation"]).astype(bool) for k, a in anns.items()}
        assert not (m["bicycle"] & m["person"]).any()  # one id per pixel
        assert (m["cyclist"] == (m["bicycle"] | m["person"])).all()
        x, y, w, h = anns["cyclist"]["bbox"]
        ys, xs = np.nonzero(m["cyclist"])
        assert (x, y, x + w, y + h) == (xs.min(), ys.min(), xs.max() + 1, ys.max() + 1)
        # the object differs from the background where the mask is
        rgb = np.asarray(Image.open(os.path.join(out, "images", img["file_name"])))
        assert rgb.shape == (img["height"], img["width"], 3)
        kp = np.array(anns["person"]["keypoints"]).reshape(-1, 3)
        assert set(kp[:, 2].astype(int)) <= {0, 1, 2} and (kp[:, 2] == 2).sum() >= 5
        # a visible joint projects onto (or next to) the person's pixels
        assert share_on_mask(kp, m["person"]) > 0.8


def share_on_mask(kp, mask):
    """Share of the visible (v=2) keypoints (K, 3) within 2 px of the mask's pixels."""
    inside = kp[kp[:, 2] == 2]
    near = [mask[max(0, int(v) - 2):int(v) + 3, max(0, int(u) - 2):int(u) + 3].any() for u, v, _ in inside]
    return float(np.mean(near))


@pytest.mark.parametrize("wrong", ["shifted", "transposed", "focal_x1.6"])
def test_wrong_keypoint_projections_fail_the_check(built, wrong):
    """The check above is not vacuous: the dataset's person keypoints, projected wrongly in memory
    (moved 15 % of the image or the person's width, u and v swapped, focal length 1.6x), miss the person's mask.  A
    left-right mirror of the image is NOT caught by it (measured: 4 of 6 mirrored people still had
    every point on their mask, the cyclist being centred); left and right are checked in 3D by
    test_labels.py::test_coco17_points_sit_on_the_rider, not in the image."""
    from pycocotools import mask as mu
    from pycocotools.coco import COCO
    _, _, out = built
    gt = COCO(os.path.join(out, "annotations.json"))
    person = gt.getCatIds(catNms=["person"])[0]
    shares = []
    for a in gt.loadAnns(gt.getAnnIds(catIds=[person])):
        img = gt.loadImgs(a["image_id"])[0]
        m = mu.decode(a["segmentation"]).astype(bool)
        kp = np.array(a["keypoints"], float).reshape(-1, 3)
        assert share_on_mask(kp, m) > 0.8                    # the real ones pass
        bad = kp.copy()
        if wrong == "shifted":  # by 15 % of the image, and at least the person's own width
            bad[:, 0] += max(0.15 * img["width"], a["bbox"][2])
        elif wrong == "transposed":
            bad[:, :2] = kp[:, 1::-1]
        else:
            c = np.array([img["width"], img["height"]]) / 2
            bad[:, :2] = c + 1.6 * (kp[:, :2] - c)
        shares.append(share_on_mask(bad, m))
    assert max(shares) <= 0.8, shares


def test_kill_and_resume_gives_identical_dataset(built, tmp_path):
    root, cfg, full = built
    cfg_path = write_yaml(str(tmp_path / "c.yaml"), cfg)
    out = str(tmp_path / "killed")
    p = subprocess.Popen([sys.executable, "-m", "splatting", "dataset", "--config", cfg_path, "--out", out, "--quiet"],
                         cwd=ROOT, env=dict(os.environ, OMP_NUM_THREADS="1"),
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    shards = os.path.join(out, "shards")
    t0 = time.time()
    while time.time() - t0 < 120 and p.poll() is None:
        if os.path.isdir(shards) and len([f for f in os.listdir(shards) if f.endswith(".json")]) >= 2:
            break
        time.sleep(0.02)
    p.send_signal(signal.SIGKILL)
    p.wait()
    assert not os.path.exists(os.path.join(out, "annotations.json")), "killed too late to test resuming"
    for f in os.listdir(os.path.join(out, "images")):  # nothing under a final name is truncated
        if f.endswith(".png") and not f.startswith("."):
            from PIL import Image
            Image.open(os.path.join(out, "images", f)).load()
    r = cli("dataset", "--config", cfg_path, "--out", out)
    assert r.returncode == 0, r.stderr
    assert "already done" in r.stdout
    with open(os.path.join(full, "annotations.json"), "rb") as a, open(os.path.join(out, "annotations.json"), "rb") as b:
        assert a.read() == b.read()
    imgs = sorted(f for f in os.listdir(os.path.join(full, "images")) if not f.startswith("."))
    assert imgs == sorted(f for f in os.listdir(os.path.join(out, "images")) if not f.startswith("."))
    for f in imgs:
        with open(os.path.join(full, "images", f), "rb") as a, open(os.path.join(out, "images", f), "rb") as b:
            assert a.read() == b.read(), f


@pytest.mark.parametrize("patch, field", [
    ({"views": {"azimuth_deg": 5}}, "views.azimuth_deg"),
    ({"pose": {"theta_q_deg": [0, 1]}}, "pose.theta_q_deg"),
    ({"pose": {"theta_s_deg": [30, -30]}}, "pose.theta_s_deg"),
    ({"count": 0}, "count"),
    ({"backgrounds": {"kinds": ["photo"]}}, "backgrounds.kinds"),
    ({"riders": ["nobody"]}, "riders"),
    ({"camera": {"preset": "kitty"}}, "camera.preset"),
    ({"mode": "street", "camera": {"preset": "custom", "width": 640, "height": 480}}, "camera.fx"),
    ({"mode": "street", "camera": {"preset": "kitti", "height_m": -1}}, "camera.height_m"),
    ({"mode": "street", "camera": {"preset": "kitti"}, "street": {"cyclists": [3, 1]}}, "street.cyclists"),
    ({"mode": "street", "camera": {"preset": "kitti"}, "street": {"heading": "north"}}, "street.heading"),
    ({"labels": {"formats": ["voc"]}}, "labels.formats"),
    ({"keypoints": {"person": "coco18"}}, "keypoints.person"),
    ({"backgrounds": {"kinds": ["images"]}}, "backgrounds.images_dir"),
    ({"bikes": ["no_such_bike"]}, "bikes"),
])
def test_config_errors_name_the_field(tmp_path, patch, field):
    from splatting.cli import main
    write_test_bike(str(tmp_path))
    cfg = small_config(str(tmp_path))
    cfg.update(patch)
    path = write_yaml(str(tmp_path / "bad.yaml"), cfg)
    import contextlib
    import io
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["dataset", "--config", path, "--out", str(tmp_path / "o")])
    assert rc == 2
    msg = err.getvalue().strip()
    assert f"config field '{field}'" in msg and len(msg.splitlines()) == 1
    assert not os.path.exists(tmp_path / "o" / "annotations.json")


@pytest.mark.parametrize("meta", ["{not json", None])
def test_bikes_all_refuses_an_unreadable_meta_json(tmp_path, meta):
    """`bikes: all` in cyclist mode keeps bikes with pedals; a bike whose meta.json is corrupt or
    missing is an error naming that file, not a bike silently dropped as "no crank"."""
    from splatting.cli import main
    import contextlib
    import io
    write_test_bike(str(tmp_path))
    bad = write_test_bike(str(tmp_path), "road_t")
    os.remove(os.path.join(bad, "meta.json"))
    if meta is not None:
        with open(os.path.join(bad, "meta.json"), "w") as f:
            f.write(meta)
    path = write_yaml(str(tmp_path / "all.yaml"), small_config(str(tmp_path), bikes="all"))
    err = io.StringIO()
    with contextlib.redirect_stderr(err):
        rc = main(["dataset", "--config", path, "--out", str(tmp_path / "o")])
    msg = err.getvalue().strip()
    assert rc == 2 and len(msg.splitlines()) == 1, msg
    assert os.path.join(bad, "meta.json") in msg, msg
    assert not os.path.exists(tmp_path / "o" / "annotations.json")


def test_bad_yaml_and_unknown_preset(tmp_path):
    from splatting.cli import main
    p = tmp_path / "x.yaml"
    p.write_text("count: [1,\n")
    assert main(["dataset", "--config", str(p)]) == 2
    assert main(["dataset", "--preset", "nope"]) == 2


def test_presets_are_valid():
    from splatting.dataset.config import load_config
    a = load_config(preset="bike-only")
    b = load_config(preset="cyclist")
    c = load_config(preset="street")
    assert a.mode == "bike-only" and b.mode == "cyclist" and c.mode == "street"
    assert a.camera.preset == b.camera.preset == "ring" and c.camera.preset == "nuscenes"


def test_other_config_in_same_folder_is_refused(built, tmp_path):
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from cyclist_formats.errors import UserError
    root, cfg, full = built
    with pytest.raises(UserError, match="seed"):
        generate(validate(dict(cfg, seed=99)), full, log=lambda m: None, progress=False)


def test_bike_only_mode_and_backgrounds(tmp_path):
    from pycocotools.coco import COCO
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.dataset.generate import background
    write_test_bike(str(tmp_path))
    cfg = validate(small_config(str(tmp_path), mode="bike-only", count=2, seed=1))
    generate(cfg, str(tmp_path / "b"), log=lambda m: None, progress=False)
    gt = COCO(str(tmp_path / "b" / "annotations.json"))
    assert {a["category_id"] for a in gt.dataset["annotations"]} == {1}
    assert len(gt.dataset["annotations"]) == 2
    for kind in ("solid", "gradient", "noise"):
        a, b = background(kind, 7, 32), background(kind, 7, 32)
        assert a.shape == (32, 32, 3) and (a == b).all() and 0 <= a.min() and a.max() <= 1
        assert not (background(kind, 8, 32) == a).all()
    assert background("noise", 7, 32).std() > 0.01


def _images_of_a_bike_recording(tmp_path, configs):
    """One dataset image per training-JSON "config" written for every part of the same trained
    (synthetic) bike: what the dataset draws from what its parts record."""
    import json

    import torch
    from PIL import Image

    from splatting.cyclist.assets import synthetic_bike_parts
    from splatting.dataset.command import generate
    from splatting.dataset.config import validate
    from splatting.gaussians.container import write_ply
    torch.set_num_threads(1)
    d = write_test_bike(str(tmp_path))
    with open(os.path.join(d, "keypoints.json")) as f:
        kps = json.load(f)["keypoints"]
    with open(os.path.join(d, "meta.json")) as f:
        parts = synthetic_bike_parts(kps, json.load(f), 600)
    os.makedirs(os.path.join(d, "gaussians"))
    for p, g in parts.items():
        write_ply(g, os.path.join(d, "gaussians", p + ".ply"))
    images = []
    for k, cfg in enumerate(configs):
        for p in parts:
            with open(os.path.join(d, "gaussians", p + ".json"), "w") as f:
                json.dump({"config": cfg}, f)
        out = str(tmp_path / f"out{k}")
        generate(validate(small_config(str(tmp_path), count=1, synthetic_assets="auto")), out, log=lambda m: None,
                 progress=False)
        (name,) = sorted(os.listdir(os.path.join(out, "images")))
        images.append(np.asarray(Image.open(os.path.join(out, "images", name)), dtype=np.int16))
    return images


def test_a_bike_trained_antialiased_is_drawn_antialiased(tmp_path):
    """The dataset draws a bike whose parts' training JSON says "antialiased" with the mip filter
    (BikeModel.antialiased, per Gaussian: the rider stays as trained): the same parts marked plain
    give another image, and marked antialiased again the same image as the first antialiased run."""
    images = _images_of_a_bike_recording(tmp_path, [{"antialiased": aa} for aa in (True, False, True)])
    assert np.array_equal(images[0], images[2])
    assert np.abs(images[0] - images[1]).max() > 20


def test_a_bike_is_drawn_with_the_low_pass_it_was_trained_with(tmp_path):
    """The dataset draws a bike with the eps2d its parts' training JSON records (BikeModel.eps2d,
    per Gaussian beside its rider at 0.3): 0.173 gives another image than 0.3, and 0.3 written
    out the same image as parts that record none (the renders of before, bit for bit)."""
    images = _images_of_a_bike_recording(tmp_path, ({"eps2d": 0.173}, {}, {"eps2d": 0.3}))
    assert np.array_equal(images[1], images[2])
    assert np.abs(images[0] - images[1]).max() > 5
