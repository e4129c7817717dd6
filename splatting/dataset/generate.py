"""One dataset sample as a pure function of (config, sample index).

All randomness comes from numpy's Generator seeded with [seed, index] and is drawn in a fixed
order (assets, poses and placements, camera, background), and everything after that is single-threaded
torch on CPU, so a sample renders to the same bytes whenever and in whichever worker it runs.
That is what makes a killed-and-resumed run identical to an uninterrupted one.
"""
import functools
import json
import os
from dataclasses import dataclass, field

import numpy as np
import torch

from cyclist_formats.atomic import atomic_path, write_json
from cyclist_formats.instances import RIDER_ID
from splatting.bike.model import KEYPOINTS as BIKE_KEYPOINTS
from splatting.cyclist import accessories, appearance, lod
from splatting.cyclist.assets import bike_dir, load_avatar, load_bike, trained_avatar_folder
from splatting.cyclist.compose import Cyclist, frame_eps2d
from splatting.cyclist.render import keypoint_visibility, orbit_camera, over, project_points, to_uint8
from splatting.cyclist.scene_render import MASK_ALPHA, render_scene, union
from splatting.dataset import camera_presets, kitti, lighting, png
from splatting.dataset.backgrounds import contact_shadows, generated, load_scene, photo
from splatting.dataset.config_models import POSE_KEYS, require_config
from splatting.dataset.frames import contact, output as frames_output
from splatting.dataset.frames.placement import draw_frame
from splatting.dataset.frames.sample import FrameSample
from splatting.dataset.labels import BoxMask, annotation, vehicle_class
from splatting.dataset.person_keypoints import COCO17_TOLERANCE_M, PersonKeypoints, RecordingAvatar
from splatting.dataset.street import draw_street
from splatting.gaussians.container import Gaussians
from splatting.raster.api import EPS2D, eps2d_cat
from splatting.rider.avatar import RiderAvatar


# Riders in a drawn look (per-instance accessories) kept per process: a least-recently-used cache over
# all riders.  Each is a whole avatar (240k Gaussians at SH degree 3 with skinning weights: ~80 MB; the
# demo's 15k at degree 0 with its redressed body: 5.7 MB) and a rider has up to 20 looks (2 x 5 x 2),
# so unbounded a worker could hold ~1.6 GB per rider; 8 hold ~0.65 GB at most.  An evicted one is
# rebuilt from its key when drawn again, to the same Gaussians (its build draws nothing), in ~0.25 s.
DRESSED_CACHE = 8


@dataclass
class Dressed:
    """A rider in a drawn look (Assets.dressed): its avatar, its redressed body, and what was computed
    of it once per bike (Assets' lod_orders, looks, label_prep entries), evicted with it."""
    avatar: object
    body: object
    derived: dict = field(default_factory=dict)


