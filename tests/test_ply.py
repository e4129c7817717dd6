"""INRIA 3DGS .ply: exact field layout, lossless round trip, and train -> write -> read -> render."""
import numpy as np
import pytest
import torch
from plyfile import PlyData

from splatting.gaussians.container import Gaussians, read_ply, write_ply
from splatting.raster.sparse import render_gaussians
from splatting.training.strategy import DensifyConfig
from splatting.training.trainer import TrainConfig, train_views
from splatting.training.views import load_views, render_ring_views, write_views

# The layout INRIA's train.py writes (save_ply), which the common viewers and Blender add-ons read.
INRIA_FIELDS = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"]
                + [f"f_rest_{i}" for i in range(45)]
                + ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"])


def random_gaussians(n, degree, seed=0):
    g = torch.Generator().manual_seed(seed)
    return Gaussians(torch.randn(n, 3, generator=g), torch.randn(n, 4, generator=g),  # quats left unnormalised
                     torch.randn(n, 3, generator=g) - 4, torch.randn(n, generator=g),
                     torch.randn(n, (degree + 1) ** 2, 3, generator=g))


def test_field_list_and_order(tmp_path):
    p = tmp_path / "g.ply"
    write_ply(random_gaussians(7, 3), p)
    ply = PlyData.read(str(p))
    assert [e.name for e in ply.elements] == ["vertex"]
    v = ply["vertex"]
    assert [prop.name for prop in v.properties] == INRIA_FIELDS
    assert all(v.data.dtype[name] == np.dtype("<f4") for name in INRIA_FIELDS)
    assert ply.text is False and ply.byte_order == "<"
    assert open(p, "rb").read(64).startswith(b"ply\nformat binary_little_endian 1.0\n")


@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_lossless_round_trip(tmp_path, degree):
    g = random_gaussians(50, degree, seed=degree)
    write_ply(g, tmp_path / "g.ply")
    h = read_ply(tmp_path / "g.ply")
    assert h.sh_degree == degree
    for f in ("means", "quats", "log_scales", "opacity_logits", "sh"):
        assert torch.equal(getattr(g, f), getattr(h, f)), f


def test_an_empty_part_reads_back(tmp_path):
    """A part pruned to no Gaussians (a tiny build's pedal) is a valid, empty PLY."""
    write_ply(random_gaussians(0, 3), tmp_path / "g.ply")
    h = read_ply(tmp_path / "g.ply")
    assert len(h) == 0 and h.sh_degree == 0


def test_f_rest_is_channel_major(tmp_path):
    """f_rest_0..14 are red's 15 higher-order coefficients, 15..29 green's, 30..44 blue's (INRIA)."""
    g = random_gaussians(3, 3)
    write_ply(g, tmp_path / "g.ply")
    v = PlyData.read(str(tmp_path / "g.ply"))["vertex"].data
    assert np.array_equal(v["f_rest_16"], g.sh[:, 2, 1].numpy())  # green, coefficient 2
    assert np.array_equal(v["f_rest_44"], g.sh[:, 15, 2].numpy())  # blue, coefficient 15


def _blob_views(folder, size=64):
    """A small scene of 60 coloured Gaussians rendered from the ring (training data)."""
    scene = random_gaussians(60, 1, seed=5)
    scene.means = scene.means * 0.15 + torch.tensor([0.0, 0.5, 0.0])
    scene.log_scales = torch.full((60, 3), np.log(0.04))
    scene.opacity_logits = torch.full((60,), 1.5)
    scene.sh = scene.sh * 0.3
    cams, imgs = render_ring_views(scene, size, (0.0, 0.5, 0.0))
    write_views(folder, cams, imgs, scene.means, (0.0, 0.5, 0.0))


def test_train_write_read_render_is_identical(tmp_path):
    _blob_views(str(tmp_path / "views"))
    views = load_views(str(tmp_path / "views"))
    cfg = TrainConfig(iterations=120, sh_degree=1, progress=False, threads=1,
                      densify=DensifyConfig(start=50, stop=100, max_gaussians=2000))
    g, _ = train_views(views, cfg)
    assert g.sh_degree == 1 and g.sh[:, 1:].abs().max() > 0  # the degree-1 band was trained
    write_ply(g, tmp_path / "part.ply")
    h = read_ply(tmp_path / "part.ply")
    assert len(h) == len(g) and h.sh_degree == 1
    for cam in (views.cameras[3], views.cameras[21]):
        a = render_gaussians(g, cam, background=torch.ones(3))
        b = render_gaussians(h, cam, background=torch.ones(3))
        assert a["alpha"].max() > 0.5  # something is on screen
        for k in ("rgb", "alpha", "depth"):
            assert (a[k] - b[k]).abs().max() <= 1e-6, k
