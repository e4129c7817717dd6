"""Training targets: the held-out split, and every view cropped to the object's box (with its
camera), at each resolution of the coarse-to-fine schedule."""
import torch
import torch.nn.functional as F

from cyclist_formats.errors import UserError
from splatting.raster.camera import Camera
from splatting.training.views import Views


def split_views(views: Views, holdout):
    """Hold out views by index in the ring (camera0003 -> 3); the rest train."""
    hold = sorted({i for i in holdout if 0 <= i < len(views)})
    train = [i for i in range(len(views)) if i not in hold]
    if not train:
        raise UserError(f"no training views left after holding out {list(holdout)} of {len(views)}")
    return train, hold


def crop_camera(cam: Camera, box):
    """The sub-image [x0, x1) x [y0, y1) of cam as a camera of its own (pixel centres unchanged)."""
    x0, y0, x1, y1 = box
    K = cam.K.clone()
    K[0, 2] -= x0
    K[1, 2] -= y0
    return Camera(cam.R, cam.T, K, x1 - x0, y1 - y0, cam.name)


def crop_box(alpha, margin, min_size=16):
    """Bounding box (x0, y0, x1, y1) of alpha > 0 plus margin, at least min_size (SSIM's 11 px window)."""
    H, W = alpha.shape
    ys, xs = torch.nonzero(alpha > 0, as_tuple=True)
    if len(xs) == 0:
        x0, x1, y0, y1 = W // 2, W // 2, H // 2, H // 2
    else:
        x0, x1, y0, y1 = int(xs.min()), int(xs.max()) + 1, int(ys.min()), int(ys.max()) + 1
    x0, y0, x1, y1 = max(0, x0 - margin), max(0, y0 - margin), min(W, x1 + margin), min(H, y1 + margin)

    def grow(a, b, n):  # widen [a, b) to min_size around its centre, inside [0, n)
        if b - a >= min_size or n <= min_size:
            return 0 if n <= min_size else a, n if n <= min_size else b
        a = min(max(0, (a + b) // 2 - min_size // 2), n - min_size)
        return a, a + min_size

    x0, x1 = grow(x0, x1, W)
    y0, y1 = grow(y0, y1, H)
    return max(0, x0), max(0, y0), min(W, x1), min(H, y1)


class Targets:
    """Per-scale premultiplied RGBA targets, cameras and object crop boxes for a set of views."""

    def __init__(self, views: Views, margin_px):
        self.views = views
        self.margin_px = margin_px
        rgba = views.images.permute(0, 3, 1, 2)  # (V, 4, H, W)
        self.premult = torch.cat([rgba[:, :3] * rgba[:, 3:], rgba[:, 3:]], 1)
        self._cache = {}

    def at(self, scale):
        if scale not in self._cache:
            H, W = self.views.height, self.views.width
            if scale == 1.0:
                img = self.premult
            else:  # area-average premultiplied colour, so edges blend as the renderer's do
                img = F.interpolate(self.premult, size=(round(H * scale), round(W * scale)), mode="area")
            cams = [c.scaled(scale) if scale != 1.0 else c for c in self.views.cameras]
            m = max(2, int(round(self.margin_px * scale)))
            boxes = [crop_box(img[i, 3], m) for i in range(len(cams))]
            self._cache[scale] = (img, cams, boxes)
        return self._cache[scale]