class Assets:
    """Per-process cache of loaded bikes, rider avatars, body keypoint regressors and the 3DGS scene."""

    def __init__(self, cfg, log=None):
        self.cfg, self.log = require_config(cfg, "Assets"), log
        self.bikes, self.avatars, self.cyclists, self.persons = {}, {}, {}, {}
        self._scene = None
        self.lod_orders, self.bodies, self.looks, self.label_prep = {}, {}, {}, {}
        self.bare_bases = {}  # rider id -> its bare base RiderAvatar (rider-avatar --bare) or None
        self.owns = {}  # rider id -> what its own avatar wears (own())
        # functools' LRU (C implementation) over the dressed riders, per Assets: key -> Dressed
        self.dressed = functools.lru_cache(maxsize=DRESSED_CACHE)(self._dress)

    def cyclist(self, bike, rider):
        key = (bike, rider)
        if key not in self.cyclists:
            c = self.cfg
            if bike not in self.bikes:
                self.bikes[bike] = load_bike(bike_dir(bike, c.bikes_root), c.synthetic_assets,
                                             c.synthetic_gaussians_per_part, log=self.log)
            av = None
            if rider is not None:
                if rider not in self.avatars:
                    avatar, body = load_avatar(rider, c.riders_root, c.synthetic_assets,
                                               c.rider_gaussians, log=self.log)
                    self.bodies[rider] = body
                    # the recorder hands the IK's pose to the COCO-17 mesh keypoints
                    self.avatars[rider] = RecordingAvatar(avatar)
                    if c.keypoints.person == "coco17":
                        self.persons[rider] = PersonKeypoints(body)
                av = self.avatars[rider]
            self.cyclists[key] = Cyclist(self.bikes[bike], av, c.ik_iterations)
        return self.cyclists[key]

    def bare(self, rider):
        """The rider's bare base RiderAvatar (`rider-avatar --bare`), loaded once, or None."""
        if rider not in self.bare_bases:
            c = self.cfg
            folder = trained_avatar_folder(rider, c.riders_root, c.synthetic_assets, bare=True)
            self.bare_bases[rider] = None if folder is None else RiderAvatar.load(folder)
        return self.bare_bases[rider]

    def own(self, rider):
        """What the rider's own avatar wears (accessories.FIELDS), the draw's value of a null field: a
        trained avatar's, from its look.json (accessories.trained_choice), unless a bare base dresses
        every instance; else the roster look's."""
        if rider not in self.owns:
            c = self.cfg
            folder = trained_avatar_folder(rider, c.riders_root, c.synthetic_assets)
            roster = folder is None or self.bare(rider) is not None
            self.owns[rider] = (accessories.own_choice(self.bodies[rider].spec) if roster
                                else accessories.trained_choice(folder, rider))
        return self.owns[rider]

    def wearing(self, rider, choice):
        """The key of the rider wearing choice (accessories.draw's dict): the rider id itself for what
        its own avatar wears (unless it has a bare base), else (rider, helmet, hair, bag), its avatar
        built now or still in the dressed cache.  The rider's own avatar must be loaded (cyclist())."""
        if self.bare(rider) is None and choice == self.own(rider):
            return rider
        key = (rider, *(choice[k] for k in accessories.FIELDS))
        self.dressed(key)
        return key

    def _dress(self, key):
        """The Dressed of a wearing() key (accessories.dressed_avatar), a function of the key alone."""
        rider, choice, c = key[0], dict(zip(accessories.FIELDS, key[1:])), self.cfg
        trained = None if trained_avatar_folder(rider, c.riders_root, c.synthetic_assets) is None else self.own(rider)
        return Dressed(*accessories.dressed_avatar(self.avatars[rider], self.bodies[rider], choice, trained,
                                                   c.rider_gaussians, self.bare(rider)))

    def model(self, rider):
        """(avatar, body) of a rider key: a rider id's own (body None for no rider), or a dressed one's."""
        if isinstance(rider, tuple):
            d = self.dressed(rider)
            return d.avatar, d.body
        return self.avatars.get(rider), self.bodies.get(rider)

    def _once(self, table, bike, rider, make):
        """table's entry of (bike, rider), made once: a dressed rider's is kept with it in the dressed
        cache (evicted with it), any other in the Assets' table of that name."""
        if isinstance(rider, tuple):
            store, key = self.dressed(rider).derived, (table, bike)
        else:
            store, key = getattr(self, table), (bike, rider)
        if key not in store:
            store[key] = make()
        return store[key]

    def lod_order(self, bike, rider, g, ids):
        """The level-of-detail ranking of a (bike, rider)'s posed Gaussians (pose does not change
        opacities or scales, so it is computed once)."""
        return self._once("lod_orders", bike, rider, lambda: lod.ranking(g, ids))

    def look_inputs(self, bike, rider, frame):
        """What appearance.apply_look needs of a (bike, rider), computed once: the rider Gaussians'
        clothing regions and colours, the bike's paint Gaussians and reference colour."""
        def make():
            out = {}
            avatar, body = self.model(rider)
            # an imported rider has no clothing regions (its clothes are its own textures): the gain alone applies
            if body is not None and body.regions is not None:
                out.update(rider_reg=appearance.rider_regions(avatar.gaussians.means, body),
                           rider_colors=appearance.reference_colours(body))
            paint = (self.meta(bike).get("spec") or {}).get("frame_colour")
            if paint is not None:
                m = appearance.paint_mask(frame.gaussians.sh, frame.ids, paint)
                if bool(m.any()):
                    ref = appearance.dc_rgb(frame.gaussians.sh[m]).median(0).values
                    out.update(paint=m, paint_rgb=ref.numpy())
            return out
        return self._once("looks", bike, rider, make)

    def meta(self, bike):
        return getattr(self.bikes[bike], "meta", None) or {}

    def label_inputs(self, bike, rider, frame):
        """What the labels need of a (bike, rider)'s Gaussians apart from their posed means,
        computed once (pose changes neither opacities, scales nor ids): extent_prep(), and the
        indices of the dense (opacity >= 0.1) bike and rider Gaussians for the projected extents."""
        def make():
            g = frame.gaussians
            dense = (g.opacities >= 0.1).numpy()
            is_r = (frame.ids == RIDER_ID).numpy()
            return {"extent": extent_prep(g), "bike": np.flatnonzero(dense & ~is_r), "rider": np.flatnonzero(dense & is_r)}
        return self._once("label_prep", bike, rider, make)

    def scene(self):
        if self._scene is None:
            b = self.cfg.backgrounds
            self._scene = load_scene(b.scene_ply, b.scene_transform)
        return self._scene


