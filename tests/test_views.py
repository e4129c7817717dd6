"""Views folder reader: docs/contract.md layout, NeRF transforms.json, fallbacks and clear errors."""
import json
import os
import shutil

import numpy as np
import pytest
import torch
from PIL import Image

from splatting.raster.camera import ring
from cyclist_formats.errors import UserError
from splatting.training.views import load_views, write_views

SIZE = 32


def _images(n):
    """Smooth colours (JPEG-friendly) inside a disc of binary alpha (img/ + mask/ then lose only JPEG)."""
    y, x = torch.meshgrid(torch.arange(SIZE) / SIZE, torch.arange(SIZE) / SIZE, indexing="ij")
    imgs = []
    for i in range(n):
        rgb = torch.stack([x, y, torch.full_like(x, i / n)], -1)
        a = (((x - 0.5) ** 2 + (y - 0.5) ** 2) < 0.1).float()
        imgs.append(torch.cat([rgb, a[..., None]], -1))
    return torch.stack(imgs)


def _folder(tmp_path, n=6, points=True):
    cams = [c.scaled(SIZE / 512) for c in ring(n=n, step_deg=60.0, orbit_centre=(0.0, 0.6, 0.0))]
    imgs = _images(n)
    pts = torch.randn(50, 3) if points else None
    d = str(tmp_path / "views" / "frame")
    write_views(d, cams, imgs, pts, (0.0, 0.6, 0.0), point_colors=torch.rand(50, 3) if points else None)
    return d, cams, imgs, pts


def test_round_trip_layout(tmp_path):
    d, cams, imgs, pts = _folder(tmp_path)
    for rel in ("cameras.json", "transforms.json", "points.ply", "rgba/camera0005/0000.png",
                "img/camera0000/0000.jpg", "mask/camera0000/0000.png"):
        assert os.path.exists(os.path.join(d, rel)), rel
    v = load_views(d)
    assert v.names == [f"camera{i:04d}" for i in range(6)]
    assert (v.width, v.height) == (SIZE, SIZE) and v.images.shape == (6, SIZE, SIZE, 4)
    assert torch.allclose(v.images, (imgs * 255).round() / 255, atol=1e-6)
    for a, b in zip(v.cameras, cams):
        assert torch.allclose(a.R, b.R, atol=1e-6) and torch.allclose(a.T, b.T, atol=1e-5)
        assert torch.allclose(a.K, b.K) and (a.width, a.height) == (SIZE, SIZE)
    assert torch.allclose(v.points, pts) and v.point_colors.shape == (50, 3)
    assert v.point_colors.min() >= 0 and v.point_colors.max() <= 1
    assert torch.allclose(v.orbit_centre, torch.tensor([0.0, 0.6, 0.0]))


def test_nerf_transforms_convention(tmp_path):
    """A hand-written NeRF frame (OpenGL camera-to-world) for docs/contract.md's view 0: the camera sits at
    orbit + (0, 0, -12) looking along +Z with +Y up, so its OpenGL axes are x = -X, y = +Y, z = -Z."""
    d = tmp_path / "v"
    (d / "rgba" / "camera0000").mkdir(parents=True)
    Image.fromarray(np.full((SIZE, SIZE, 4), 255, np.uint8)).save(d / "rgba" / "camera0000" / "0000.png")
    c2w = [[-1, 0, 0, 0], [0, 1, 0, 0.6], [0, 0, -1, -12], [0, 0, 0, 1]]
    focal = 2084.97 * SIZE / 512
    angle = 2 * np.arctan(SIZE / (2 * focal))
    (d / "transforms.json").write_text(json.dumps({"camera_angle_x": angle, "frames": [
        {"file_path": "./rgba/camera0000/0000", "transform_matrix": c2w}]}))
    cam = load_views(str(d)).cameras[0]
    assert torch.allclose(cam.R, torch.diag(torch.tensor([-1.0, -1.0, 1.0])))  # docs/contract.md's R0
    assert torch.allclose(cam.T, torch.tensor([0.0, 0.6, 12.0]), atol=1e-6)  # T = -R C
    assert abs(float(cam.K[0, 0]) - focal) < 1e-3 and float(cam.K[0, 2]) == SIZE / 2
    ref = ring(n=1, orbit_centre=(0.0, 0.6, 0.0))[0]
    assert torch.allclose(cam.R, ref.R, atol=1e-6) and torch.allclose(cam.T, ref.T, atol=1e-5)


