"""Per-instance accessories: a helmet on or off, a hair style, a backpack on or off, drawn per dataset
instance by the look sampler (the dataset config's `appearance.helmet_share`, `bag_share`,
`hair_styles`; each null = the rider's own look, as drawn per rider id by splatting/rider/looks.py).

The body and its accessories are separate sets.  `body.redress` puts the same body (the same vertices,
faces and skinning weights) into the drawn look: looks.dress appends the accessory surfaces, each
skinned to its bone (helmet shell, hair shell, bun and ponytail weighted 1 on the head joint: rigid on
the head; the backpack taking its nearest torso vertex's weights: it bends with the back), and paints
what an accessory changes on the body (hair on the scalp wherever no helmet covers it, the backpack's
straps on the jersey).  Which Gaussians an instance gets:

- mesh avatar (no trained avatar, or synthetic_assets: always): Gaussians on the redressed mesh's
  vertices (assets.mesh_avatar), so body and accessories are exactly those of a roster rider with
  that look, every accessory removable: the body under it is the mesh's own skin.
- trained avatar with a bare base (`rider-avatar --bare`: the same rider trained bald, without helmet
  or bag, in <avatar>/bare/): the base's Gaussians, its scalp recoloured where the draw paints hair,
  plus every accessory of the draw as a Gaussian set on the accessory's mesh vertices.  Every instance
  of the rider uses it (its own look too), so no look is drawn by another model than the rest.
- trained avatar without a base: its Gaussians hold the look it was trained in.  Under a helmet the
  training views never saw the skull, under a backpack never the back, so a trained accessory cannot
  be taken off (the body there is missing, not hidden), and its hair is in its Gaussians.  It can only
  gain what it was trained without: a helmet, a backpack, as sets.  `check` refuses, before any work,
  a config that asks such an avatar for more.

What a trained avatar (or bare base) wears is read from its folder's look.json (rider/avatar_look.py,
written by `rider-avatar`), not from the roster: an avatar trained before the looks existed, or before
its roster entry changed, wears another look than its roster entry now draws.  Its look is also the
rider's own look for the fields a config leaves null.  A trained avatar without the record is refused
when any field is drawn (with all three null nothing here runs, and such avatars work as before).

The draw's own Generator is seeded with (seed, sample index, instance, TAG, 29), so a sample's
accessories are a function of (config, index), and the colour draws (appearance.draw_look) are
unchanged by them.  Without a bare base, an instance whose draw is its rider's own look gets the
rider's own avatar.
"""
import os
from dataclasses import replace

import numpy as np
import torch

from cyclist_formats.errors import UserError
from cyclist_formats.instances import RIDER_ID
from splatting.cyclist.appearance import TAG, recolour, rider_regions
from splatting.cyclist.assets import mesh_avatar, mesh_gaussians, trained_avatar_folder
from splatting.gaussians.container import Gaussians
from splatting.rider.avatar import RiderAvatar
from splatting.rider.avatar_look import LOOK_NAME, read_look
from splatting.rider.body import REGIONS, redress
from splatting.rider.looks import BARE, hex_rgb, look_of
from splatting.rider.roster import get_spec

FIELDS = ("helmet", "hair", "bag")  # the look fields a dataset draws per instance
# what a trained avatar can gain (looks.dress's part names): the body under them stays as trained
ADDABLE = {"helmet": "helmet", "bag": "backpack"}


def varies(a):
    """Whether the config's Appearance block a draws any accessory per instance."""
    return a.helmet_share is not None or a.bag_share is not None or a.hair_styles is not None


def draw(a, seed, index, instance, own):
    """The accessories {helmet: bool, hair: style, bag: 'none' | 'backpack'} of one instance under
    Appearance block a; own: what the rider wears (Assets.own: its trained avatar's record, else its
    roster look), kept for every field left null.
    Three numbers are drawn whichever fields are set, so setting one leaves the others' draws."""
    rng = np.random.default_rng([int(seed), int(index), int(instance), TAG, 29])
    u_helmet, u_bag, u_hair = rng.uniform(), rng.uniform(), rng.uniform()
    return {"helmet": own["helmet"] if a.helmet_share is None else bool(u_helmet < a.helmet_share),
            "hair": own["hair"] if a.hair_styles is None else a.hair_styles[int(u_hair * len(a.hair_styles))],
            "bag": own["bag"] if a.bag_share is None else ("backpack" if u_bag < a.bag_share else "none")}


def own_choice(spec):
    """The roster rider's own accessories (its look's FIELDS)."""
    look = look_of(spec)
    return {k: look[k] for k in FIELDS}


def trained_choice(folder, rider_id, bare=False):
    """The accessories the trained avatar (bare: base) in folder wears, from its look.json; UserError,
    naming the folder and how to rebuild it, when it has no record or the record is another rider's."""
    rec = read_look(folder)
    build = f"`python -m splatting rider-avatar --id {rider_id}{' --bare' if bare else ''} --out {folder}`"
    if rec is None:
        raise UserError(f"rider {rider_id!r}: the trained avatar in {folder} has no {LOOK_NAME} (built before avatars "
                        f"recorded their look), so what it wears is unknown; move it away and rebuild it ({build}), "
                        f"or leave appearance.helmet_share, bag_share and hair_styles null")
    if rec["rider"] != rider_id or rec["look"] is None:
        what = f"rider {rec['rider']!r}" if rec["rider"] != rider_id else "no roster look"
        raise UserError(f"rider {rider_id!r}: {os.path.join(folder, LOOK_NAME)} records {what}; rebuild it ({build})")
    return {k: rec["look"][k] for k in FIELDS}


