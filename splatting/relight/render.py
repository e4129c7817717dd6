"""Rendering extra per-Gaussian feature channels (albedo, normal) through one pair list.

The rasterizer's compositing pass carries three colour channels; until `rasterize(features=...)`
lands (another branch), each 3-channel feature is one more `composite` call over the pair list
`intersect` made once, as splatting/cyclist/render.py does for instance ids.  Projection and
intersection -- most of a render -- are shared.
"""
import math

import torch

from splatting.raster.sparse import ALPHA_MAX, ALPHA_MIN, T_MIN, composite, intersect, project
from splatting.relight.shading import HIGHLIGHT, ROUGHNESS, Light, shade, view_directions


def prepare(g, camera):
    """Projection + pair list of Gaussians g for camera (no grad): what every channel reuses."""
    with torch.no_grad():
        means = g.means.float().contiguous()
        opac = g.opacities.float().contiguous()
        m2, conics, z, radii, boxes = project(means, g.quats.float(), g.scales.float(), camera)
        pairs = intersect(m2, conics, opac, z, boxes, radii, camera.width, camera.height)
    return {"m2": m2, "conics": conics, "opac": opac, "z": z, "pairs": pairs, "H": camera.height, "W": camera.width}


def composite_features(prep, features):
    """features: list of (N, 3) tensors -> list of premultiplied (H, W, 3) images, and alpha (H, W).
    Differentiable in the features (the geometry in prep is fixed)."""
    outs, alpha = [], None
    for f in features:
        img, a, _ = composite(prep["m2"], prep["conics"], prep["opac"], f.to(prep["m2"].dtype), prep["z"], None,
                              prep["pairs"], prep["H"], prep["W"])
        outs.append(img)
        alpha = a
    return outs, alpha


@torch.no_grad()
def composite_forward(prep, features):
    """Forward-only compositing of C channels at once: features (N, C) -> (H, W, C) premultiplied,
    alpha (H, W).  The same image formation as sparse._Composite.forward (the INRIA cut-offs, T
    from a float64 running sum of log(1 - a)), but the weights are found once for all channels;
    for rendering, where no backward is needed (two 3-channel composite() calls measured slower)."""
    pix, gid, dx, dy, alpha_raw = prep["pairs"]
    H, W = prep["H"], prep["W"]
    n_pix, C = H * W, features.shape[1]
    if len(pix) == 0:
        return features.new_zeros(H, W, C), features.new_zeros(H, W)
    ok = alpha_raw >= ALPHA_MIN
    a = torch.where(ok, alpha_raw.clamp_max(ALPHA_MAX), torch.zeros_like(alpha_raw))
    logm = torch.log1p(-a).double()
    cs = torch.cumsum(logm, 0)
    cnt = torch.bincount(pix, minlength=n_pix)
    base = torch.nn.functional.pad(cs, (1, 0)).index_select(0, torch.cumsum(cnt, 0) - cnt)
    logT_incl = cs - base.index_select(0, pix)
    keep = torch.nonzero((logT_incl >= math.log(T_MIN)) & ok).squeeze(1)
    pix, gid, a = pix.index_select(0, keep), gid.index_select(0, keep), a.index_select(0, keep)
    w = a * torch.exp(logT_incl.index_select(0, keep) - logm.index_select(0, keep)).to(a.dtype)
    table = torch.cat([features.to(w.dtype), torch.ones(len(features), 1, dtype=w.dtype)], 1)
    cnt = torch.bincount(pix, minlength=n_pix)
    out = torch.segment_reduce(table.index_select(0, gid) * w[:, None], "sum", lengths=cnt)
    return out[:, :C].reshape(H, W, C), out[:, C].reshape(H, W)


@torch.no_grad()
def render_relit(g, albedo, normals, camera, light: Light, gloss=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
                 shadows=False):
    """Gaussians g with per-Gaussian linear albedo (N, 3), world-frame unit normals (N, 3) and optionally
    a linear glossy colour (N, 3) under a light -> dict rgb (H, W, 3) display colour premultiplied
    (over black), alpha, albedo, gloss and normal (composited).  One rasterizer call composites
    every channel (rasterize(features=...)); the gloss reflects the sky and shows the sun's
    highlight (splatting/relight/shading.py).  shadows: the sun is blocked per Gaussian by the
    others (splatting/relight/shadow.py: one more render, from the sun)."""
    from splatting.raster.sparse import render_gaussians

    feats = [albedo, normals] + ([] if gloss is None else [gloss])
    if shadows:
        from splatting.relight.shadow import sun_visibility
        feats.append(sun_visibility(g, light)[:, None].to(albedo.dtype))
    r = render_gaussians(g, camera, features=torch.cat(feats, 1).float().contiguous(), sh_degree=0)
    out, alpha = r["features"], r["alpha"]
    alb, nrm = out[..., :3], out[..., 3:6]
    gl = out[..., 6:9] if gloss is not None else None
    vis = (out[..., -1:] / alpha[..., None].clamp_min(1e-6)).clamp(0, 1) if shadows else None
    view = view_directions(camera, alb.dtype) if gloss is not None else None
    rgb = shade(alb, nrm, alpha, light, gl, view, roughness, highlight, vis)
    return {"rgb": rgb, "alpha": alpha, "albedo": alb, "gloss": gl, "normal": nrm, "sun_visibility": vis}