def draw(cfg, index):
    """The random choices of sample `index`: instances (asset ids, pose (8,)), camera, background."""
    rng = np.random.default_rng([cfg.seed, index])
    if cfg.mode == "street":
        cam = camera_presets.resolve(cfg.camera)
        instances, dropped = draw_street(cfg, rng, cam)
        camera = {"preset": cam["preset"]}
    elif cfg.mode == "frames":  # a KITTI frame: its own camera and image (splatting/dataset/frames)
        instances, dropped, camera = draw_frame(cfg, rng, index)
        return {"instances": instances, "dropped": dropped, "camera": camera,
                "background": {"kind": "frame", "frame": camera["frame"]}}
    else:
        bike = cfg.bikes[int(rng.integers(len(cfg.bikes)))]
        rider = cfg.riders[int(rng.integers(len(cfg.riders)))] if cfg.mode == "cyclist" else None
        pose = [float(rng.uniform(*getattr(cfg.pose, k))) for k in POSE_KEYS]
        v = cfg.views
        camera = {"preset": "ring", "azimuth_deg": float(rng.uniform(*v.azimuth_deg)),
                  "elevation_deg": float(rng.uniform(*v.elevation_deg)),
                  "distance_m": float(rng.uniform(*v.distance_m)),
                  "jitter": (rng.uniform(-1, 1, 3) * v.centre_jitter_m).tolist()}
        instances, dropped = [{"kind": "cyclist" if rider else "parked", "bike": bike, "rider": rider, "pose": pose}], 0
    kind = cfg.backgrounds.kinds[int(rng.integers(len(cfg.backgrounds.kinds)))]
    bg_seed = int(rng.integers(2 ** 31))
    still_signals(cfg, index, instances)
    return {"instances": instances, "dropped": dropped, "camera": camera,
            "background": {"kind": kind, "seed": bg_seed}}


STILL_SIGNALS = ("left", "right", "stop", "one_handed")


def still_signals(cfg, index, instances):
    """Arm signals in still sets (sequence.still_signal_share, default 0: nothing drawn, no `signal`
    key, bytes as before): each rider shows one of STILL_SIGNALS, uniformly, with that probability.
    Its own Generator, so the sample's other draws are unchanged."""
    share = float(cfg.sequence.still_signal_share)
    if share <= 0:
        return
    rng = np.random.default_rng([cfg.seed, index, 2029, 7])
    for inst in instances:
        if inst["rider"] is not None:
            u, k = float(rng.uniform()), int(rng.integers(len(STILL_SIGNALS)))
            inst["signal"] = STILL_SIGNALS[k] if u < share else "none"


def background(kind, seed, size):
    """(size, size, 3) float32 in [0, 1], generated from the seed (nothing downloaded)."""
    return generated(kind, seed, size, size)


def _ry(deg):
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def extent_prep(g, min_opacity=0.1):
    """(indices of the Gaussians with opacity >= min_opacity, their radii (n, 1) float64) for
    extent_box: they depend on opacities and scales alone, which posing leaves unchanged."""
    o = g.opacities
    keep = torch.nonzero(o >= min_opacity).squeeze(1)
    oo = o[keep].double().clamp_max(0.99)
    r = (g.scales[keep].max(1).values.double() * torch.sqrt(torch.clamp_min(2 * torch.log(2 * oo), 0.0)))[:, None]
    return keep, r


def extent_box(g, pose, min_opacity=0.1, prep=None):
    """The posed instance's 3D box in its heading frame -> {bottom_centre (world), heading_deg, h, w, l}.
    Gaussians with opacity >= min_opacity count, each widened by the radius where it alone renders
    alpha 0.5 (sigma sqrt(2 ln 2o) of its largest scale; none below opacity 0.5): the extent of
    the masks, whose threshold is alpha 0.5.  prep: extent_prep(g, min_opacity), when known."""
    keep, r = prep if prep is not None else extent_prep(g, min_opacity)
    m = g.means.index_select(0, keep).double()
    t = torch.tensor(pose[5:8], dtype=torch.float64)
    R = _ry(pose[3])
    local = (m - t) @ torch.from_numpy(R)  # R^T (p - t) for row vectors
    lo, hi = (local - r).min(0).values.numpy(), (local + r).max(0).values.numpy()
    bottom = np.array([(lo[0] + hi[0]) / 2, lo[1], (lo[2] + hi[2]) / 2])
    return {"bottom_centre": (R @ bottom + np.asarray(pose[5:8], float)).tolist(), "heading_deg": float(pose[3]),
            "h": float(hi[1] - lo[1]), "w": float(hi[2] - lo[2]), "l": float(hi[0] - lo[0])}


