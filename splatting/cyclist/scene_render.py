"""Rendering a scene of several instances in one rasterization: RGB, alpha, depth, a per-pixel
label (which instance part is in front) and every instance part's amodal alpha (rendered alone).

Every Gaussian carries a slot (an int: 0 = scene / shadow, 1.. = the parts of the instances, two
per instance: bike then rider).  The image is rasterized once for all slots with the slots'
one-hot as feature channels, so nearer Gaussians hide farther ones whatever instance they belong
to, and each feature channel is that slot's summed compositing weight w = alpha T per pixel.  The
label of a pixel is the slot with the largest weight, -1 where alpha <= 0.5.  Amodal alphas:
each slot's Gaussians as if rasterized alone, from the same pass (the rasterizer's `groups`: the
alpha a Gaussian has at a pixel is computed once for the image and for its slot, and a pixel's
list is walked past the image's cut-off only for slots still open there).  With amodal_max_px
(street scenes) a slot whose screen box is larger is instead rasterized alone (opacity only)
through a camera cropped to its box, at max_px / size of the resolution.

Screen boxes come from slot_boxes(): each Gaussian's projected mean with a bound on its 3-sigma
radius (conservative, a few multiply-adds per Gaussian) instead of a second EWA projection of
every Gaussian in torch (the rasterizer's C++ projects them anyway).
"""
import math

import numpy as np
import torch

from splatting.raster.camera import Camera
from splatting.raster.api import EPS2D, rasterize

MASK_ALPHA = 0.5
BOX_MARGIN_PX = 2.0  # >= 3 sqrt(eps2d = 0.3) = 1.64 px: the screen-space low-pass widens every splat


def cropped_camera(camera, crop):
    """The same camera seeing only the pixels [u0, u0 + w) x [v0, v0 + h): the principal point moves."""
    u0, v0, w, h = crop
    K = camera.K.clone()
    K[0, 2] -= u0
    K[1, 2] -= v0
    return Camera(camera.R, camera.T, K, int(w), int(h), camera.name)


def slot_boxes(means, scales, slots, n_slots, camera, near=0.01, eps2d=EPS2D):
    """Conservative screen box (u0, v0, w, h) of every slot's Gaussians, clipped to the image; None
    where the slot has no Gaussian in front of the near plane or is off screen.  Each Gaussian
    reaches at most 3 sigma_max |J| <= 3 sigma_max f / z sqrt(1 + (x/z)^2 + (y/z)^2) pixels from its
    projected mean (J the EWA Jacobian), plus the low-pass margin (3 sqrt(eps2d), eps2d a number or
    one per Gaussian; at least BOX_MARGIN_PX); the rasterizer culls means at z <= near, so they are
    left out here too."""
    H, W = camera.height, camera.width
    p = means.float() @ camera.R.float().T + camera.T.float()
    z = p[:, 2]
    ok = z > near
    zs = torch.where(ok, z, torch.ones_like(z))
    K = camera.K.double()
    x, y = p[:, 0] / zs, p[:, 1] / zs
    u, v = float(K[0, 0]) * x + float(K[0, 2]), float(K[1, 1]) * y + float(K[1, 2])
    sc = scales.float()
    smax = torch.maximum(torch.maximum(sc[:, 0], sc[:, 1]), sc[:, 2])  # elementwise: max(1) over 3 columns is slower
    r = 3.0 * smax / zs * torch.sqrt(1 + x * x + y * y)
    # + 0.5 px for float32 rounding of pixel coordinates up to ~1e4
    e = float(eps2d.max()) if torch.is_tensor(eps2d) else float(eps2d)
    margin = max(BOX_MARGIN_PX, 3.0 * math.sqrt(max(e, 0.0)))  # a wider low-pass widens every splat more
    ru, rv = float(K[0, 0]) * r + margin + 0.5, float(K[1, 1]) * r + margin + 0.5
    inf = torch.full_like(u, math.inf)
    idx = slots.long()
    lo = lambda a: torch.full((n_slots,), math.inf, dtype=a.dtype).scatter_reduce(0, idx, a, "amin")  # noqa: E731
    lu, lv = lo(torch.where(ok, u - ru, inf)), lo(torch.where(ok, v - rv, inf))
    hu, hv = -lo(torch.where(ok, -(u + ru), inf)), -lo(torch.where(ok, -(v + rv), inf))
    out = []
    for s in range(n_slots):
        if not math.isfinite(float(lu[s])):
            out.append(None)
            continue
        # pixel i is touched when its centre i + 0.5 lies inside [min, max]
        u0, u1 = max(0, math.ceil(float(lu[s]) - 0.5)), min(W - 1, math.floor(float(hu[s]) - 0.5))
        v0, v1 = max(0, math.ceil(float(lv[s]) - 0.5)), min(H - 1, math.floor(float(hv[s]) - 0.5))
        out.append((u0, v0, u1 - u0 + 1, v1 - v0 + 1) if u1 >= u0 and v1 >= v0 else None)
    return out


