"""The low-pass a model was trained with (rasterize's eps2d) is a property of the model: parts,
fine-tuned bikes and avatars record it and BikeModel / RiderAvatar read it back (0.3 where nothing
records one); a scene composing models of different filters draws each with its own."""
import json
import os

import pytest
import torch

from cyclist_formats.errors import UserError
from splatting.bike.model import BikeModel
from splatting.raster.sparse import eps2d_cat, eps2d_where

from helpers import make_bike


def _write(path, doc):
    with open(path, "w") as f:
        json.dump(doc, f)


def test_parts_record_their_filter_and_absent_means_0_3(tmp_path):
    d = make_bike(tmp_path, sh_degree=0)
    g = os.path.join(d, "gaussians")
    assert BikeModel.load(d).eps2d == 0.3  # no metrics at all
    for p in ("frame", "steering", "crank"):
        _write(os.path.join(g, p + ".json"), {"config": {"antialiased": False}})
    assert BikeModel.load(d).eps2d == 0.3  # metrics from before the field
    for p in ("frame", "steering", "crank"):
        _write(os.path.join(g, p + ".json"), {"config": {"eps2d": 0.173}})
    assert BikeModel.load(d).eps2d == 0.173
    _write(os.path.join(g, "crank.json"), {"config": {"eps2d": 0.3}})
    with pytest.raises(UserError, match="different eps2d"):
        BikeModel.load(d)
    for bad in (-1.0, 0.0, "0.3", None):
        _write(os.path.join(g, "crank.json"), {"config": {"eps2d": bad}})
        with pytest.raises(UserError, match="eps2d"):
            BikeModel.load(d)


def test_a_fine_tuned_bike_has_the_fine_tunes_filter(tmp_path):
    d = make_bike(tmp_path, sh_degree=0)
    g = os.path.join(d, "gaussians")
    counts = {p: len(BikeModel.load(d).canonical.means[a:e]) for p, (a, e) in
              zip(BikeModel.load(d).part_names, BikeModel.load(d).ranges)}
    _write(os.path.join(g, "posed_train.json"), {"gaussians": counts, "config": {"eps2d": 0.2}})
    assert BikeModel.load(d).eps2d == 0.2
    # a record from before --eps2d: the fine-tune rendered at 0.3, whatever the parts' own
    for p in counts:
        _write(os.path.join(g, p + ".json"), {"config": {"eps2d": 0.173}})
    _write(os.path.join(g, "posed_train.json"), {"gaussians": counts, "config": {}})
    assert BikeModel.load(d).eps2d == 0.3
    # a part the record does not describe (retrained since: another count) has its own filter,
    # which here disagrees with the fine-tuned others
    _write(os.path.join(g, "posed_train.json"), {"gaussians": dict(counts, frame=counts["frame"] + 1),
                                                 "config": {"eps2d": 0.2}})
    with pytest.raises(UserError, match="frame: 0.173"):
        BikeModel.load(d)


def test_avatars_record_their_filter(tmp_path):
    from splatting.rider.avatar import trained_eps2d

    assert trained_eps2d(str(tmp_path)) == 0.3
    _write(os.path.join(tmp_path, "rider.json"), {"config": {"sh_degree": 0}})
    assert trained_eps2d(str(tmp_path)) == 0.3
    _write(os.path.join(tmp_path, "rider.json"), {"config": {"eps2d": 0.25}})
    assert trained_eps2d(str(tmp_path)) == 0.25
    _write(os.path.join(tmp_path, "rider.json"), {"config": {"eps2d": float("nan")}})
    with pytest.raises(UserError, match="eps2d"):
        trained_eps2d(str(tmp_path))


def test_a_scene_of_one_filter_stays_on_the_scalar_path():
    mask = torch.tensor([True, True, False])
    assert eps2d_where(mask, 0.3, 0.3) == 0.3 and not torch.is_tensor(eps2d_where(mask, 0.3, 0.3))
    assert eps2d_where(torch.zeros(3, dtype=torch.bool), 0.173, 0.3) == 0.3
    assert eps2d_where(torch.ones(3, dtype=torch.bool), 0.173, 0.3) == 0.173
    assert torch.equal(eps2d_where(mask, 0.173, 0.3), torch.tensor([0.173, 0.173, 0.3], dtype=torch.float64))
    assert eps2d_cat([(2, 0.3), (5, 0.3)]) == 0.3 and eps2d_cat([]) == 0.3
    assert torch.equal(eps2d_cat([(2, 0.173), (1, 0.3)]), torch.tensor([0.173, 0.173, 0.3], dtype=torch.float64))
    t = torch.tensor([0.1, 0.2], dtype=torch.float64)
    assert torch.equal(eps2d_cat([(2, t), (1, 0.3)]), torch.tensor([0.1, 0.2, 0.3], dtype=torch.float64))


def test_frame_eps2d_draws_bike_and_rider_with_their_own():
    from cyclist_formats.instances import IDS
    from splatting.cyclist.compose import frame_eps2d

    class M:
        def __init__(self, e):
            self.eps2d = e
    ids = torch.tensor([1, 2, 3, IDS["rider"], IDS["rider"]], dtype=torch.uint8)
    assert torch.equal(frame_eps2d(ids, M(0.173), M(0.3)), torch.tensor([0.173] * 3 + [0.3] * 2, dtype=torch.float64))
    assert frame_eps2d(ids, M(0.3), M(0.3)) == 0.3
    assert frame_eps2d(ids[:3], M(0.173), None) == 0.173
