"""Per-image light in datasets (`lighting:` in the config; docs/cyclists_and_datasets.md).

mode baked (the default): the Gaussians' trained colour, as before; nothing here runs and the
dataset's bytes are those of a config without the section.  mode relit: every image draws a sun
(elevation, azimuth, strength, a slight tint) and a sky from the config's ranges, the bikes and
riders are shaded under it from their relight channels (albedo, gloss, normal per Gaussian:
docs/relighting.md), each with its own cast shadows (`shadows`), and on photo and scene
backgrounds their shadows fall on the ground away from the sun (beside the baked contact shadow).  The light is drawn from its own generator
seeded with (seed, index, TAG), so a sample stays a function of (config, index) and the other
draws are those of the baked set.  The image record gets "lighting": the sun used, in the world
and the camera frame.  Only the RGB changes: masks, boxes, depth and keypoints come from the
same rasterization as in baked mode.
"""
import os

import numpy as np
import torch

from cyclist_formats import bike_folder
from cyclist_formats.errors import UserError
from splatting.bike.model import present_parts
from splatting.cyclist.assets import bike_dir, has_trained_gaussians
from splatting.cyclist.scene_relit import render_scene_relit
from splatting.dataset.backgrounds import contact_shadows
from splatting.gaussians.sh import C0
from splatting.raster.api import EPS2D, render_gaussians
from splatting.relight.avatar import cyclist_static, RelightableAvatar
from splatting.relight.bike import RelightableBike
from splatting.relight.render import leading_view_normals, relight_features
from splatting.relight.shading import Light, SKY_TINT, srgb_decode, sun_direction
from splatting.relight import shadow  # shadow.X at call time: the maps are swapped in tests
from splatting.rider.avatar import PLY_NAME, SKINNING_NAME

TAG = 0x5A11  # separates the light's draws from the sample's other streams
# the section's fields, defaults and ranges: splatting/dataset/config_models.py (Lighting)


def _err(field, msg):
    return UserError(f"config field 'lighting.{field}': {msg}")


def relit(cfg):
    """Whether the DatasetConfig draws a light per image (its config.json then keeps the section:
    generate.config_record leaves it out in baked mode, so a baked set's record is what it was
    before the section existed, and such sets resume)."""
    return cfg.lighting.mode == "relit"


def check_assets(cfg):
    """Relit mode: every bike and rider of the (asset-resolved) config must carry relight channels;
    one UserError naming the first asset without them and the command that makes them."""
    if not relit(cfg):
        return
    if cfg.synthetic_assets == "always":
        raise _err("mode", "relit needs trained assets with relight channels, but synthetic_assets is 'always' "
                           "(stand-ins carry no albedo or normals)")
    for b in cfg.bikes:
        d = bike_dir(b, cfg.bikes_root)
        if not has_trained_gaussians(d):
            raise _err("mode", f"relit: bike {b!r} has no trained Gaussians in {d}/gaussians (stand-ins carry no "
                               f"relight channels); train it with `python -m splatting train`, then relight-fit")
        for p in present_parts(os.path.join(d, "gaussians")):
            ply = bike_folder.gaussians_path(d, p)
            if not os.path.isfile(bike_folder.relight_path(ply)):
                raise _err("mode", f"relit: bike {b!r} part {p!r} has no relight channels "
                                   f"({bike_folder.relight_path(ply)}); make them with `python -m splatting relight-fit "
                                   f"--views {os.path.join(d, 'views', p)}`")
    for r in cfg.riders:
        folder = os.path.join(cfg.riders_root, r)
        ply = os.path.join(folder, PLY_NAME)
        if not (os.path.isfile(ply) and os.path.isfile(os.path.join(folder, SKINNING_NAME))):
            raise _err("mode", f"relit: rider {r!r} has no trained avatar in {folder} (the mesh stand-in carries no "
                               f"relight channels); build it with `python -m splatting rider-avatar --id {r} --out {folder}`")
        if not os.path.isfile(bike_folder.relight_path(ply)):
            raise _err("mode", f"relit: rider {r!r} has no relight channels ({bike_folder.relight_path(ply)}); make them "
                               f"with `python -m splatting relight-fit --views {os.path.join(folder, 'views')} --ply {ply}`")


def draw_light(lc, seed, index):
    """The sun and sky of sample `index` under the config's Lighting block lc: (Light, its record
    without the camera frame)."""
    rng = np.random.default_rng([int(seed), int(index), TAG])
    el, az = rng.uniform(*lc.elevation_deg), rng.uniform(*lc.azimuth_deg)
    strength, s = rng.uniform(*lc.strength), rng.uniform(*lc.sky)
    tint = rng.uniform(1.0 - lc.sun_tint, 1.0, 3)
    tint = tint / tint.max()
    d = sun_direction(el, az)  # world: Y up; azimuth 0 = towards +X (where a bike at heading 0 rides)
    sky = tuple(float(c * s) for c in SKY_TINT)
    light = Light(sun_direction=d, sun_colour=tuple(float(x) for x in tint), sun_strength=float(strength), sky=sky)
    rec = {"mode": "relit", "sun_direction_world": list(d), "elevation_deg": float(el), "azimuth_deg": float(az),
           "sun_strength": float(strength), "sun_colour": list(light.sun_colour), "sky": list(sky),
           "shadows": bool(lc.shadows)}
    return light, rec


