"""Appearance variety without retraining: per instance, new clothing and paint colours and a
brightness / white-balance gain, applied to the Gaussians' SH colour.

Which Gaussians a colour change touches:
- rider: each avatar Gaussian carries the clothing region (splatting.rider.body.REGIONS: skin,
  top, bottom, shoes, helmet) of its nearest rest-mesh vertex (rider_regions: the avatar's rest
  Gaussians and the rider mesh share the canonical T-pose frame; the mesh's regions are the
  ones its vertex colours were painted from);
- bike paint: the Gaussians of the frame and steering parts whose colour has the paint's hue
  (meta.json spec.frame_colour; saturation >= PAINT_MIN_SAT and hue within PAINT_HUE_DEG of it):
  tyres, metal, saddle and grips are grey and stay.  A grey paint (no hue) is left as it is.
The colour change keeps each Gaussian's shading: DC colour c -> target x lum(c) / lum(reference)
(the reference: the rider's roster colour of the region, the median paint colour of the bike),
the higher SH bands scaled by lum(target) / lum(reference).  The gain multiplies the whole
instance's evaluated colour (SH DC through the 0.5 offset, and every higher band), exactly.
All draws come from a Generator seeded with (seed, sample index, instance, a tag), so a sample's
looks are a function of (config, index) and switching appearance off changes nothing else.
"""
from dataclasses import replace
import colorsys
import math

import numpy as np
import torch

from cyclist_formats.instances import RIDER_ID
from splatting.cyclist.look_defaults import RECOLOUR, RECOLOUR_EXTRA
from splatting.gaussians.sh import C0
from splatting.rider.body import REGIONS
from splatting.rider.looks import GREY_HAIR, HAIR_COLOURS, hex_rgb, look_of

PAINT_MIN_SAT = 0.2
PAINT_HUE_DEG = 30.0
TAG = 0xA99E  # separates these draws from the sample's main stream


def _lum(rgb):
    rgb = torch.as_tensor(rgb, dtype=torch.float32)
    return rgb @ torch.tensor([0.2126, 0.7152, 0.0722])


def reference_colours(rider):
    """{region: '#rrggbb'} the rider was painted with: the roster's colours, plus the hair and bag colours
    of its look where it has hair or a bag (splatting/rider/looks.py)."""
    out = dict(rider.spec.get("colors") or {})
    if rider.regions is not None and rider.spec.get("body", "anny") == "anny":
        look = look_of(rider.spec)
        for region, key in (("hair", "hair_colour"), ("bag", "bag_colour")):
            if bool((rider.regions == REGIONS.index(region)).any()):
                out[region] = look[key]
    return out


def rider_regions(avatar_means, rider, chunk=2048):
    """(N,) int64 clothing region of each avatar Gaussian: its nearest rest-mesh vertex's."""
    if rider.regions is None:
        raise ValueError(f"rider {rider.id} has no clothing regions")
    V = rider.vertices.float()
    pts = torch.as_tensor(avatar_means).float()
    out = torch.empty(len(pts), dtype=torch.int64)
    for a in range(0, len(pts), chunk):
        out[a:a + chunk] = rider.regions[torch.cdist(pts[a:a + chunk], V).argmin(1)]
    return out


def dc_rgb(sh):
    return C0 * sh[:, 0] + 0.5


def _hue_sat(rgb):
    """Hue (degrees) and HSV saturation of (N, 3) colours in [0, 1] (clipped)."""
    c = rgb.clamp(0, 1)
    mx, mn = c.max(1).values, c.min(1).values
    sat = torch.where(mx > 1e-6, (mx - mn) / mx.clamp_min(1e-6), torch.zeros_like(mx))
    r, g, b = c.unbind(1)
    hue = torch.rad2deg(torch.atan2(math.sqrt(3.0) * (g - b), 2 * r - g - b)) % 360.0
    return hue, sat


def paint_mask(sh, ids, paint_rgb, part_ids=(1, 2)):
    """(N,) bool: frame / steering Gaussians with the paint's hue (see module docstring); all False
    for a grey paint."""
    ref_hue, ref_sat = _hue_sat(torch.as_tensor(np.asarray(paint_rgb, float), dtype=torch.float32)[None])
    on_part = torch.isin(torch.as_tensor(ids).long(), torch.tensor(part_ids))
    if float(ref_sat[0]) < PAINT_MIN_SAT:
        return torch.zeros(len(sh), dtype=torch.bool)
    hue, sat = _hue_sat(dc_rgb(sh))
    dh = (hue - ref_hue[0] + 180.0) % 360.0 - 180.0
    return on_part & (sat >= PAINT_MIN_SAT) & (dh.abs() <= PAINT_HUE_DEG)


