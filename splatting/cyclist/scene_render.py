"""Rendering a scene of several instances in one rasterization: RGB, alpha, depth, a per-pixel
label (which instance part is in front) and every instance part's amodal alpha (rendered alone).

Every Gaussian carries a slot (an int: 0 = scene / shadow, 1.. = the parts of the instances, two
per instance: bike then rider).  The image is projected, intersected and composited once for all
slots, so nearer Gaussians hide farther ones whatever instance they belong to.  The label of a
pixel is the slot with the largest summed compositing weight w = alpha T there (the weights are
recomputed from intersect()'s pair list exactly as composite() forms them), -1 where alpha <= 0.5.
Amodal alphas reuse the one projection: each slot's Gaussians are intersected and composited alone,
inside that slot's own screen box, so their total work is about one more render.
"""
import math

import numpy as np
import torch

from splatting.gaussians.sh import eval_sh
from splatting.raster.sparse import ALPHA_MAX, ALPHA_MIN, T_MIN, composite, intersect, project

MASK_ALPHA = 0.5


def pair_weights(pairs, n_pix):
    """Compositing weight w = alpha T of every (pixel, Gaussian) pair of intersect(), 0 for the
    pairs composite() drops (alpha < 1/255, past the transmittance cut-off)."""
    pix, _, _, _, alpha_raw = pairs
    ok = alpha_raw >= ALPHA_MIN
    alpha = torch.where(ok, alpha_raw.clamp_max(ALPHA_MAX), torch.zeros_like(alpha_raw))
    logm = torch.log1p(-alpha).double()
    cs = torch.cumsum(logm, 0)
    cnt = torch.bincount(pix, minlength=n_pix)
    seg_start = torch.cumsum(cnt, 0) - cnt
    base = torch.nn.functional.pad(cs, (1, 0)).index_select(0, seg_start)
    logT_incl = cs - base.index_select(0, pix)
    keep = (logT_incl >= math.log(T_MIN)) & ok
    T = torch.exp(logT_incl - logm)
    return torch.where(keep, alpha.double() * T, torch.zeros_like(T)).float()


def _crop(radii, boxes, idx):
    """Screen box (u0, v0, w, h) of the on-screen Gaussians among idx, and those Gaussians."""
    on = idx[radii.index_select(0, idx) > 0]
    if len(on) == 0:
        return None, on
    b = boxes.index_select(0, on)
    u0, u1 = int(b[:, 0].min()), int(b[:, 1].max())
    v0, v1 = int(b[:, 2].min()), int(b[:, 3].max())
    return (u0, v0, u1 - u0 + 1, v1 - v0 + 1), on


def _render_crop(m2, conics, opac, z, radii, boxes, colors, idx):
    """Composite the Gaussians idx alone inside their own screen box: the (pixel, Gaussian) lists,
    transmittance buffers and per-pixel reductions then scale with the box, not with the image
    (at 1600x900 a distant cyclist covers a few thousand of its 1.4M pixels).
    -> (crop (u0, v0, w, h), pairs, rgb, alpha, depth) or None when nothing is on screen."""
    crop, on = _crop(radii, boxes, idx)
    if crop is None:
        return None
    u0, v0, w, h = crop
    m2s = m2.index_select(0, on) - torch.tensor([u0, v0], dtype=m2.dtype)
    bs = boxes.index_select(0, on) - torch.tensor([u0, u0, v0, v0])
    cs, os_, zs, rs = (t.index_select(0, on) for t in (conics, opac, z, radii))
    pairs = intersect(m2s, cs, os_, zs, bs, rs, w, h)
    col = colors.index_select(0, on) if colors is not None else torch.zeros(len(on), 3)
    rgb, a, d = composite(m2s, cs, os_, col, zs, None, pairs, h, w)
    # pair gids index `on`: map them back to the caller's Gaussian ids
    pairs = (pairs[0], on.index_select(0, pairs[1].long()).int()) + tuple(pairs[2:])
    return crop, pairs, rgb, a, d


