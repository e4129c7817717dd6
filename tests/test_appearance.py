"""Appearance variety (issue 12): re-colouring touches only its region's Gaussians, the gain is
exact, looks are a function of (config, index), and the switch off changes nothing."""
import numpy as np
import pytest
import torch

from helpers import RIDER, street_config, write_test_bike


@pytest.fixture(scope="module")
def setup(tmp_path_factory):
    torch.set_num_threads(1)
    root = str(tmp_path_factory.mktemp("looks_bikes"))
    write_test_bike(root)
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets
    cfg = resolve_assets(validate(street_config(root, appearance={"enabled": True})))
    assets = Assets(cfg)
    cyc = assets.cyclist("city_t", RIDER)
    frame = cyc.pose(torch.tensor([30.0, 0, 0, 0, 0, 0, 0, 8.0], dtype=torch.float64))[0]
    return root, cfg, assets, frame


def test_rider_regions_are_the_mesh_vertex_regions(setup):
    _, _, assets, _ = setup
    from splatting.cyclist.appearance import rider_regions
    from splatting.rider.body import REGIONS
    body = assets.bodies[RIDER]
    # the mesh avatar's Gaussians sit on mesh vertices: each must get its own vertex's region
    V = body.vertices
    idx = torch.tensor([0, 5, 100, len(V) // 2, len(V) - 1])
    assert torch.equal(rider_regions(V[idx] + 1e-5, body), body.regions[idx])
    reg = rider_regions(assets.avatars[RIDER].gaussians.means, body)
    counts = torch.bincount(reg, minlength=len(REGIONS))
    assert (counts > 0).all()  # skin, top, bottom, shoes, helmet all present
    # the helmet is on top of the head, the shoes at the bottom
    y = assets.avatars[RIDER].gaussians.means[:, 1]
    assert y[reg == REGIONS.index("helmet")].min() > y[reg == REGIONS.index("top")].max() - 0.3
    assert y[reg == REGIONS.index("shoes")].max() < 0.2


@pytest.mark.parametrize("region", ["top", "bottom", "shoes", "helmet", "paint"])
def test_recolouring_changes_only_its_regions_gaussians(setup, region):
    _, _, assets, frame = setup
    from cyclist_formats.instances import RIDER_ID
    from splatting.cyclist import appearance
    from splatting.rider.body import REGIONS
    inputs = assets.look_inputs("city_t", RIDER, frame)
    g = frame.gaussians
    out = appearance.apply_look(g, frame.ids, {region: np.array([0.1, 0.8, 0.3])}, np.ones(3), **inputs)
    # the unit gain's round trip through the DC offset may move a colour by one float32 ulp
    changed = ((out.sh - g.sh).abs() > 1e-5).flatten(1).any(1)
    if region == "paint":
        want = inputs["paint"]
        assert bool(want.any()) and not bool((want & (frame.ids == RIDER_ID)).any())
    else:
        want = torch.zeros(len(g), dtype=torch.bool)
        want[frame.ids == RIDER_ID] = inputs["rider_reg"] == REGIONS.index(region)
    assert bool(want.any()) and torch.equal(changed, want)
    # the region's colour now has the target's hue: green dominates where the top was red
    rgb = appearance.dc_rgb(out.sh[want])
    assert (rgb[:, 1] > rgb[:, 0]).float().mean() > 0.95
    assert torch.equal(out.means, g.means) and torch.equal(out.opacity_logits, g.opacity_logits)


def test_gain_scales_the_evaluated_colour_exactly():
    from splatting.cyclist.appearance import apply_gain
    from splatting.gaussians.sh import eval_sh
    gen = torch.Generator().manual_seed(0)
    sh = torch.randn(50, 16, 3, generator=gen, dtype=torch.float64) * 0.3
    dirs = torch.nn.functional.normalize(torch.randn(50, 3, generator=gen, dtype=torch.float64), dim=1)
    gain = np.array([0.8, 1.1, 1.3])
    a = eval_sh(sh, dirs, 3)
    b = eval_sh(apply_gain(sh, gain), dirs, 3)
    assert torch.allclose(b, a * torch.tensor(gain), atol=1e-12)


def test_looks_are_a_function_of_config_and_index(setup):
    _, cfg, _, _ = setup
    from splatting.cyclist.appearance import draw_look
    a, ga = draw_look(cfg.appearance, 3, 7, 1)
    b, gb = draw_look(cfg.appearance, 3, 7, 1)
    assert all((a[k] is None and b[k] is None) or np.array_equal(a[k], b[k]) for k in a) and np.array_equal(ga, gb)
    others = [draw_look(cfg.appearance, 3, 8, 1), draw_look(cfg.appearance, 3, 7, 2), draw_look(cfg.appearance, 4, 7, 1)]
    assert all(not np.array_equal(g, ga) for _, g in others)
    lo, hi = cfg.appearance.brightness
    assert lo * 0.9 <= ga.mean() <= hi * 1.1


def _sample(root, index=0, **kw):
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    cfg = resolve_assets(validate(street_config(root, **kw)))
    return make_sample(cfg, index, Assets(cfg))


def test_switch_off_is_unchanged_and_on_changes_colours_not_labels(setup):
    root = setup[0]
    off = _sample(root)
    identity = _sample(root, appearance={"enabled": True, "regions": [], "brightness": [1.0, 1.0], "white_balance": 0.0})
    on = _sample(root, appearance={"enabled": True, "keep_share": 0.0})
    again = _sample(root, appearance={"enabled": True, "keep_share": 0.0})
    assert (identity[0] == off[0]).all()  # an identity look renders the same bytes
    assert all("appearance" not in i for i in off[1]["instances"])
    assert (on[0] == again[0]).all() and on[1] == again[1]  # deterministic
    assert (on[0] != off[0]).any(-1).sum() > 200  # the cyclists changed colour ...
    strip = lambda anns: [{k: v for k, v in a.items() if k != "keypoints"} for a in anns]  # noqa: E731
    assert strip(on[2]) == strip(off[2])  # ... but not shape: the same masks, boxes, 3D labels
    looks = [i["appearance"] for i in on[1]["instances"]]
    assert all(set(x["colours"]) == {"top", "bottom", "shoes", "helmet", "paint"} for x in looks)