def projected_extent(points, cam):
    uv, z = project_points(points, cam)
    ok = z > 1e-3
    if not ok.any():
        return [0.0, 0.0, 0.0, 0.0]
    uv = uv[ok]
    return [float(uv[:, 0].min()), float(uv[:, 1].min()), float(uv[:, 0].max()), float(uv[:, 1].max())]


def _height_px(box, cam):
    """Screen height of an extent_box (its bottom centre's camera depth; upright instances)."""
    z = float((cam.R.double() @ torch.tensor(box["bottom_centre"], dtype=torch.float64) + cam.T.double())[2])
    return lod.height_px(box["h"], z, cam.K[1, 1]) if z > 1e-3 else float("inf")


def box_mask(label, box, slot):
    """BoxMask of the pixels labelled slot inside box (u0, v0, w, h): a slot's pixels lie in its box."""
    u0, v0, w, h = box
    return BoxMask(label[v0:v0 + h, u0:u0 + w] == slot, u0, v0)


def amodal_mask(entry, box, visible):
    """BoxMask in box of a render_scene amodal entry ((alpha crop, (u0, v0)) inside box, or None)
    thresholded at MASK_ALPHA, united with the visible mask (same box)."""
    m = visible.crop.copy()
    if entry is not None:
        a, (au, av) = entry
        u, v = au - box[0], av - box[1]
        m[v:v + a.shape[0], u:u + a.shape[1]] |= a > MASK_ALPHA
    return BoxMask(m, visible.u0, visible.v0)


def mask_or(a, b):
    """Union of two BoxMasks of the same box."""
    return BoxMask(a.crop | b.crop, a.u0, a.v0)


def over_in_box(layers, background, box):
    """over() where the render has pixels (box; outside it alpha is 0, so the background shows
    unchanged: the same bytes as over() on the whole image, for 1/10 of the work).  background:
    float in [0, 1] or uint8 (a photo: read as x / 255)."""
    photo_bytes = background.dtype == np.uint8
    out = background.copy() if photo_bytes else to_uint8(background)
    if box is not None:
        u0, v0, w, h = box
        sl = np.s_[v0:v0 + h, u0:u0 + w]
        bg = background[sl].astype(np.float32) / 255.0 if photo_bytes else background[sl]
        out[sl] = over({"rgb": layers["rgb"][sl], "alpha": layers["alpha"][sl]}, bg)
    return out