def _subset_alpha(m2, conics, opac, z, radii, boxes, idx, W, H, g=None, camera=None, max_px=None):
    """Alpha of the Gaussians idx alone, as (alpha crop (h, w) numpy, (u0, v0)) or None if off screen.
    max_px: when the subset's screen box is larger, it is rendered at max_px / size of the
    resolution (projected again with the scaled camera) and resampled bilinearly at the full-size
    pixel centres, so its mask edge is exact to about 1 / scale pixels; None = full resolution."""
    crop, on = _crop(radii, boxes, idx)
    if crop is None:
        return None
    u0, v0, w, h = crop
    if max_px is None or max(w, h) <= max_px:
        r = _render_crop(m2, conics, opac, z, radii, boxes, None, idx)
        (u0, v0, _, _), _, _, a, _ = r
        return a.numpy(), (u0, v0)
    f = max_px / max(w, h)
    sub = g[idx]
    cam = camera.scaled(f)
    # the full-size image's 0.3 px^2 dilation, in small pixels: the same alpha field, sampled coarser
    pm2, pc, pz, pr, pb = project(sub.means.float(), sub.quats.float(), sub.scales.float(), cam, eps2d=0.3 * f * f)
    r = _render_crop(pm2, pc, sub.opacities.float(), pz, pr, pb, None, torch.arange(len(sub)))
    if r is None:
        return None
    (lu, lv, lw, lh), _, _, a, _ = r
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
    means = g.means.float().contiguous()
    opac = g.opacities.float().contiguous()
    m2, conics, z, radii, boxes = project(means, g.quats.float(), g.scales.float(), camera)
    dirs = means - camera.centre.to(means.dtype)
    dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
    colors = eval_sh(g.sh.float(), dirs)
    rgb, alpha, depth = torch.zeros(H, W, 3), torch.zeros(H, W), torch.zeros(H, W)
    label = torch.full((H, W), -1, dtype=torch.int16)
    r = _render_crop(m2, conics, opac, z, radii, boxes, colors, torch.arange(len(means)))
    if r is not None:
        (u0, v0, w, h), pairs, rgb_c, a_c, d_c = r
        rgb[v0:v0 + h, u0:u0 + w], alpha[v0:v0 + h, u0:u0 + w], depth[v0:v0 + h, u0:u0 + w] = rgb_c, a_c, d_c
        # label: argmax over slots of the summed weights, on the covered pixels only (dense per
        # slot over the crop would be n_slots floats per pixel)
        covered = (a_c > MASK_ALPHA).reshape(-1)
        n_cov = int(covered.sum())
        if n_cov:
            wts = pair_weights(pairs, h * w)
            pix, gid = pairs[0].long(), pairs[1].long()
            ci = torch.full((h * w,), -1, dtype=torch.long)
            ci[covered] = torch.arange(n_cov)
            c = ci.index_select(0, pix)
            sel = c >= 0
            acc = torch.zeros(n_cov * n_slots)
            acc.index_add_(0, c[sel] * n_slots + slots.index_select(0, gid[sel]), wts[sel])
            lab = torch.full((h * w,), -1, dtype=torch.int16)
            lab[covered] = acc.reshape(n_cov, n_slots).argmax(1).to(torch.int16)
            label[v0:v0 + h, u0:u0 + w] = lab.reshape(h, w)
    d = torch.where(alpha > 1e-4, depth / alpha.clamp_min(1e-4), torch.zeros_like(depth))
    amodal = {}
    for s in amodal_slots:
        idx = torch.nonzero(slots == s).squeeze(1)
        amodal[s] = _subset_alpha(m2, conics, opac, z, radii, boxes, idx, W, H, g, camera, amodal_max_px) \
            if len(idx) else None
    return {"rgb": rgb.numpy(), "alpha": alpha.numpy(), "depth": d.numpy(), "label": label.numpy(),
            "amodal": amodal}
