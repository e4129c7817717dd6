"""Per-image light in datasets (`lighting:`, splatting/dataset/lighting.py): config checks, refusal
of assets without relight channels, determinism, the recorded sun is the one rendered, and relit
samples differ from baked ones in the RGB only."""
import math
import os

import numpy as np
import pytest
import torch

from cyclist_formats import bike_folder
from helpers import RIDER, dataset_main, make_bike, random_relight_files, small_config

RELIT = {"mode": "relit", "elevation_deg": [20, 70], "strength": [2, 5], "sky": [0.1, 0.5]}


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """A trained-looking bike (random part Gaussians) and a 1500-Gaussian avatar of the roster rider,
    each with relight channels."""
    torch.set_num_threads(1)
    from splatting.cyclist.assets import mesh_avatar
    from splatting.rider.roster import load_rider
    root = tmp_path_factory.mktemp("relit")
    d = make_bike(str(root), "rl", n=300, sh_degree=1)
    random_relight_files([os.path.join(d, "gaussians", p + ".ply") for p in ("frame", "steering", "crank")])
    folder = root / "riders" / RIDER
    mesh_avatar(load_rider(RIDER), 1500).save(str(folder))
    random_relight_files([str(folder / "rider.ply")], seed=1)
    return str(root)


def _cfg(root, **kw):
    cfg = small_config(root, bikes=["rl"], riders_root=os.path.join(root, "riders"), synthetic_assets="never",
                       count=2, image_size=64, lighting=dict(RELIT))
    cfg.update(kw)
    return cfg


@pytest.mark.parametrize("light, field", [
    ({"mode": "sunny"}, "lighting.mode"),
    ({"elevation_deg": [60, 20]}, "lighting.elevation_deg"),
    ({"elevation_deg": [-10, 20]}, "lighting.elevation_deg"),
    ({"elevation_deg": [float("nan"), 20]}, "lighting.elevation_deg"),
    ({"azimuth_deg": 30}, "lighting.azimuth_deg"),
    ({"strength": [1, float("inf")]}, "lighting.strength"),
    ({"sky": [-0.1, 0.5]}, "lighting.sky"),
    ({"sun_tint": 1.0}, "lighting.sun_tint"),
    ({"shadows": "yes"}, "lighting.shadows"),
    ({"sunrise": 1}, "lighting.sunrise"),
])
def test_bad_lighting_fields_are_named(tmp_path, light, field):
    rc, msg = dataset_main(small_config(str(tmp_path), lighting=light), tmp_path)
    assert rc == 2 and f"config field '{field}'" in msg and len(msg.splitlines()) == 1, msg
    assert not os.path.exists(tmp_path / "o" / "annotations.json")


def test_relit_refuses_assets_without_relight_channels(assets, tmp_path):
    import shutil
    root = str(tmp_path / "copy")
    shutil.copytree(assets, root)
    rc, msg = dataset_main(_cfg(root, synthetic_assets="always"), tmp_path)
    assert rc == 2 and "synthetic_assets" in msg and len(msg.splitlines()) == 1, msg
    os.remove(bike_folder.relight_path(os.path.join(root, "rl", "gaussians", "crank.ply")))
    rc, msg = dataset_main(_cfg(root), tmp_path)
    assert rc == 2 and len(msg.splitlines()) == 1, msg
    assert "'rl'" in msg and "'crank'" in msg and "relight-fit --views" in msg
    random_relight_files([os.path.join(root, "rl", "gaussians", "crank.ply")])
    os.remove(bike_folder.relight_path(os.path.join(root, "riders", RIDER, "rider.ply")))
    rc, msg = dataset_main(_cfg(root), tmp_path)
    assert rc == 2 and len(msg.splitlines()) == 1 and RIDER in msg and "relight-fit" in msg, msg
    shutil.rmtree(os.path.join(root, "riders", RIDER))
    rc, msg = dataset_main(_cfg(root), tmp_path)
    assert rc == 2 and len(msg.splitlines()) == 1 and "rider-avatar" in msg, msg
    assert not os.path.exists(tmp_path / "o")


def _sample(cfg, index):
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    c = resolve_assets(validate(cfg))  # what the command's workers receive
    return make_sample(c, index, Assets(c))


