"""Level of detail (issue 12): the level follows the screen height, a level is a subset of the
next larger one with its budget, every part keeps its share, and LOD off renders what the full
model renders."""
import math

import numpy as np
import pytest
import torch

from helpers import fixed_scene, street_config  # noqa: F401

LEVELS = [{"below_px": 100, "keep": 0.5}, {"below_px": 50, "keep": 0.25}, {"below_px": 20, "keep": 0.1}]


def _gaussians(n, seed=0):
    from splatting.gaussians.container import Gaussians
    gen = torch.Generator().manual_seed(seed)
    return Gaussians(means=torch.randn(n, 3, generator=gen), quats=torch.randn(n, 4, generator=gen),
                     log_scales=torch.randn(n, 3, generator=gen) - 3, opacity_logits=torch.randn(n, generator=gen),
                     sh=torch.rand(n, 1, 3, generator=gen))


@pytest.mark.parametrize("h, keep", [(500, 1.0), (100, 1.0), (99.9, 0.5), (50, 0.5), (49, 0.25), (20, 0.25),
                                     (19, 0.1), (1, 0.1)])
def test_level_follows_the_screen_height(h, keep):
    from splatting.cyclist.lod import level_keep
    assert level_keep(h, LEVELS) == keep
    assert level_keep(h, list(reversed(LEVELS))) == keep  # order in the config does not matter
    assert level_keep(h, []) == 1.0


def test_levels_are_nested_with_their_budget_and_every_part_keeps_its_share():
    from splatting.cyclist import lod
    g = _gaussians(1000)
    groups = torch.tensor([0] * 700 + [3] * 200 + [7] * 100)
    # part 7 is made of far larger Gaussians: a global ranking would keep it whole and starve the rest
    g.log_scales[900:] += 3.0
    order = lod.ranking(g, groups)
    assert sorted(order.tolist()) == list(range(1000))
    prev = set(range(1000))
    for keep in (0.5, 0.25, 0.1):
        idx = lod.kept(order, keep)
        assert len(idx) == math.ceil(keep * 1000)
        assert set(idx.tolist()) <= prev
        prev = set(idx.tolist())
        for v, n in ((0, 700), (3, 200), (7, 100)):
            assert abs(int((groups[idx] == v).sum()) - keep * n) <= 1.5
        # inside a part, the kept ones are the most important
        imp = lod.importance(g)
        in0 = idx[groups[idx] == 0]
        out0 = torch.tensor(sorted(set(range(700)) - set(in0.tolist())))
        assert imp[in0].min() >= imp[out0].max()


def test_reduce_grows_only_the_kept_gaussians_by_their_parts_lost_importance():
    from splatting.cyclist import lod
    g = _gaussians(400, seed=1)
    groups = torch.tensor([1] * 200 + [2] * 200)
    order = lod.ranking(g, groups)
    plain, idx = lod.reduce(g, order, 0.25, compensate=0.0, groups=groups)
    assert torch.equal(plain.means, g.means[idx]) and torch.equal(plain.log_scales, g.log_scales[idx])
    grown, idx2 = lod.reduce(g, order, 0.25, compensate=1.0, groups=groups)
    assert torch.equal(idx, idx2) and torch.equal(grown.means, g.means[idx])
    imp = lod.importance(g).double()
    for v in (1, 2):
        m = groups == v
        k = groups[idx] == v
        want = 0.5 * math.log(float(imp[m].sum() / imp[idx][k].sum()))
        d = (grown.log_scales[k] - g.log_scales[idx][k]).double()
        assert torch.allclose(d, torch.full_like(d, want), atol=1e-5) and want > 0
    same, all_idx = lod.reduce(g, order, 1.0)
    assert same is g and len(all_idx) == 400


def _sample(cfg):
    torch.set_num_threads(1)
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets, make_sample
    cfg = resolve_assets(validate(cfg))
    return make_sample(cfg, 0, Assets(cfg))


def test_lod_off_renders_the_full_model_and_on_thins_far_cyclists(bikes, monkeypatch):
    from helpers import RIDER
    # kitti at scale 0.5 (f 361 px): a 1.8 m cyclist at 30 m is ~21 px tall, at 6 m ~108 px
    fixed_scene(monkeypatch, [(RIDER, -90.0, 1.0, 6.0), (RIDER, -90.0, -2.0, 30.0)])
    levels = [{"below_px": 60, "keep": 0.3}]
    off = _sample(street_config(bikes, lod={"enabled": False, "levels": levels}))
    none_apply = _sample(street_config(bikes, lod={"enabled": True, "levels": [{"below_px": 5, "keep": 0.3}]}))
    on = _sample(street_config(bikes, lod={"enabled": True, "levels": levels}))
    rgb_off, im_off, anns_off, _ = off
    assert (none_apply[0] == rgb_off).all() and none_apply[2] == anns_off
    assert all("lod_keep" not in i for i in im_off["instances"])
    assert [i["lod_keep"] for i in none_apply[1]["instances"]] == [1.0, 1.0]
    rgb_on, im_on, anns_on, _ = on
    assert [i["lod_keep"] for i in im_on["instances"]] == [1.0, 0.3]
    diff = np.abs(rgb_on.astype(int) - rgb_off.astype(int)).max(-1) > 0
    ys, xs = np.nonzero(diff)
    assert len(ys)  # the far cyclist changed ...
    near = [a for a in anns_off if a["instance"] == 1 and a["category_id"] == 3][0]
    x0, y0, w, h = near["bbox"]
    inside_near = (xs >= x0) & (xs < x0 + w) & (ys >= y0) & (ys < y0 + h)
    far = [a for a in anns_off if a["instance"] == 2 and a["category_id"] == 3][0]
    fx0, fy0, fw, fh = far["bbox"]
    inside_far = (xs >= fx0 - 2) & (xs < fx0 + fw + 2) & (ys >= fy0 - 2) & (ys < fy0 + fh + 2)
    assert inside_far[~inside_near].all()  # ... and only it (the near one is full in both)
    # its labels come from the full model's 3D box either way
    far_on = [a for a in anns_on if a["instance"] == 2 and a["category_id"] == 3][0]
    assert far_on["pose_3d"] == far["pose_3d"]