def test_transforms_used_when_cameras_json_missing(tmp_path):
    d, cams, _, _ = _folder(tmp_path)
    os.remove(os.path.join(d, "cameras.json"))
    v = load_views(d)
    assert len(v) == 6 and v.orbit_centre is None
    for a, b in zip(v.cameras, cams):
        assert torch.allclose(a.R, b.R, atol=1e-5) and torch.allclose(a.T, b.T, atol=1e-4)
        assert torch.allclose(a.K, b.K, atol=1e-3)


def test_img_mask_fallback(tmp_path):
    d, _, imgs, _ = _folder(tmp_path)
    shutil.rmtree(os.path.join(d, "rgba"))
    v = load_views(d)
    assert torch.equal(v.images[..., 3], imgs[..., 3])  # the 0/255 mask is the alpha
    inside = imgs[..., 3] > 0
    assert (v.images[..., :3][inside] - imgs[..., :3][inside]).abs().mean() < 0.05  # JPEG


def test_points_optional(tmp_path):
    d, _, _, _ = _folder(tmp_path, points=False)
    assert load_views(d).points is None


# -- every bad input is a UserError naming the file ------------------------------------------------

def test_zero_views(tmp_path):
    with pytest.raises(UserError, match="zero views"):
        load_views(str(tmp_path))
    (tmp_path / "cameras.json").write_text('{"orbit_centre": [0, 0, 0]}')
    with pytest.raises(UserError, match="zero views"):
        load_views(str(tmp_path))


def test_mismatched_sizes(tmp_path):
    d, _, _, _ = _folder(tmp_path)
    p = os.path.join(d, "rgba", "camera0002", "0000.png")
    Image.fromarray(np.zeros((SIZE, SIZE + 4, 4), np.uint8)).save(p)
    with pytest.raises(UserError, match="size mismatch.*camera0002"):
        load_views(d)


def test_size_disagrees_with_intrinsics(tmp_path):
    d, _, _, _ = _folder(tmp_path)
    for i in range(6):  # all images half size: K (cx = 16) no longer fits
        p = os.path.join(d, "rgba", f"camera{i:04d}", "0000.png")
        Image.open(p).resize((SIZE // 2, SIZE // 2)).save(p)
    with pytest.raises(UserError, match="size mismatch"):
        load_views(d)


def test_empty_masks(tmp_path):
    d, _, _, _ = _folder(tmp_path)
    for i in range(6):
        p = os.path.join(d, "rgba", f"camera{i:04d}", "0000.png")
        a = np.asarray(Image.open(p)).copy()
        a[..., 3] = 0
        Image.fromarray(a).save(p)
    with pytest.raises(UserError, match="empty masks"):
        load_views(d)


@pytest.mark.parametrize("rel", ["rgba/camera0003/0000.png", "points.ply", "cameras.json"])
def test_unreadable_file_is_named(tmp_path, rel):
    d, _, _, _ = _folder(tmp_path)
    with open(os.path.join(d, rel), "wb") as f:
        f.write(b"\x00garbage\xff" * 3)
    with pytest.raises(UserError, match=os.path.basename(rel)):
        load_views(d)


def test_missing_image_is_named(tmp_path):
    d, _, _, _ = _folder(tmp_path)
    shutil.rmtree(os.path.join(d, "rgba", "camera0004"))
    shutil.rmtree(os.path.join(d, "img", "camera0004"))
    with pytest.raises(UserError, match="camera0004"):
        load_views(d)
