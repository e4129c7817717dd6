"""One frame of a street sequence: the street sample machinery (generate.make_sample) with the
cyclists posed by their trajectories and the ego camera of the frame, plus the tracking labels.

Frame f of sequence s is dataset sample index s * length + f (its image id is that + 1).  Looks
(appearance) are drawn with the sequence index, so a cyclist keeps its clothes through the sequence.
"""
import math

from cyclist_formats import kitti_frame
from splatting.dataset.generate import make_sample
from splatting.dataset.labels import CATEGORY_IDS
from splatting.dataset.sequences.blur import blurred_sample
from splatting.dataset.sequences.draw import draw_sequence, ego_camera, frame_draw
from splatting.dataset.sequences.in_frames import frame_rows

COMBINED_IDS = (CATEGORY_IDS["cyclist"], CATEGORY_IDS["motorcyclist"])
TRACK_STRIDE = 1000  # COCO track_id = sequence * 1000 + track (the still street sets use index * 1000 + k)


def sequence_of(cfg, index):
    n = int(cfg.sequence.length)
    return index // n, index % n


def drawn(cfg, seq, assets):
    """The sequence's draw, once per process (assets is the per-process cache)."""
    cache = assets.__dict__.setdefault("sequences", {})
    if seq not in cache:
        cache.clear()  # workers take frames in order: one sequence at a time is enough
        cache[seq] = draw_sequence(cfg, seq)
    return cache[seq]


def motion_record(inst, f):
    """Per-instance, per-frame motion labels (docs/sequences.md)."""
    tr = inst["traj"]
    vx, vz = (float(x) for x in tr["velocity_xz"][f])
    rec = {"manoeuvre": inst["manoeuvre"], "intention": inst["intention"][f],
           "velocity_world_mps": [round(vx, 5), 0.0, round(vz, 5)], "speed_mps": round(float(tr["speed"][f]), 5)}
    if inst["kind"] == "cyclist":
        rec.update(curvature_per_m=round(float(tr["kappa"][f]), 6),
                   lateral_accel_mps2=round(float(tr["lateral_accel"][f]), 5),
                   wheel_angle_deg=round(math.degrees(float(tr["wheel_rad"][f])) % 360.0, 4),
                   wheel_rate_rad_s=round(float(tr["wheel_rate"][f]), 5),
                   crank_rate_rad_s=round(float(tr["crank_rate"][f]), 5), gear_ratio=round(inst["gear_ratio"], 5),
                   pedalling=bool(tr["pedalling"][f]), signal=inst["signal"][f], foot_down=inst["foot_down"][f])
    return rec


def make_frame(cfg, index, assets):
    """Frame `index` (global) -> (rgb, image record, annotations, {"kitti": [(track, obj)], "mot": [(track, row)]})."""
    seq, f = sequence_of(cfg, index)
    sd = drawn(cfg, seq, assets)
    exposure = float(cfg.sequence.exposure_s)
    if exposure > 0:  # motion blur: sub-frame renders averaged, the labels of the frame's instant
        rgb, image, anns, extras = blurred_sample(cfg, index, assets, sd, f, exposure, int(cfg.sequence.blur_subframes))
    else:
        rgb, image, anns, extras = make_sample(cfg, index, assets, drawn=frame_draw(sd, f), camera=ego_camera(sd, f),
                                               look_index=seq)
    image.update(file_name=f"{seq:04d}/{f:06d}.png", video_id=seq + 1, frame_id=f,
                 sequence={"time_s": round(f / float(cfg.sequence.fps), 6),
                           "ego_speed_mps": round(sd["ego_speed"], 6), "ego_z_m": round(float(sd["ego_z"][f]), 6)})
    for k, rec in enumerate(image["instances"]):
        rec.update(track_id=k + 1, **motion_record(sd["instances"][k], f))
    mot = {}
    for a in anns:
        k = a["instance"] - 1
        inst = sd["instances"][k]
        a.update(track_id=seq * TRACK_STRIDE + k + 1, instance_id=(seq * TRACK_STRIDE + k + 1) * 10 + a["category_id"],
                 video_id=seq + 1, frame_id=f, **motion_record(inst, f))
        main = a["category_id"] in COMBINED_IDS if inst["rider"] is not None else True
        if main:
            mot[k + 1] = {"box": [float(x) for x in a["bbox_amodal"]], "kind": inst["kind"],
                          "visibility": float(a["visibility"])}
    kit = [[o["instance"], {key: (float(v) if isinstance(v, float) else v) for key, v in o.items()}]
           for o in extras["kitti"]]
    signals = [[k + 1, inst["signal"][f]] for k, inst in enumerate(sd["instances"]) if "signal" in inst]
    rows = {"kitti": kit, "mot": sorted(([k, r] for k, r in mot.items())), "calib": extras["calib"], "signal": signals}
    if "frame" in extras:  # a KITTI frame: its own objects as static tracks after the inserted ones, its calib, scan
        fk, fm = frame_rows(extras["frame"]["frame_lines"], len(sd["instances"]) + 1)
        rows["kitti"] += fk
        rows["mot"] += fm
        with open(kitti_frame.frame_paths(extras["frame"]["folder"], extras["frame"]["frame_id"])["calib"]) as fh:
            rows["calib_text"] = fh.read()
        rows["scan"] = extras["frame"]["scan"]
    return rgb, image, anns, rows
