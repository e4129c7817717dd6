"""Relit rendering: the reflectance, normals and gloss composited by the rasterizer, shaded per pixel.

`render_relit` is one rasterizer call (rasterize(features=...), the tiled C++ compositor).
`prepare` / `composite_features` keep the pure-torch pair list for the relight fit, which needs the
backward of the features with the geometry fixed (one projection per view, reused every step).
"""
import torch

from splatting.raster.sparse import composite, intersect, project
from splatting.relight.shading import HIGHLIGHT, ROUGHNESS, Light, shade, view_directions

LUMA = torch.tensor([0.2126, 0.7152, 0.0722])  # Rec. 709 luminance of linear RGB


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
def render_relit(g, albedo, normals, camera, light: Light, gloss=None, roughness=ROUGHNESS, highlight=HIGHLIGHT,
                 shadows=False, antialiased=True):
    """Gaussians g with per-Gaussian linear albedo (N, 3), world-frame unit normals (N, 3) and optionally
    a linear glossy colour (N, 3) under a light -> dict rgb (H, W, 3) display colour premultiplied
    (over black), alpha, albedo, gloss and normal (composited).  One rasterizer call composites
    every channel (rasterize(features=...)); the gloss reflects the sky and shows the sun's
    highlight (splatting/relight/shading.py).  shadows: the sun is blocked per Gaussian by the
    others (splatting/relight/shadow.py: one more render, from the sun).  antialiased: the
    rasterizer's mip filter (keeps sub-pixel Gaussians -- spokes, cables -- their true coverage
    when rendered below their training resolution; mask IoU 0.795 -> 0.892 for a 512 px-trained
    bike at 256 px, bench/relight.py)."""
    from splatting.gaussians.container import Gaussians
    from splatting.gaussians.sh import C0
    from splatting.raster.sparse import render_gaussians

    # Channel budget (each composited channel costs the tiled compositor ~4-5 % of a render): the
    # reflectance albedo + gloss rides in the colour channels (degree-0 SH whose colour is it), the
    # normal and the gloss's luminance are the features; per pixel the gloss colour is taken as
    # the reflectance's tint times that luminance (exact for grey gloss: metals, clear coats).
    refl = albedo if gloss is None else albedo + gloss
    feats = [normals] + ([] if gloss is None else [(gloss @ LUMA.to(gloss.dtype))[:, None]])
    if shadows:
        from splatting.relight.shadow import sun_visibility
        feats.append(sun_visibility(g, light)[:, None].to(albedo.dtype))
    gr = Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, ((refl.float() - 0.5) / C0)[:, None, :].contiguous())
    r = render_gaussians(gr, camera, features=torch.cat(feats, 1).float().contiguous(), sh_degree=0,
                         antialiased=antialiased)
    out, alpha = r["features"], r["alpha"]
    H, W = alpha.shape
    # shade the covered pixels only (an object fills a fraction of its image; measured 48 -> 6 ms
    # for a bike at 256 px)
    pix = torch.nonzero(alpha.reshape(-1) > 1e-5).squeeze(1)
    f, a = out.reshape(H * W, -1).index_select(0, pix), alpha.reshape(-1).index_select(0, pix)
    R = r["rgb"].reshape(H * W, 3).index_select(0, pix)
    nrm = f[:, :3]
    if gloss is not None:
        share = (f[:, 3:4] / (R @ LUMA.to(R.dtype))[:, None].clamp_min(1e-6)).clamp(0, 1)
        gl, alb = R * share, R * (1 - share)
    else:
        gl, alb = None, R
    vis = (f[:, -1:] / a[:, None].clamp_min(1e-6)).clamp(0, 1) if shadows else None
    view = view_directions(camera, f.dtype, pix) if gloss is not None else None
    rgb = torch.zeros(H * W, 3, dtype=f.dtype)
    rgb[pix] = shade(alb, nrm, a, light, gl, view, roughness, highlight, vis)
    full = lambda x, c: None if x is None else torch.zeros(H * W, c, dtype=f.dtype).index_copy_(0, pix, x).reshape(H, W, c)  # noqa: E731
    return {"rgb": rgb.reshape(H, W, 3), "alpha": alpha, "reflectance": r["rgb"], "normal": out[..., :3],
            "gloss": full(gl, 3), "sun_visibility": full(vis, 1)}