def union(boxes):
    boxes = [b for b in boxes if b is not None]
    if not boxes:
        return None
    u0, v0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
    u1, v1 = max(b[0] + b[2] for b in boxes), max(b[1] + b[3] for b in boxes)
    return u0, v0, u1 - u0, v1 - v0


def _subset_alpha(t, idx, camera, crop, max_px=None, antialiased=False, eps2d=EPS2D):
    """Alpha of the Gaussians idx of the tensors t alone inside crop, as (alpha (h, w) numpy,
    (u0, v0)).  max_px: when the crop is larger, it is rendered at max_px / size of the resolution
    (the full-size eps2d px^2 low-pass in small pixels: the same alpha field, sampled coarser) and
    resampled bilinearly at the full-size pixel centres, so its mask edge is exact to about
    1 / scale pixels; None = full resolution."""
    means, quats, scales, opac = (x.index_select(0, idx) for x in t)
    aa = antialiased.index_select(0, idx) if torch.is_tensor(antialiased) else antialiased
    eps2d = eps2d.index_select(0, idx) if torch.is_tensor(eps2d) else eps2d
    dc = torch.zeros(len(idx), 1, 3)  # colour is not needed: alpha only
    u0, v0, w, h = crop
    cam = cropped_camera(camera, crop)
    if max_px is None or max(w, h) <= max_px:
        return rasterize(means, quats, scales, opac, dc, cam, sh_degree=0, antialiased=aa,
                         eps2d=eps2d)["alpha"].numpy(), (u0, v0)
    f = max_px / max(w, h)
    small = cam.scaled(f)
    # each Gaussian's own low-pass, in the small pixels (a number or per Gaussian alike)
    a = rasterize(means, quats, scales, opac, dc, small, sh_degree=0, eps2d=eps2d * f * f, antialiased=aa)["alpha"]
    lw, lh = small.width, small.height
    xs = f * (torch.arange(w, dtype=torch.float32) + 0.5) - 0.5  # full-size pixel centres, small-pixel coords
    ys = f * (torch.arange(h, dtype=torch.float32) + 0.5) - 0.5
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


def _argmax_channels(feat):
    """(C, h, w) contiguous -> (h, w) index of the largest channel (first on ties, like argmax)."""
    best, arg = feat[0].clone(), torch.zeros(feat.shape[1:], dtype=torch.int16)
    for c in range(1, feat.shape[0]):
        more = feat[c] > best
        best = torch.where(more, feat[c], best)
        arg.masked_fill_(more, c)
    return arg