def make_sample(cfg, index, assets, drawn=None, camera=None, look_index=None):
    """Render sample `index` -> (rgb uint8 (H, W, 3), image record, annotations, extras)
    extras: {"depth": (H, W) float32, "kitti": [objects], "calib": {...}}.
    A sequence frame (splatting/dataset/sequences) passes its own draw, the ego camera of the
    frame and the index its looks are drawn with (the sequence's, so they stay across frames)."""
    require_config(cfg, "make_sample")
    d = draw(cfg, index) if drawn is None else drawn
    street = cfg.mode == "street"
    fs = FrameSample(cfg, d, index) if cfg.mode == "frames" else None
    relit = lighting.RelitSample(cfg, index, assets) if lighting.relit(cfg) else None  # None: baked colour
    kp_cfg, lab = cfg.keypoints, cfg.labels
    # instances of one (bike, rider) are posed in one batch: the IK's cost is mostly per iteration,
    # not per pose.  The groups follow from the draw, so a sample stays a function of its index.
    groups = {}
    for j, inst in enumerate(d["instances"]):
        groups.setdefault((inst["bike"], inst["rider"]), []).append(j)
    frames = [None] * len(d["instances"])
    look_at = index if look_index is None else look_index
    # per instance: the accessories drawn (None: not drawn), the key of its rider's avatar in assets
    worn, rkeys = [None] * len(frames), [i["rider"] for i in d["instances"]]
    for (bike, rider), js in groups.items():
        cyc = assets.cyclist(bike, rider)
        if fs is not None:  # both tyres on the frame's road plane (frames.contact)
            for j in js:
                d["instances"][j]["pose"] = contact.seat(cyc.bike.keypoints, d["instances"][j]["pose"])
        sig = [d["instances"][j].get("signal", "none") for j in js]  # arm signals (sequences; stills optional)
        wheel = [d["instances"][j].get("wheel_deg") for j in js]  # sequences: the wheels' rolling angle
        feet = [d["instances"][j].get("foot_down", "none") for j in js]  # sequences: a foot on the road at a stop
        posed = cyc.pose(torch.tensor([d["instances"][j]["pose"] for j in js], dtype=torch.float64),
                         signals=sig if rider is not None and any(x != "none" for x in sig) else None,
                         wheel_deg=wheel if all(w is not None for w in wheel) else None,
                         feet=feet if rider is not None and any(x != "none" for x in feet) else None)
        people = [None] * len(js)
        if rider is not None:
            if kp_cfg.person == "coco17":
                rot, root = assets.avatars[rider].last
                people = list(assets.persons[rider].posed(rot, root).numpy())
            else:
                people = [f.rider_joints for f in posed]
        rot, root = assets.avatars[rider].last if rider is not None else (None, None)  # the group's rider pose
        for b, (j, f, person) in enumerate(zip(js, posed, people)):
            if rider is not None and accessories.varies(cfg.appearance):  # drawn per instance, as the colours
                worn[j] = accessories.draw(cfg.appearance, cfg.seed, look_at, j, assets.own(rider))
                rkeys[j] = assets.wearing(rider, worn[j])
                if rkeys[j] != rider:  # the same pose, the redressed rider's Gaussians
                    f = accessories.swap_rider(f, assets.model(rkeys[j])[0], rot[b:b + 1], None if root is None else root[b:b + 1])
            frames[j] = (d["instances"][j], f, person)
        if relit is not None:
            relit.posed(bike, rider, js, [f.pose for f in posed])

    if street:
        spec = camera_presets.resolve(cfg.camera)
        cam = camera_presets.street_camera(spec) if camera is None else camera
    elif fs is not None:
        cam = fs.camera()
    else:
        g = frames[0][1].gaussians
        lo, hi = g.means.min(0).values, g.means.max(0).values
        centre = (0.5 * (lo + hi)).double() + torch.tensor(d["camera"]["jitter"], dtype=torch.float64)
        cam = orbit_camera(d["camera"]["azimuth_deg"], d["camera"]["elevation_deg"], d["camera"]["distance_m"],
                           centre.tolist(), cfg.image_size, cfg.views.focal_px)
    H, W = cam.height, cam.width
    bg_kind = d["background"]["kind"]

    parts, slots, boxes, keeps, aa, eps = [], [], [], [], [], []
    lod_cfg = cfg.lod
    # lod.level_keep (the cyclist layer) takes {below_px, keep} mappings, look_defaults.DEFAULT_LEVELS' shape
    lod_levels = [lv.model_dump() for lv in lod_cfg.levels]
    looks, scan_parts = [], []
    for k, (inst, frame, _) in enumerate(frames):
        g = frame.gaussians
        slot = torch.where(frame.ids == RIDER_ID, 2 * k + 2, 2 * k + 1).long()
        prep = assets.label_inputs(inst["bike"], rkeys[k], frame)
        boxes.append(extent_box(g, inst["pose"], prep=prep["extent"]))  # labels come from the full model, LOD or not
        idx = None
        if cfg.appearance.enabled:
            look, gain = appearance.draw_look(cfg.appearance, cfg.seed, look_at, k)
            g = appearance.apply_look(g, frame.ids, look, gain, **assets.look_inputs(inst["bike"], rkeys[k], frame))
            looks.append({"colours": {r: None if c is None else [round(float(x), 4) for x in c] for r, c in look.items()},
                          "gain": [round(float(x), 4) for x in gain]})
        looked = g
        if lod_cfg.enabled:
            keeps.append(lod.level_keep(_height_px(boxes[-1], cam), lod_levels))
            if keeps[-1] < 1.0:
                g, idx = lod.reduce(g, assets.lod_order(inst["bike"], rkeys[k], g, frame.ids), keeps[-1],
                                    lod_cfg.compensate, frame.ids)
                slot = slot.index_select(0, idx)
        # a bike whose parts were trained antialiased is drawn so (its rider and the rest as trained)
        bike_trained_aa = bool(assets.bikes[inst["bike"]].antialiased)
        bike_aa = (frame.ids != RIDER_ID) & bike_trained_aa
        aa.append(bike_aa if idx is None else bike_aa.index_select(0, idx))
        # and each model with the low-pass it was trained with (bike and rider may differ)
        cyc = assets.cyclists[(inst["bike"], inst["rider"])]
        e = frame_eps2d(frame.ids, cyc.bike, cyc.avatar if rkeys[k] == inst["rider"] else assets.model(rkeys[k])[0])
        if fs is not None:  # the full model, for the LiDAR scan
            scan_parts.append((frame.gaussians, e, bike_aa if bike_trained_aa else False))
        eps.append((len(g), e if idx is None or not torch.is_tensor(e) else e.index_select(0, idx)))
        if relit is not None:  # its sun's shadow map draws the instance as the view does
            relit.instance(k, inst["bike"], inst["rider"], frame.gaussians, looked, g, idx, cam,
                           aa[-1] if bike_trained_aa else False, eps[-1][1])
        parts.append(g)
        slots.append(slot)
    b = cfg.backgrounds
    ground_shadows = bool(b.shadow and bg_kind in ("images", "scene", "frame") and frames)  # the contact shadow, and relit the sun's
    if ground_shadows:
        feet = [(inst["pose"][5], inst["pose"][7], inst["pose"][3], bx["l"], bx["w"]) for (inst, _, _), bx in zip(frames, boxes)]
        if fs is not None and cfg.insert.look.cast_shadow:  # frames: the sun's shadow in the render, so
            # the frame's depth hides it too (baked: the config's sun; relit: the sample's)
            sun = fs.sun() if relit is None else relit.light
            sh = contact_shadows(feet, b.shadow_opacity, sun=sun, heights=[bx["h"] for bx in boxes])
        else:
            sh = contact_shadows(feet, b.shadow_opacity)
        parts.append(sh)
        slots.append(torch.zeros(len(sh), dtype=torch.long))
    if bg_kind == "scene":
        sc = assets.scene()
        parts.append(sc)
        slots.append(torch.zeros(len(sc), dtype=torch.long))
    n_slots = 2 * len(frames) + 1
    if parts:
        aa += [torch.zeros(len(p), dtype=torch.bool) for p in parts[len(aa):]]  # shadows, scene: as trained
        aa = torch.cat(aa) if any(bool(m.any()) for m in aa) else False
        eps = eps2d_cat(eps + [(len(p), EPS2D) for p in parts[len(eps):]])  # shadows, scene: rasterize's default
        if relit is None:
            L = render_scene(Gaussians.cat(parts), torch.cat(slots), n_slots, cam, range(1, n_slots), cfg.amodal_max_px,
                             antialiased=aa, eps2d=eps)
        else:
            L = relit.render(parts, torch.cat(slots), n_slots, cam, range(1, n_slots), cfg.amodal_max_px, aa, eps)
    else:
        L = {"rgb": np.zeros((H, W, 3), np.float32), "alpha": np.zeros((H, W), np.float32),
             "depth": np.zeros((H, W), np.float32), "label": np.full((H, W), -1, np.int16), "amodal": {},
             "boxes": []}
    bg_rec = dict(d["background"])
    kp_alpha, kp_depth = L["alpha"], L["depth"]
    if fs is not None:  # the frame's real objects hide what is behind them; then its look
        kp_alpha, kp_depth = fs.occlude(L, union(L.get("boxes", [])))
        rgb, bg_rec["look"] = fs.composite(L, union(L.get("boxes", [])), [(i["pose"][5], i["pose"][7]) for i, _, _ in frames])
    elif bg_kind == "images":
        bg, rec = photo(b.image_files, d["background"]["seed"], W, H)
        bg_rec.update(rec)
    elif bg_kind == "scene":
        bg = np.zeros((H, W, 3), np.float32)
    else:
        bg = generated(bg_kind, d["background"]["seed"], W, H)
    if fs is None:
        rgb = over_in_box(L, bg, union(L.get("boxes", [])))
    if relit is not None and ground_shadows and fs is None:
        rgb = relit.cast_shadows(rgb, L, cam, feet, [bx["h"] for bx in boxes], b.shadow_opacity)

    K, R, T = cam.K.double().numpy(), cam.R.double().numpy(), cam.T.double().numpy()
    # the depth test compares with the surface seen through the keypoint's whole pixel, whose
    # footprint (z / f metres) adds to every tolerance: a far cyclist's pixel spans centimetres
    px = 1.0 / float(K[0, 0])
    anns, kitti_objs = [], []
    for k, (inst, frame, person) in enumerate(frames):
        sb, sr = 2 * k + 1, 2 * k + 2
        box = union([L["boxes"][sb], L["boxes"][sr]]) or (0, 0, 1, 1)
        vis_b, vis_r = box_mask(L["label"], box, sb), box_mask(L["label"], box, sr)
        am_b = amodal_mask(L["amodal"].get(sb), box, vis_b)
        am_r = amodal_mask(L["amodal"].get(sr), box, vis_r)
        means, prep = frame.gaussians.means.numpy(), assets.label_inputs(inst["bike"], rkeys[k], frame)
        ext_b = projected_extent(means[prep["bike"]], cam)
        bx = boxes[k]
        loc, ry, alpha = fs.box3d(bx) if fs is not None else kitti.box3d(R, T, bx)
        vclass = vehicle_class(assets.meta(inst["bike"]), lab.vehicle_of.get(inst["bike"]))
        extra = {"instance": k + 1, "track_id": index * 1000 + k + 1, "parked": inst["rider"] is None,
                 "bike": inst["bike"], "rider": inst["rider"], "vehicle": vclass,
                 "pose_3d": {"pose": [float(x) for x in inst["pose"]], "pose_fields": list(POSE_KEYS),
                             "bottom_centre_world_m": bx["bottom_centre"], "heading_deg": bx["heading_deg"],
                             "dimensions_hwl_m": [bx["h"], bx["w"], bx["l"]],
                             "location_cam_m": [float(x) for x in loc], "rotation_y": float(ry), "alpha": float(alpha),
                             "depth_m": float(loc[2])}}
        if "signal" in inst:  # only where the draw has signals: other sets keep their bytes
            extra["signal"] = inst["signal"]
        bk = np.array([frame.bike_keypoints.get(n, [np.nan] * 3) for n in BIKE_KEYPOINTS], dtype=np.float64)
        have = np.isfinite(bk).all(1)
        uv, z = project_points(np.nan_to_num(bk), cam)
        vis = keypoint_visibility(uv, z, kp_alpha, kp_depth, kp_cfg.tolerance_bike_m + z * px) * have
        a_b = annotation(vclass, vis_b, am_b, ext_b, W, H, np.column_stack([uv, vis]), extra)
        inst_anns = [a_b]
        if inst["rider"] is not None:
            ext_r = projected_extent(means[prep["rider"]], cam)
            uvr, zr = project_points(person, cam)
            # COCO-17: per-point depths under the skin; SMPL joints: one tolerance for joint centres
            tol = COCO17_TOLERANCE_M if kp_cfg.person == "coco17" else kp_cfg.tolerance_rider_m
            visr = keypoint_visibility(uvr, zr, kp_alpha, kp_depth, np.asarray(tol) + zr * px)
            inst_anns.append(annotation("rider", vis_r, am_r, ext_r, W, H, np.column_stack([uvr, visr]), extra))
            ext_c = [min(ext_b[0], ext_r[0]), min(ext_b[1], ext_r[1]), max(ext_b[2], ext_r[2]), max(ext_b[3], ext_r[3])]
            combined = getattr(lab.combined, vclass)
            a_c = annotation(combined, mask_or(vis_b, vis_r), mask_or(am_b, am_r), ext_c, W, H, None, extra)
            inst_anns.append(a_c)
            main, main_am, ktype = a_c, mask_or(am_b, am_r), kitti.KITTI_TYPES[combined]
        else:
            main, main_am, ktype = a_b, am_b, kitti.KITTI_TYPES["parked"]
        anns += [a for a in inst_anns if a is not None]
        if main is not None:
            x0, y0, x1, y1 = main_am.bbox_xyxy()
            kitti_objs.append({"type": ktype, "truncated": main["truncation"], "occluded": main["occlusion"],
                               "alpha": alpha, "x1": x0, "y1": y0, "x2": x1, "y2": y1,
                               "h": bx["h"], "w": bx["w"], "l": bx["l"], "x": loc[0], "y": loc[1], "z": loc[2],
                               "rotation_y": ry, "instance": k + 1})

    cam_rec = {"K": K.tolist(), "R": R.tolist(), "T": T.tolist(), **{k: v for k, v in d["camera"].items() if k != "jitter"}}
    if street:
        cam_rec.update(height_m=spec["height_m"], pitch_deg=spec["pitch_deg"], roll_deg=spec["roll_deg"])
    image = {"id": index + 1, "file_name": f"{index:06d}.png", "width": W, "height": H,
             "instances": [{"kind": i["kind"], "bike": i["bike"], "rider": i["rider"], "pose": i["pose"],
                            **({"signal": i["signal"]} if "signal" in i else {})} for i, _, _ in frames],
             "pose_fields": list(POSE_KEYS), "camera": cam_rec, "background": bg_rec}
    if street or fs is not None:
        image["dropped_placements"] = d["dropped"]
    if relit is not None:
        image["lighting"] = relit.record(cam)
    for rec, look in zip(image["instances"], looks):  # the sampled look: None = kept
        rec["appearance"] = look
    for rec, w in zip(image["instances"], worn):  # the accessories each rider wears, where drawn
        if w is not None:
            rec["accessories"] = w
    if keeps:  # the level each instance was rendered at (share of its Gaussians)
        for rec, keep in zip(image["instances"], keeps):
            rec["lod_keep"] = keep
    elif frames:  # (a frame may get no instance: every placement refused)
        inst, frame, _ = frames[0]
        image.update(bike=inst["bike"], rider=inst["rider"], pose=inst["pose"])
        if frame.ik is not None:
            image["ik"] = frame.ik
    extras = {"depth": L["depth"], "kitti": kitti_objs, "calib": kitti.calib(K, R, T)}
    if fs is not None:  # the frame's own label rows (occlusion raised), calib, plane and scan
        extras["frame"] = fs.kitti_extras(L)
        image["frame"] = dict(fs.record(), occlusion_raised=[[o, n, round(sh_, 4)] for o, n, sh_ in extras["frame"]["occlusion_raised"]])
        # (a motion-blur sub-frame's draw says so: only the frame's own instant writes a scan)
        counts = fs.insert_scan(scan_parts, extras) if "kitti" in lab.formats and not d.get("subframe") else None
        if counts is not None:  # the LiDAR points on each inserted instance
            image["frame"]["scan"] = fs.scan_record
            for a in anns:
                a["lidar_points"] = counts[a["instance"] - 1]
        for rec, (inst, _, _) in zip(image["instances"], frames):
            rec["tyre_heights_m"] = [round(x, 5) for x in contact.tyre_heights(assets.bikes[inst["bike"]].keypoints, inst["pose"])]
    return rgb, image, anns, extras


