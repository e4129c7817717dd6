"""Rendering a scene of several instances in one rasterization: RGB, alpha, depth, a per-pixel
label (which instance part is in front) and every instance part's amodal alpha (rendered alone).

Every Gaussian carries a slot (an int: 0 = scene / shadow, 1.. = the parts of the instances, two
per instance: bike then rider).  The image is rasterized once for all slots with the slots'
one-hot as feature channels, so nearer Gaussians hide farther ones whatever instance they belong
to, and each feature channel is that slot's summed compositing weight w = alpha T per pixel.  The
label of a pixel is the slot with the largest weight, -1 where alpha <= 0.5.  Amodal alphas:
each slot's Gaussians rasterized alone through a camera cropped to that slot's screen box (from
one projection of the whole scene), so their total work is about one more render.
"""
import numpy as np
import torch

from splatting.raster.camera import Camera
from splatting.raster.sparse import project, rasterize

MASK_ALPHA = 0.5


def _crop(radii, boxes, idx):
    """Screen box (u0, v0, w, h) of the on-screen Gaussians among idx, and those Gaussians."""
    on = idx[radii.index_select(0, idx) > 0]
    if len(on) == 0:
        return None, on
    b = boxes.index_select(0, on)
    u0, u1 = int(b[:, 0].min()), int(b[:, 1].max())
    v0, v1 = int(b[:, 2].min()), int(b[:, 3].max())
    return (u0, v0, u1 - u0 + 1, v1 - v0 + 1), on


def cropped_camera(camera, crop):
    """The same camera seeing only the pixels [u0, u0 + w) x [v0, v0 + h): the principal point moves."""
    u0, v0, w, h = crop
    K = camera.K.clone()
    K[0, 2] -= u0
    K[1, 2] -= v0
    return Camera(camera.R, camera.T, K, int(w), int(h), camera.name)


def _render(g, idx, camera, features=None, eps2d=0.3):
    """Rasterize the Gaussians idx of g through camera (tiled back end) -> the rasterize() dict."""
    sub = g[idx]
    return rasterize(sub.means.float(), sub.quats.float(), sub.scales.float(), sub.opacities.float(),
                     sub.sh.float(), camera, eps2d=eps2d, features=None if features is None else features[idx])


def _subset_alpha(g, idx, camera, radii, boxes, max_px=None):
    """Alpha of the Gaussians idx alone, as (alpha crop (h, w) numpy, (u0, v0)) or None if off screen.
    max_px: when the subset's screen box is larger, it is rendered at max_px / size of the
    resolution and resampled bilinearly at the full-size pixel centres, so its mask edge is exact
    to about 1 / scale pixels; None = full resolution."""
    crop, on = _crop(radii, boxes, idx)
    if crop is None:
        return None
    u0, v0, w, h = crop
    if max_px is None or max(w, h) <= max_px:
        return _render(g, on, cropped_camera(camera, crop))["alpha"].numpy(), (u0, v0)
    f = max_px / max(w, h)
    cam = camera.scaled(f)
    # the full-size image's 0.3 px^2 dilation, in small pixels: the same alpha field, sampled coarser
    pm2, pc, pz, pr, pb = project(g.means[on].float(), g.quats[on].float(), g.scales[on].float(), cam, eps2d=0.3 * f * f)
    lcrop, lon = _crop(pr, pb, torch.arange(len(on)))
    if lcrop is None:
        return None
    lu, lv, lw, lh = lcrop
    a = _render(g, on[lon], cropped_camera(cam, lcrop), eps2d=0.3 * f * f)["alpha"]
    xs = f * (torch.arange(u0, u0 + w, dtype=torch.float32) + 0.5) - 0.5 - lu  # low-res pixel-centre coords
    ys = f * (torch.arange(v0, v0 + h, dtype=torch.float32) + 0.5) - 0.5 - lv
    gx = xs / max(lw - 1, 1) * 2 - 1
    gy = ys / max(lh - 1, 1) * 2 - 1
    grid = torch.stack(torch.meshgrid(gy, gx, indexing="ij")[::-1], -1)[None]
    up = torch.nn.functional.grid_sample(a[None, None], grid, mode="bilinear", padding_mode="zeros",
                                         align_corners=True)[0, 0]
    return up.numpy(), (u0, v0)


def full_frame(crop, W, H):
    """(alpha crop, (u0, v0)) -> (H, W) float32 (zeros for None)."""
    out = np.zeros((H, W), np.float32)
    if crop is not None:
        a, (u0, v0) = crop
        out[v0:v0 + a.shape[0], u0:u0 + a.shape[1]] = a
    return out


@torch.no_grad()
def render_scene(g, slots, n_slots, camera, amodal_slots=(), amodal_max_px=None):
    """Gaussians g (N), slots (N,) long in 0..n_slots-1, camera -> dict:
    rgb (H, W, 3) premultiplied, alpha (H, W), depth (H, W) expected camera z (0 where alpha is 0),
    label (H, W) int16 (-1 where alpha <= 0.5), amodal {slot: (alpha crop, (u0, v0)) or None}
    (amodal_max_px: see _subset_alpha)."""
    H, W = camera.height, camera.width
    _, _, _, radii, boxes = project(g.means.float(), g.quats.float(), g.scales.float(), camera)
    rgb, alpha, depth = torch.zeros(H, W, 3), torch.zeros(H, W), torch.zeros(H, W)
    label = torch.full((H, W), -1, dtype=torch.int16)
    crop, on = _crop(radii, boxes, torch.arange(len(g)))
    if crop is not None:
        u0, v0, w, h = crop
        onehot = torch.zeros(len(g), n_slots)
        onehot[torch.arange(len(g)), slots.long()] = 1.0
        out = _render(g, on, cropped_camera(camera, crop), features=onehot)
        a_c = out["alpha"]
        rgb[v0:v0 + h, u0:u0 + w], alpha[v0:v0 + h, u0:u0 + w], depth[v0:v0 + h, u0:u0 + w] = out["rgb"], a_c, out["depth"]
        lab = out["features"].argmax(-1).to(torch.int16)
        lab[a_c <= MASK_ALPHA] = -1
        label[v0:v0 + h, u0:u0 + w] = lab
    d = torch.where(alpha > 1e-4, depth / alpha.clamp_min(1e-4), torch.zeros_like(depth))
    amodal = {}
    for s in amodal_slots:
        idx = torch.nonzero(slots == s).squeeze(1)
        amodal[s] = _subset_alpha(g, idx, camera, radii, boxes, amodal_max_px) if len(idx) else None
    return {"rgb": rgb.numpy(), "alpha": alpha.numpy(), "depth": d.numpy(), "label": label.numpy(),
            "amodal": amodal}
