"""A dataset scene with relit instances: the same one rasterization as render_scene, the relight
channels riding along as features.

The relit parts' colour channels are black and their reflectance (albedo + gloss) and
relight_features are composited as features; the baked parts (slot 0: the contact shadows and a
3DGS background scene) keep their colour and have zero features.  So the composited rgb is the
baked parts' share alone, and per pixel the relit share is shade_composited() of the features
over the relit coverage (the summed weights of slots 1..: render_scene's slot channels), added
to it.  Geometry, and so alpha, depth, labels, boxes and amodal masks, is the baked render's:
only the RGB differs (tests/test_dataset_lighting.py).
"""
import numpy as np
import torch

from splatting.cyclist.scene_render import cropped_camera, render_scene
from splatting.gaussians.container import Gaussians
from splatting.gaussians.sh import C0
from splatting.raster.api import EPS2D
from splatting.relight.render import shade_composited


@torch.no_grad()
def render_scene_relit(parts, channels, slots, n_slots, camera, light, shadows, amodal_slots=(), amodal_max_px=None,
                       antialiased=False, eps2d=EPS2D):
    """parts: list of Gaussians, of which the first len(channels) are relit with channels
    [(reflectance (n, 3), relight_features(normals, gloss, roughness, visibility, sky_visibility) (n, C))]
    (one layout for all); the rest baked.  Slot 0 must hold the baked parts only.  -> render_scene's
    dict and relit_cover (H, W): the relit parts' coverage.  antialiased: as render_scene's (a mask
    over the concatenated parts); eps2d: as render_scene's (a number or one per Gaussian)."""
    C = channels[0][1].shape[1] if channels else 0
    gs, feats = [], []
    for i, g in enumerate(parts):
        if i < len(channels):
            refl, f = channels[i]
            black = torch.full((len(g), 1, 3), -0.5 / C0)  # colour 0: the relit share comes from the features
            gs.append(Gaussians(g.means, g.quats, g.log_scales, g.opacity_logits, black))
            feats.append(torch.cat([refl.float(), f.float()], 1))
        else:
            gs.append(g)
            feats.append(torch.zeros(len(g), 3 + C))
    L = render_scene(Gaussians.cat(gs), slots, n_slots, camera, amodal_slots, amodal_max_px, features=torch.cat(feats),
                     antialiased=antialiased, eps2d=eps2d)
    F, crop = L.pop("features"), L.pop("crop")
    L["relit_cover"] = np.zeros(L["alpha"].shape, np.float32)  # the relit parts' coverage, full frame
    if crop is not None and channels:
        u0, v0, w, h = crop
        cover = F[..., 1:n_slots].sum(-1)
        L["relit_cover"][v0:v0 + h, u0:u0 + w] = cover.numpy()
        rgb = shade_composited(F[..., n_slots:n_slots + 3], F[..., n_slots + 3:], cover, cropped_camera(camera, crop),
                               light, gloss=True, rough_channel=True, shadows=shadows, sky_channel=True)
        L["rgb"][v0:v0 + h, u0:u0 + w] += rgb.numpy()
    return L