def write_sample(cfg, index, out_dir, assets):
    """Render and store one sample: image, depth map, KITTI files, then its shard (the shard marks it
    complete: a killed run redoes the sample, overwriting whatever part of it was written)."""
    rgb, image, anns, extras = make_sample(cfg, index, assets)
    img_path = os.path.join(out_dir, "images", image["file_name"])
    os.makedirs(os.path.dirname(img_path), exist_ok=True)
    with atomic_path(img_path) as tmp:
        png.write(tmp, rgb, cfg.png_compress_level)
    if cfg.depth_maps:
        dpath = os.path.join(out_dir, "depth", image["file_name"])
        os.makedirs(os.path.dirname(dpath), exist_ok=True)
        mm = np.clip(np.round(extras["depth"] * 1000.0), 0, 65535).astype(np.uint16)
        with atomic_path(dpath) as tmp:
            png.write(tmp, mm, cfg.png_compress_level)
    if "kitti" in cfg.labels.formats and "frame" in extras:
        frames_output.write_sample(out_dir, index, img_path, extras["kitti"], extras["frame"])
    elif "kitti" in cfg.labels.formats:
        kitti.write_sample(out_dir, index, img_path, extras["kitti"], extras["calib"])
    os.makedirs(os.path.join(out_dir, "shards"), exist_ok=True)
    write_json(os.path.join(out_dir, "shards", f"{index:06d}.json"), {"image": image, "annotations": anns}, indent=None)
    return index


