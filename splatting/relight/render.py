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


def relight_features(normals, gloss=None, roughness=None, visibility=None):
    """The per-Gaussian channels shade_composited reads, as one (N, C) float32 table: the world
    normal (3), then the gloss's luminance (1) when there is a gloss, a per-Gaussian roughness (1)
    when given (scenes mixing materials: a bike's 0.4, a rider's 1.0), the sun visibility (1) when
    given (cast shadows).  The reflectance albedo + gloss is composited through the colour
    channels (or its own 3 features, splatting/relight/scene.py)."""
    cols = [normals.float()]
    if gloss is not None:
        cols.append((gloss.float() @ LUMA)[:, None])
    for x in (roughness, visibility):
        if x is not None:
            cols.append(x.float().reshape(-1, 1))
    return torch.cat(cols, 1).contiguous()


def shade_composited(R, feats, alpha, camera, light: Light, gloss=True, rough_channel=False, shadows=False,
                     roughness=ROUGHNESS, highlight=HIGHLIGHT):
    """Display colour of composited relight channels: R (H, W, 3) the premultiplied reflectance
    albedo + gloss, feats (H, W, C) the composited relight_features (same flags), alpha (H, W) the
    coverage of what they came from, camera the view they were rendered in (for the highlight's
    view directions) -> dict rgb (H, W, 3) premultiplied, gloss (H, W, 3) or None,
    sun_visibility (H, W, 1) or None.  Only covered pixels are shaded (an object fills a fraction
    of its image; measured 48 -> 6 ms for a bike at 256 px)."""
    H, W = alpha.shape
    pix = torch.nonzero(alpha.reshape(-1) > 1e-5).squeeze(1)
    f = feats.reshape(H * W, -1).index_select(0, pix)
    a = alpha.reshape(-1).index_select(0, pix)
    Rp = R.reshape(H * W, 3).index_select(0, pix)
    nrm, c = f[:, :3], 3
    gl, alb = None, Rp
    if gloss:
        # per pixel the gloss colour is the reflectance's tint times the composited gloss luminance
        # (exact for grey gloss: metals, clear coats)
        share = (f[:, c:c + 1] / (Rp @ LUMA.to(Rp.dtype))[:, None].clamp_min(1e-6)).clamp(0, 1)
        gl, alb, c = Rp * share, Rp * (1 - share), c + 1
    if rough_channel:
        roughness, c = (f[:, c] / a.clamp_min(1e-6)).clamp(0.05, 1.0), c + 1
    vis = (f[:, c:c + 1] / a[:, None].clamp_min(1e-6)).clamp(0, 1) if shadows else None
    view = view_directions(camera, f.dtype, pix) if gloss else None
    rgb = torch.zeros(H * W, 3, dtype=f.dtype)
    rgb.index_copy_(0, pix, shade(alb, nrm, a, light, gl, view, roughness, highlight, vis))
    full = lambda x, ch: None if x is None else torch.zeros(H * W, ch, dtype=f.dtype).index_copy_(0, pix, x).reshape(H, W, ch)  # noqa: E731
    return {"rgb": rgb.reshape(H, W, 3), "gloss": full(gl, 3), "sun_visibility": full(vis, 1)}


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
    # normal and the gloss's luminance are the features (relight_features).
    refl = albedo if gloss is None else albedo + gloss
    vis = None
    if shadows:
        from splatting.relight.shadow import sun_visibility
        vis = sun_visibility(g, light)
    feats = relight_features(normals, gloss, visibility=vis)
    gr = Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, ((refl.float() - 0.5) / C0)[:, None, :].contiguous())
    r = render_gaussians(gr, camera, features=feats, sh_degree=0, antialiased=antialiased)
    out = shade_composited(r["rgb"], r["features"], r["alpha"], camera, light, gloss is not None, False, shadows,
                           roughness, highlight)
    return {"rgb": out["rgb"], "alpha": r["alpha"], "reflectance": r["rgb"], "normal": r["features"][..., :3],
            "gloss": out["gloss"], "sun_visibility": out["sun_visibility"]}