def check(cfg):
    """Before any work: every rider of the (asset-resolved) config can wear what the Appearance block
    draws (module docstring); one UserError naming the field, the rider and why."""
    a = cfg.appearance
    if not varies(a):
        return
    for r in cfg.riders:
        spec = get_spec(r)
        if spec.get("body", "anny") != "anny":
            raise UserError(f"appearance: rider {r!r} is a {spec.get('body')} body without a roster look; per-instance "
                            f"accessories (helmet_share, bag_share, hair_styles) need anny roster riders")
        folder = trained_avatar_folder(r, cfg.riders_root, cfg.synthetic_assets)
        if folder is None:
            continue  # a mesh avatar: every draw can be worn
        base = trained_avatar_folder(r, cfg.riders_root, cfg.synthetic_assets, bare=True)
        if base is not None:  # a bare base takes every draw, if it is bare
            worn = trained_choice(base, r, bare=True)
            if worn != BARE:
                raise UserError(f"rider {r!r}: the bare base in {base} was trained wearing {worn}, not {BARE}; rebuild "
                                f"it (`python -m splatting rider-avatar --id {r} --bare --out {base}`)")
            continue
        own = trained_choice(folder, r)
        why = None
        if a.hair_styles is not None and list(a.hair_styles) != [own["hair"]]:
            why = ("appearance.hair_styles", f"its hair ({own['hair']}) is in its trained Gaussians")
        elif a.helmet_share is not None and own["helmet"] and a.helmet_share < 1:
            why = ("appearance.helmet_share", "it was trained wearing a helmet (the skull under it was never seen)")
        elif a.bag_share is not None and own["bag"] != "none" and a.bag_share < 1:
            why = ("appearance.bag_share", "it was trained wearing a backpack (the back under it was never seen)")
        if why:
            raise UserError(f"{why[0]}: rider {r!r} has a trained avatar in {folder}, and {why[1]}; train its bare base "
                            f"(`python -m splatting rider-avatar --id {r} --bare --out {folder}/bare`), use mesh avatars "
                            f"(synthetic_assets: always) or leave the field null")


def dressed_avatar(avatar, body, choice, trained=None, n=None, bare=None):
    """(RiderAvatar, Rider) of a rider wearing choice (draw's dict): avatar and body are the rider's own
    (assets.load_avatar), trained None for a mesh avatar, else what the trained avatar wears (its
    trained_choice), bare its accessory-free trained base (RiderAvatar of `rider-avatar --bare`) or None.
    Mesh avatar: the redressed mesh's (n: its subsample).  Bare base: its Gaussians, the scalp recoloured
    where the draw paints hair on it, plus every accessory of the draw as a set.  Trained without a base:
    its Gaussians plus the sets it lacks (ADDABLE).  A set: Gaussians on the accessory's vertices with
    their colours and skinning weights."""
    dressed = redress(body, **choice)
    if trained is None:
        return mesh_avatar(dressed, n), dressed
    if bare is not None:
        base, add = _scalp_painted(bare, dressed), list(dressed.accessory_parts)
    else:
        own = trained
        add = [ADDABLE[k] for k in ADDABLE if choice[k] != own[k]]
        if choice["hair"] != own["hair"] or any(part not in dressed.accessory_parts for part in add):
            raise UserError(f"rider {body.id}: a trained avatar without a bare base can gain a helmet or a backpack, "
                            f"not lose one or change its hair ({own} -> {choice})")
        base = avatar
    if not add:
        return base, dressed
    idx = torch.cat([torch.arange(*dressed.accessory_parts[p]) for p in add])
    sets = mesh_gaussians(dressed, idx, len(dressed.vertices))  # the full mesh avatar's spacing
    out = RiderAvatar(Gaussians.cat([base.gaussians, sets]), torch.cat([base.weights, dressed.weights[idx]]),
                      base.rest_joints.clone(), base.rider_id, base.method, base.eps2d)
    return out, dressed


def _scalp_painted(bare, dressed):
    """The bare (bald) base avatar with the Gaussians on the scalp the dressed look paints as hair turned
    from skin to the hair colour, shading kept (appearance.recolour): a buzz cut, and the scalp under a
    hair shell, as looks.dress paints them on the mesh."""
    n = dressed.body_vertex_count
    body = replace(dressed, vertices=dressed.vertices[:n], regions=dressed.regions[:n])  # the skin, not the shells
    hair = rider_regions(bare.gaussians.means, body) == REGIONS.index("hair")
    if not bool(hair.any()):
        return bare
    skin, colour = hex_rgb(dressed.spec["colors"]["skin"]), hex_rgb(look_of(dressed.spec)["hair_colour"])
    g = replace(bare.gaussians, sh=recolour(bare.gaussians.sh, hair, skin, colour))
    return RiderAvatar(g, bare.weights, bare.rest_joints, bare.rider_id, bare.method, bare.eps2d)


def swap_rider(frame, avatar, rotations, root):
    """The CyclistFrame with its rider Gaussians replaced by avatar's posed with (1, 24, 3, 3) local
    rotations and (1, 3) root (what the frame's own rider was posed with: RecordingAvatar.last)."""
    out = avatar.pose_tensors(rotations, root)
    ag = avatar.gaussians
    rider = Gaussians(out["means"][0], out["quats"][0], ag.log_scales, ag.opacity_logits, out["sh"][0])
    is_bike = frame.ids != RIDER_ID
    g = Gaussians.cat([frame.gaussians[is_bike], rider])
    ids = torch.cat([frame.ids[is_bike], torch.full((len(ag),), RIDER_ID, dtype=frame.ids.dtype)])
    return replace(frame, gaussians=g, ids=ids)