def sample_done(out_dir, index, cfg=None):
    done = (os.path.isfile(os.path.join(out_dir, "shards", f"{index:06d}.json"))
            and os.path.isfile(os.path.join(out_dir, "images", f"{index:06d}.png")))
    if done and cfg is not None and "kitti" in cfg.labels.formats:
        done = kitti.sample_done(out_dir, index)
    return done


def config_record(cfg):
    """The config stored beside a dataset (config.json, and the key a resumed run must match): the one
    place a DatasetConfig becomes a dict again.  The frames fields only in frames mode, the lighting
    section only when relit, the sequence section only when enabled (or drawing still arm signals),
    so the other sets' config.json stays what it was before those sections existed, and they resume."""
    require_config(cfg, "config_record")
    rec = cfg.model_dump()
    if not lighting.relit(cfg):
        del rec["lighting"]
    for k in ("helmet_share", "bag_share", "hair_styles"):  # per-instance accessories: only when drawn
        if rec["appearance"][k] is None:
            del rec["appearance"][k]
    if cfg.mode != "frames":
        del rec["frames"], rec["insert"]
    if not cfg.sequence.enabled:
        del rec["sequence"]
        if cfg.sequence.still_signal_share:  # ... unless it draws arm signals
            rec["sequence"] = {"still_signal_share": cfg.sequence.still_signal_share}
    return json.loads(json.dumps(rec))
