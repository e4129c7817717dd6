"""Rendering extra per-Gaussian feature channels (albedo, normal) through one pair list.

The rasterizer's compositing pass carries three colour channels; until `rasterize(features=...)`
lands (another branch), each 3-channel feature is one more `composite` call over the pair list
`intersect` made once, as splatting/cyclist/render.py does for instance ids.  Projection and
intersection -- most of a render -- are shared.
"""
import torch

from splatting.raster.sparse import composite, intersect, project
from splatting.relight.shading import Light, shade


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
def render_relit(g, albedo, normals, camera, light: Light):
    """Gaussians g with per-Gaussian linear albedo (N, 3) and world-frame unit normals (N, 3) under a
    light -> dict rgb (H, W, 3) display colour premultiplied (over black), alpha, albedo, normal."""
    prep = prepare(g, camera)
    (alb, nrm), alpha = composite_features(prep, [albedo, normals])
    return {"rgb": shade(alb, nrm, alpha, light), "alpha": alpha, "albedo": alb, "normal": nrm}