def test_relit_is_deterministic_and_records_the_sun_it_renders(assets, monkeypatch):
    from splatting.cyclist import scene_relit as scene
    used = []
    real = scene.shade_composited
    monkeypatch.setattr(scene, "shade_composited", lambda *a, **k: used.append(a[4]) or real(*a, **k))
    cfg = _cfg(assets)
    rgb0, img0, anns0, _ = _sample(cfg, 1)
    rgb1, img1, anns1, _ = _sample(cfg, 1)  # fresh assets: a resumed run's worker
    assert np.array_equal(rgb0, rgb1) and img0 == img1 and anns0 == anns1
    assert len(used) == 2
    light, rec = used[0], img0["lighting"]
    assert rec["mode"] == "relit" and rec["shadows"] is True
    np.testing.assert_allclose(rec["sun_direction_world"], light.direction(torch.float64).numpy(), atol=1e-12)
    assert rec["sun_strength"] == light.sun_strength and tuple(rec["sun_colour"]) == light.sun_colour
    assert tuple(rec["sky"]) == light.sky
    R = np.asarray(img0["camera"]["R"])
    np.testing.assert_allclose(rec["sun_direction_camera"], R @ np.asarray(rec["sun_direction_world"]), atol=1e-12)
    # elevation / azimuth describe the same direction, within the configured ranges
    e, a = math.radians(rec["elevation_deg"]), math.radians(rec["azimuth_deg"])
    np.testing.assert_allclose(rec["sun_direction_world"], [math.cos(e) * math.cos(a), math.sin(e), math.cos(e) * math.sin(a)],
                               atol=1e-12)
    assert 20 <= rec["elevation_deg"] <= 70 and 2 <= rec["sun_strength"] <= 5
    # another image, another sun
    _, img2, _, _ = _sample(cfg, 0)
    assert img2["lighting"]["sun_direction_world"] != rec["sun_direction_world"]


def test_relit_bikes_carry_their_sky_visibility(assets, monkeypatch):
    # the bike's self-occlusion rides as the last relight channel (riders: 1), and is shaded
    from splatting.cyclist import scene_relit as scene
    seen = []
    real = scene.shade_composited
    monkeypatch.setattr(scene, "shade_composited", lambda *a, **k: seen.append((a, k)) or real(*a, **k))
    _sample(_cfg(assets), 1)
    (R, F, cover, *_), kw = seen[0]
    assert kw["sky_channel"] and kw["shadows"] and F.shape[-1] == 3 + 1 + 1 + 1 + 1  # normal, gloss, rough, sun, sky
    m = cover > 0.5
    sky = F[..., -1][m] / cover[m]
    assert int(m.sum()) > 20 and float(sky.max()) <= 1 + 1e-4 and float(sky.min()) < 0.95


@pytest.mark.parametrize("extra", [{}, {"appearance": {"enabled": True}, "lod": {"enabled": True}}])
def test_relit_and_baked_differ_in_rgb_only(assets, extra):
    relit = _cfg(assets, **extra)
    baked = _cfg(assets, lighting={"mode": "baked"}, **extra)
    for i in range(2):
        rgb_r, img_r, anns_r, ex_r = _sample(relit, i)
        rgb_b, img_b, anns_b, ex_b = _sample(baked, i)
        assert "lighting" not in img_b
        assert {k: v for k, v in img_r.items() if k != "lighting"} == img_b
        assert anns_r == anns_b  # masks (RLE), boxes, keypoints, occlusion, 3D boxes
        assert np.array_equal(ex_r["depth"], ex_b["depth"]) and ex_r["kitti"] == ex_b["kitti"]
        changed = np.abs(rgb_r.astype(int) - rgb_b.astype(int)).max(-1) > 0
        assert changed.mean() > 0.02
        # the pixels that change are the instances' (the background stays)
        from pycocotools import mask as mask_utils
        ink = np.zeros(changed.shape, bool)
        for a in anns_r:
            ink |= mask_utils.decode(a["segmentation_amodal"] if "segmentation_amodal" in a else a["segmentation"]).astype(bool)
        assert changed[ink].mean() > 0.5


def test_baked_config_record_has_no_lighting_section(assets):
    from splatting.dataset.config import validate
    from splatting.dataset.generate import config_record
    assert "lighting" not in config_record(validate(small_config(assets)))
    assert config_record(validate(_cfg(assets)))["lighting"]["mode"] == "relit"