class _Channels:
    """Per-process cache (kept on the dataset's Assets): RelightableBike / RelightableAvatar by id."""

    def __init__(self):
        self.bikes, self.riders, self.statics = {}, {}, {}

    def bike(self, assets, bike):
        if bike not in self.bikes:
            self.bikes[bike] = RelightableBike.of(assets.bikes[bike], bike_dir(bike, assets.cfg.bikes_root))
        return self.bikes[bike]

    def rider(self, assets, rider):
        if rider not in self.riders:
            self.riders[rider] = RelightableAvatar.of(assets.avatars[rider], os.path.join(assets.cfg.riders_root, rider))
        return self.riders[rider]

    def static(self, assets, bike, rider):
        """The pose-invariant channels of a (bike, rider) cyclist, bike parts then rider: albedo,
        gloss, roughness and sky visibility, concatenated once rather than per image."""
        key = (bike, rider)
        if key not in self.statics:
            self.statics[key] = cyclist_static(self.bike(assets, bike),
                                               self.rider(assets, rider) if rider is not None else None)
        return self.statics[key]


def _srgb_decode(c):
    return srgb_decode(c)


class RelitSample:
    """The relit side of one dataset sample, fed by generate.make_sample at four points: posed
    groups (normals), instances (looks, level of detail, cast shadows), the render and the
    shadows on the ground; record() is the image record's "lighting"."""

    def __init__(self, cfg, index, assets):
        lc = cfg.lighting
        self.light, self.rec = draw_light(lc, cfg.seed, index)
        self.shadows = lc.shadows
        if getattr(assets, "relight_channels", None) is None:
            assets.relight_channels = _Channels()
        self.assets, self.ch = assets, assets.relight_channels
        self.normals, self.normal_view, self.channels = {}, {}, {}

    def posed(self, bike, rider, js, poses):
        """After Cyclist.pose of the instances js (poses (B, 8)): their world normals (bike parts then
        rider, the CyclistFrame's order); the rider's skinning rotations are the recorder's."""
        rb = self.ch.bike(self.assets, bike)
        ra = self.ch.rider(self.assets, rider) if rider is not None else None
        rot = self.assets.avatars[rider].rotations if rider is not None else None
        for b, j in enumerate(js):
            pose = torch.as_tensor(np.asarray(poses[b]), dtype=torch.float64)
            n = rb.posed_normals(pose)
            self.normal_view[j] = rb.posed_normal_view(pose)  # the bike's view-dependent normals, or None
            if ra is not None:
                n = torch.cat([n, ra.posed_normals(rot[b])])
            self.normals[j] = n

    def instance(self, k, bike, rider, trained, looked, g, idx, camera, antialiased=False, eps2d=EPS2D):
        """Instance k's channels: trained = its posed Gaussians, looked = after the appearance look
        (the look's change of each Gaussian's colour goes into its albedo, in linear light),
        g = what is rendered (after the level of detail, idx its rows of looked, or None), seen by
        camera (a bike fitted with view-dependent normals turns them to it).  antialiased, eps2d:
        how g is drawn (rasterize's; the bike's mip filter and each model's low-pass), which its
        shadow map draws it with too."""
        alb, gl, rough, sky = self.ch.static(self.assets, bike, rider)
        nrm = self.normals[k]
        if self.normal_view.get(k) is not None:  # the bike's Gaussians come first
            nrm = leading_view_normals(nrm, self.normal_view[k], trained.means, camera)
        if looked is not trained:
            before = _srgb_decode((C0 * trained.sh[:, 0] + 0.5).float()).clamp_min(1e-3)
            after = _srgb_decode((C0 * looked.sh[:, 0] + 0.5).float())
            alb = (alb * (after / before).clamp(0, 20)).clamp(0, 1)
        if idx is not None:
            alb, gl, rough, sky, nrm = (x.index_select(0, idx) for x in (alb, gl, rough, sky, nrm))
        vis = None
        if self.shadows:
            vis = shadow.sun_visibility(g, self.light, antialiased=antialiased, eps2d=eps2d)
        self.channels[k] = (alb + gl, relight_features(nrm, gl, rough, vis, sky))

    def cast_shadows(self, rgb, L, camera, footprints, heights, opacity):
        """The final image (H, W, 3) uint8 with the instances' shadows cast on the ground away from the
        sun (backgrounds.contact_shadows with the sun) darkening what is not an instance: the
        background, the contact shadows, a 3DGS scene.  A layer of its own rather than Gaussians in
        the scene's rasterization, so it cannot sort in front of a wheel and move a label: the
        labels stay the baked render's."""
        g = contact_shadows(footprints, opacity, sun=self.light, heights=heights)
        a = render_gaussians(g, camera, sh_degree=0)["alpha"].numpy()
        keep = 1.0 - a * (1.0 - np.clip(L["relit_cover"], 0.0, 1.0))
        out = rgb.copy()
        m = keep < 1.0
        out[m] = np.clip(np.round(rgb[m].astype(np.float32) * keep[m][:, None]), 0, 255).astype(np.uint8)
        return out

    def render(self, parts, slots, n_slots, camera, amodal_slots, amodal_max_px, antialiased=False, eps2d=EPS2D):
        """render_scene's layers with the instances (the first len(self.channels) parts) relit."""
        ch = [self.channels[k] for k in range(len(self.channels))]
        return render_scene_relit(parts, ch, slots, n_slots, camera, self.light, self.shadows, amodal_slots,
                                  amodal_max_px, antialiased, eps2d)

    def record(self, camera):
        R = camera.R.double().numpy()
        d = R @ np.asarray(self.rec["sun_direction_world"], float)
        return dict(self.rec, sun_direction_camera=[float(x) for x in d], camera_frame="opencv (x right, y down, z forward)")