@torch.no_grad()
def render_scene(g, slots, n_slots, camera, amodal_slots=(), amodal_max_px=None, features=None, antialiased=False,
                 eps2d=EPS2D):
    """Gaussians g (N), slots (N,) long in 0..n_slots-1, camera -> dict:
    rgb (H, W, 3) premultiplied, alpha (H, W), depth (H, W) expected camera z (0 where alpha is 0),
    label (H, W) int16 (-1 where alpha <= 0.5), amodal {slot: (alpha crop, (u0, v0)) or None}
    (amodal_max_px: see _subset_alpha), boxes [slot box (u0, v0, w, h) or None] (slot_boxes).
    features: optional (N, F) channels composited in the same rasterization (relit datasets:
    splatting/cyclist/scene_relit.py); then also "features" (h, w, n_slots + F): the slots' weights and
    the features inside "crop" (u0, v0, w, h), the union of the slot boxes (None: nothing seen).
    antialiased: rasterize's mip filter, for all Gaussians (bool) or those of a (N,) bool mask (the
    bikes whose parts were trained with it: BikeModel.antialiased), amodal alphas included.
    eps2d: rasterize's low-pass, a number or one per Gaussian (each model its own: BikeModel.eps2d,
    RiderAvatar.eps2d), amodal alphas included."""
    H, W = camera.height, camera.width
    t = (g.means.float(), g.quats.float(), g.scales.float(), g.opacities.float())
    boxes = slot_boxes(t[0], t[2], slots, n_slots, camera, eps2d=eps2d)
    # numpy's zeros are calloc'ed pages (zeroed when first touched): the full-size images cost
    # only where the crop is written; everything per pixel is computed inside the crop
    rgb, alpha, d = np.zeros((H, W, 3), np.float32), np.zeros((H, W), np.float32), np.zeros((H, W), np.float32)
    label = np.full((H, W), -1, np.int16)
    crop = union(boxes)
    groups, one_pass, feats = None, [], None
    if crop is not None:
        u0, v0, w, h = crop
        onehot = torch.zeros(len(g), n_slots)
        onehot[torch.arange(len(g)), slots.long()] = 1.0
        if features is not None:  # as parts: the compositor reads both without a concatenated table
            onehot = [onehot, features.float()]
        # the amodal alphas from the same pass, except for parts larger than amodal_max_px (those
        # are rendered alone at reduced resolution, _subset_alpha)
        one_pass = [s for s in amodal_slots if boxes[s] is not None
                    and (amodal_max_px is None or max(boxes[s][2:]) <= amodal_max_px)]
        group_of = torch.full((n_slots,), -1, dtype=torch.int32)
        for k, s in enumerate(one_pass):
            group_of[s] = k
        if one_pass:
            groups = (group_of[slots.long()], len(one_pass))
        out = rasterize(*t, g.sh.float(), cropped_camera(camera, crop), features=onehot, groups=groups,
                        antialiased=antialiased, eps2d=eps2d)
        feats = out["features"]
        a_c = out["alpha"]
        sl = np.s_[v0:v0 + h, u0:u0 + w]
        rgb[sl], alpha[sl] = out["rgb"].numpy(), a_c.numpy()
        d[sl] = torch.where(a_c > 1e-4, out["depth"] / a_c.clamp_min(1e-4), torch.zeros_like(a_c)).numpy()
        # the features are (H, W, C) pixel-major: reduce over the slots' channels channel-major
        lab = _argmax_channels(feats[..., :n_slots].permute(2, 0, 1).contiguous())
        lab[a_c <= MASK_ALPHA] = -1
        label[sl] = lab.numpy()
    amodal = {}
    for s in amodal_slots:
        if boxes[s] is None or not bool((slots == s).any()):
            amodal[s] = None
        elif s in one_pass:  # the slot's box, inside the union crop
            bu, bv, bw, bh = boxes[s]
            u, v = bu - crop[0], bv - crop[1]
            amodal[s] = out["group_alpha"][one_pass.index(s), v:v + bh, u:u + bw].numpy(), (bu, bv)
        else:
            amodal[s] = _subset_alpha(t, torch.nonzero(slots == s).squeeze(1), camera, boxes[s], amodal_max_px,
                                      antialiased, eps2d)
    L = {"rgb": rgb, "alpha": alpha, "depth": d, "label": label, "amodal": amodal, "boxes": boxes}
    if features is not None:
        L.update(features=feats, crop=crop)
    return L