def test_ground_shadow_falls_away_from_the_sun():
    from splatting.dataset.backgrounds import contact_shadows
    from splatting.relight.shading import Light
    foot = [(2.0, 3.0, 0.0, 1.8, 0.6)]
    base = contact_shadows(foot, 0.55)
    el = math.radians(40.0)
    sun = Light(sun_direction=(math.cos(el), math.sin(el), 0.0), sun_strength=4.0, sky=(0.2, 0.2, 0.2))
    cast = contact_shadows(foot, 0.55, sun=sun, heights=[1.7])
    # the sun stands towards +X: the shadow reaches h / tan(el) towards -X, not sideways
    m = cast.means.double()
    assert float(m[:, 0].min()) < 2.0 - 0.7 * 1.7 / math.tan(el) and abs(float(m[:, 2].mean()) - 3.0) < 1e-5
    assert float(base.means[:, 0].min()) > 2.0 - 0.9
    # the darkness is the sun's share of the ground's light, times the configured opacity
    e_sun = 4.0 * math.sin(el) / math.pi
    share = e_sun / (e_sun + 0.2)
    dense = 1 - (1 - cast.opacities.double()[0]) ** 2  # two copies overlap anywhere
    assert float(dense) == pytest.approx(0.55 * share, rel=1e-4)
    low = contact_shadows(foot, 0.55, sun=Light(sun_direction=(1.0, 0.01, 0.0), sky=(0.2, 0.2, 0.2)), heights=[1.7])
    assert float(low.means[:, 0].min()) > 2.0 - 4 * 1.7 - 1.0  # at most 4 heights long


def test_relit_street_scene_on_a_photo(assets, tmp_path, monkeypatch):
    # several cyclists, parked bikes, a photo background with contact shadows: the labels are the
    # baked scene's; the instances' shadows fall on the road away from the sun (a layer darkening
    # what is not an instance)
    from PIL import Image
    from helpers import street_config
    from splatting.dataset import lighting
    Image.fromarray(np.full((90, 160, 3), 200, np.uint8)).save(tmp_path / "road.png")
    kw = dict(bikes=["rl"], riders_root=os.path.join(assets, "riders"), synthetic_assets="never",
              backgrounds={"kinds": ["images"], "images_dir": str(tmp_path)},
              camera={"preset": "kitti", "scale": 0.25}, street={"distance_m": [4, 8]})
    baked = street_config(assets, **kw)
    relit = street_config(assets, lighting=dict(RELIT, shadows=False), **kw)
    seen = []
    real = lighting.RelitSample.cast_shadows
    monkeypatch.setattr(lighting.RelitSample, "cast_shadows",
                        lambda self, rgb, L, *a: seen.append((rgb, L["relit_cover"], real(self, rgb, L, *a))) or seen[-1][2])
    rgb_r, img_r, anns_r, _ = _sample(relit, 0)
    rgb_b, img_b, anns_b, _ = _sample(baked, 0)
    assert len(img_r["instances"]) >= 2 and anns_r == anns_b
    assert img_r["lighting"]["shadows"] is False
    (before, cover, after), = seen
    assert np.array_equal(after, rgb_r) and (after <= before).all()
    road = (cover < 1e-3) & (after < before).any(-1)
    assert road.sum() > 50  # the shadows land on the road ...
    assert ((after < before).any(-1) <= (cover < 0.999)).all()  # ... never on what an instance covers


def _bike_recording(assets, name, config):
    """A relight-ready bike `name` whose parts' training JSONs hold `config` (made once per module)."""
    import json
    d = os.path.join(assets, name)
    if not os.path.isdir(d):
        make_bike(assets, name, n=300, sh_degree=1)
        plys = [os.path.join(d, "gaussians", p + ".ply") for p in ("frame", "steering", "crank")]
        random_relight_files(plys)
        for ply in plys:
            with open(ply[:-4] + ".json", "w") as f:
                json.dump({"config": config}, f)
    return name


def _spy_on_maps(monkeypatch, kw, default):
    """{"sun": [(Gaussians, kw) of every sun map], "sky": [kw of every sky visibility]}, filled as
    the renders call them."""
    from splatting.relight import shadow
    calls = {"sun": [], "sky": []}
    real_sun, real_sky = shadow.sun_visibility, shadow.sky_visibility
    monkeypatch.setattr(shadow, "sun_visibility", lambda g, light, *a, **k:
                        calls["sun"].append((len(g), k.get(kw, default))) or real_sun(g, light, *a, **k))
    monkeypatch.setattr(shadow, "sky_visibility", lambda g, n, *a, **k:
                        calls["sky"].append(k.get(kw, default)) or real_sky(g, n, *a, **k))
    return calls