def recolour(sh, mask, reference_rgb, target_rgb, out=None):
    """SH (N, K, 3) with the Gaussians of mask turned from the reference colour to the target,
    shading kept (module docstring).  Writes into out (a copy of sh when None) and returns it;
    unmasked rows are untouched."""
    out = sh.clone() if out is None else out
    if not bool(mask.any()):
        return out
    ref = torch.as_tensor(np.asarray(reference_rgb, float), dtype=sh.dtype)
    tgt = torch.as_tensor(np.asarray(target_rgb, float), dtype=sh.dtype)
    lref = float(_lum(ref)) + 1e-3
    rows = sh[mask]
    shade = (_lum(dc_rgb(rows).clamp_min(0)).to(sh.dtype) / lref).clamp(0.0, 2.0)
    rows[:, 0] = (shade[:, None] * tgt[None] - 0.5) / C0
    if sh.shape[1] > 1:
        rows[:, 1:] *= (float(_lum(tgt)) + 1e-3) / lref
    out[mask] = rows
    return out


def apply_gain(sh, gain):
    """SH whose evaluated colour is gain (3,) times the original's (before clamping)."""
    g = torch.as_tensor(np.asarray(gain, float), dtype=sh.dtype)
    out = sh * g
    out[:, 0] = (g * (C0 * sh[:, 0] + 0.5) - 0.5) / C0
    return out


def draw_look(a, seed, index, instance):
    """The looks of one instance under the dataset config's Appearance block a (its keep_share,
    saturation, value, regions, brightness, white_balance): {region: target rgb or None (kept)} and
    the gain (3,)."""
    rng = np.random.default_rng([int(seed), int(index), int(instance), TAG])
    look = {}
    for region in RECOLOUR:  # every region draws the same numbers whether it is kept or not
        keep = rng.uniform() < a.keep_share
        h, s, v = rng.uniform(), rng.uniform(*a.saturation), rng.uniform(*a.value)
        look[region] = None if keep or region not in a.regions else np.array(colorsys.hsv_to_rgb(h, s, v))
    b = rng.uniform(*a.brightness)
    wb = rng.uniform(-a.white_balance, a.white_balance, 3)
    gain = b * (1.0 + wb) / (1.0 + wb).mean()  # white balance tints, brightness sets the level
    # hair (a natural colour, its value varied +-20 %) and bags: a Generator of their own (look_defaults)
    rng2 = np.random.default_rng([int(seed), int(index), int(instance), TAG, 28])
    palette = HAIR_COLOURS + GREY_HAIR
    for region in RECOLOUR_EXTRA:
        keep = rng2.uniform() < a.keep_share
        if region == "hair":
            c = hex_rgb(palette[int(rng2.integers(len(palette)))]) * rng2.uniform(0.8, 1.2)
        else:
            c = np.array(colorsys.hsv_to_rgb(rng2.uniform(), rng2.uniform(*a.saturation), rng2.uniform(*a.value)))
        if region in a.regions:  # absent otherwise: a dataset's record of its looks stays as before
            look[region] = None if keep else np.clip(c, 0, 1)
    return look, gain


def apply_look(g, ids, look, gain, rider_reg=None, rider_colors=None, paint=None, paint_rgb=None):
    """Gaussians g of a posed instance (bike parts then rider, ids per Gaussian) in the look:
    rider_reg (N_rider,) regions of its rider Gaussians, rider_colors {region: '#rrggbb'} (reference_colours);
    paint (N,) bool and paint_rgb (its reference colour) for the bike."""

    sh = g.sh * 1.0  # one copy, recoloured in place (regions do not overlap)
    if rider_reg is not None:
        is_r = torch.as_tensor(ids).long() == RIDER_ID
        full_reg = torch.full((len(g),), -1, dtype=torch.int64)
        full_reg[is_r] = rider_reg
        for region in ("top", "bottom", "shoes", "helmet", "hair", "bag"):
            # a rider without the region's colour (no hair, no bag, an imported body) has nothing to turn
            if look.get(region) is not None and region in rider_colors:
                recolour(g.sh, full_reg == REGIONS.index(region), hex_rgb(rider_colors[region]), look[region], sh)
    if paint is not None and look.get("paint") is not None:
        recolour(g.sh, paint, paint_rgb, look["paint"], sh)
    return replace(g, sh=apply_gain(sh, gain))