def test_shadow_maps_draw_an_antialiased_bike_with_the_filter(assets, monkeypatch):
    # a bike whose parts were trained with the mip filter casts its shadows (sun map) and hides its
    # sky through the filter, its rider as trained; a plain bike draws none of it with the filter
    calls = _spy_on_maps(monkeypatch, "antialiased", False)
    for bike, want in (("rl", False), (_bike_recording(assets, "rlaa", {"antialiased": True}), True)):
        calls["sun"].clear()
        calls["sky"].clear()
        _sample(_cfg(assets, bikes=[bike]), 1)
        assert calls["sky"] and all(a is want for a in calls["sky"])
        scene = [(n, aa) for n, aa in calls["sun"] if n > 1500]  # the cyclist's sun map (the sky's are the bike's alone)
        assert scene
        for n, aa in scene:
            if not want:
                assert aa is False
            else:  # the bike's Gaussians (first, 3 x ~300), not the rider's 1500
                assert torch.is_tensor(aa) and len(aa) == n and 800 < int(aa.sum()) < 1000 and not bool(aa[-1])


def test_relit_bike_with_view_normals_turns_them_to_the_dataset_camera(assets, tmp_path, monkeypatch):
    # a bike fitted with view-dependent normals (relight.npz "normal_view") is shaded with them
    # turned to the sample's camera; normal_view 0 shades as the plain normals
    import shutil

    from splatting.relight import render
    root = str(tmp_path / "a")
    shutil.copytree(assets, root)
    plys = [os.path.join(root, "rl", "gaussians", p + ".ply") for p in ("frame", "steering", "crank")]
    base, _, _, _ = _sample(_cfg(root), 1)
    g = torch.Generator().manual_seed(9)
    for view in ("zero", "random"):
        for ply in plys:
            r = bike_folder.read_relight(ply)
            n = len(r["normal"])
            B = np.zeros((n, 3, 3)) if view == "zero" else torch.randn(n, 3, 3, generator=g).numpy() * 3
            bike_folder.write_relight(ply, r["albedo"], r["normal"], r["gloss"], B)
        calls = []
        real = render.view_normals
        monkeypatch.setattr(render, "view_normals", lambda n, b, m, c: calls.append((len(n), c)) or real(n, b, m, c))
        rgb, img, _, _ = _sample(_cfg(root), 1)
        monkeypatch.setattr(render, "view_normals", real)
        assert calls and all(k == sum(len(bike_folder.read_relight(p)["normal"]) for p in plys) for k, _ in calls)
        np.testing.assert_allclose(calls[0][1].R.double().numpy(), np.asarray(img["camera"]["R"]), atol=1e-6)
        diff = np.abs(rgb.astype(int) - base.astype(int))
        if view == "zero":
            assert diff.max() <= 1
        else:
            assert (diff.max(-1) > 2).mean() > 0.005


def test_shadow_maps_draw_each_model_with_its_own_low_pass(assets, monkeypatch):
    # a bike whose parts record eps2d 0.173 casts its shadows (sun map) and hides its sky with it,
    # its rider with the avatar's 0.3; a bike that records none draws everything at 0.3 (one number)
    calls = _spy_on_maps(monkeypatch, "eps2d", 0.3)
    for bike, want in (("rl", 0.3), (_bike_recording(assets, "rleps", {"eps2d": 0.173}), 0.173)):
        calls["sun"].clear()
        calls["sky"].clear()
        _sample(_cfg(assets, bikes=[bike]), 1)
        assert calls["sky"] and all(e == want for e in calls["sky"])
        scene = [(n, e) for n, e in calls["sun"] if n > 1500]  # the cyclist's sun map
        assert scene
        for n, e in scene:
            if want == 0.3:
                assert e == 0.3 and not torch.is_tensor(e)
            else:  # the bike's Gaussians (first, 3 x ~300) at 0.173, the rider's 1500 at 0.3
                assert torch.is_tensor(e) and len(e) == n and 800 < int((e == 0.173).sum()) < 1000
                assert bool((e[-1500:] == 0.3).all())
