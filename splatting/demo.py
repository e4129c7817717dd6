"""`demo`: the whole pipeline from nothing, on a reduced budget, with a report of this run.

procedural bikes -> 36-view renders -> part Gaussians -> rider avatar -> relight channels of the
parts and the avatar -> 24-frame pedalling cyclist from 4 views -> small COCO set -> the same
first samples relit under their own suns -> street images -> real KITTI frames with the cyclist
inserted (when ../shared/realism/kitti_dev is there) -> a street sequence with its tracks -> contact sheet -> point-cloud import
into Blender with one Cycles render -> OUT/report.md.  Each step is skipped when its output exists, so an
interrupted demo resumes.  Blender steps run as subprocesses (this package never imports bpy).
"""
import glob
import os
import subprocess
import sys
import time

import yaml

from cyclist_formats import checks
from cyclist_formats.atomic import atomic_path, read_json_or_none
from cyclist_formats.errors import UserError
from splatting import paths

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).

ROOT = str(paths.ROOT)
PARTS = ("frame", "steering", "crank")
# the sub-parts' share of --train-seconds and of --max-gaussians: a wheel is a fraction of the
# frame's surface, a pedal body a few boxes (the city bike's, 256 px views: the wheels reached
# 42.7 / 43.2 dB held-out PSNR in 1500 iterations, the pedals 59.6 dB, with 8000 Gaussians each)
SUB_PART_BUDGET = {"front_wheel": (0.5, 0.5), "rear_wheel": (0.5, 0.5), "pedal_left": (0.25, 0.1),
                   "pedal_right": (0.25, 0.1)}


def bike_parts(bike):
    """The demo bike's trained parts: PARTS and the wheel / pedal sub-parts its meta.json lists."""
    from cyclist_formats import bike_folder

    return list(PARTS) + bike_folder.sub_parts(bike_folder.read_meta(bike))
RELIGHT_FIT_PX = 256  # the relight fits' view size (below: the demo's time budget)


def add_arguments(p):
    p.add_argument("--out", default=os.path.join("out", "demo"))
    p.add_argument("--bikes", type=int, default=3, help="procedural bikes to generate (default 3)")
    p.add_argument("--rider", default="m_adult_average_185", help="roster rider id")
    p.add_argument("--train-seconds", type=float, default=110, help="training budget per part (default 110 s)")
    p.add_argument("--rider-train-seconds", type=float, default=140)
    p.add_argument("--max-gaussians", type=int, default=15000, help="per part (default 15000)")
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--coco-count", type=int, default=24)
    p.add_argument("--relight-iterations", type=int, default=150,
                   help="relight fit steps per part and for the avatar (default 150; the command's own default is 300)")
    p.add_argument("--relit-count", type=int, default=4, help="relit dataset images (default 4)")


class Steps:
    def __init__(self, out):
        self.out, self.times = out, {}

    def run(self, name, cmd, done=None):
        """Run one step as a subprocess unless `done` (a path) exists; time it."""
        if done and os.path.exists(done):
            print(f"demo: {name}: done earlier, skipped", flush=True)
            return
        print(f"demo: {name}", flush=True)
        t = time.time()
        r = subprocess.run(cmd, cwd=ROOT)
        self.times[name] = time.time() - t
        if r.returncode != 0:
            raise UserError(f"step '{name}' failed (exit {r.returncode}): {' '.join(cmd)}")


def check_args(args):
    checks.output_dir("out", args.out)
    checks.count("bikes", args.bikes, hi=1000)
    checks.positive("train_seconds", args.train_seconds)
    checks.positive("rider_train_seconds", args.rider_train_seconds)
    checks.gaussians("max_gaussians", args.max_gaussians)
    checks.count("frames", args.frames, hi=1_000_000)
    checks.count("coco_count", args.coco_count)
    checks.count("relight_iterations", args.relight_iterations)
    checks.count("relit_count", args.relit_count, hi=args.coco_count)


def run(args):
    out = os.path.abspath(args.out)
    py = sys.executable
    bs = lambda s: os.path.join(ROOT, "blender_scripts", s)  # noqa: E731
    st = Steps(out)
    t0 = time.time()
    st.run("procedural bikes", [py, bs("make_bikes.py"), "--out", out, "--count", str(args.bikes), "--seed", "0", "--no-extras"])
    bikes = sorted(glob.glob(os.path.join(out, "bikes", "*", "bike.blend")))
    bike_dirs = [os.path.dirname(b) for b in bikes]
    if not bike_dirs:
        raise UserError(f"no bikes were generated under {out}/bikes")
    for b in bike_dirs[1:]:
        st.run(f"view 3 of {os.path.basename(b)}", [py, bs("render_views.py"), "--bike", b, "--parts", "whole", "--views", "3"])
    bike = bike_dirs[0]
    # 16 spp (+ denoise) rather than the library's 128-spp training default (docs/training.md: +0.5 dB
    # box PSNR for ~2.6x the render time), so a fresh clone's demo stays within its 20 minutes.
    parts = bike_parts(bike)  # frame, steering, crank and the wheel / pedal sub-parts
    st.run(f"36 views x {len(parts) + 1} of {os.path.basename(bike)}", [py, bs("render_views.py"), "--bike", bike, "--parts",
                                                                        "all", "--samples", "16"])
    for part in parts:
        ply = os.path.join(bike, "gaussians", f"{part}.ply")
        share, cap = SUB_PART_BUDGET.get(part, (1.0, 1.0))
        st.run(f"train {part}", [py, "-m", "splatting", "train", "--views", os.path.join(bike, "views", part),
                                 "--time-budget-s", str(round(args.train_seconds * share, 1)),
                                 "--max-gaussians", str(max(1000, int(args.max_gaussians * cap)))], done=ply)
    riders = os.path.join(out, "riders")
    st.run(f"rider avatar {args.rider}", [py, "-m", "splatting", "rider-avatar", "--id", args.rider, "--out",
                                          os.path.join(riders, args.rider), "--time-budget-s", str(args.rider_train_seconds)],
           done=os.path.join(riders, args.rider, "skinning.npz"))
    # relight channels (docs/relighting.md): 150 steps reach 42.7 / 47.7 / 39.9 dB held-out albedo
    # (frame / steering / crank) and 33.6 dB, 6.4 deg normals for the rider, ~145 s for all four on
    # the loaded 2 cores; 300 steps gave the frame 44.2 dB, 23.2 deg (150: 23.7 deg) for 41 s
    # instead of 28 s of fitting: the demo keeps the margin to its 20 minutes.  For the same reason
    # the demo fits at 256 px (RELIGHT_FIT_PX), not the command's 512 px default: 512 px gains the
    # bike 0.7 dB relit box PSNR (bench/relight.py) but doubles the fits (frame 20 -> 40 s, rider
    # ~105 s), about 110 s more for the four
    fit_px = ["--max-size", str(RELIGHT_FIT_PX)]
    for part in bike_parts(bike):
        ply = os.path.join(bike, "gaussians", f"{part}.ply")
        st.run(f"relight fit {part}", [py, "-m", "splatting", "relight-fit", "--views", os.path.join(bike, "views", part),
                                       "--ply", ply, "--iterations", str(args.relight_iterations), "--quiet"] + fit_px,
               done=os.path.splitext(ply)[0] + ".relight.npz")
    av = os.path.join(riders, args.rider)
    st.run("relight fit rider", [py, "-m", "splatting", "relight-fit", "--views", os.path.join(av, "views"), "--ply",
                                 os.path.join(av, "rider.ply"), "--iterations", str(args.relight_iterations), "--quiet"] + fit_px,
           done=os.path.join(av, "rider.relight.npz"))
    cyc = os.path.join(out, "cyclist")
    st.run(f"{args.frames}-frame cyclist from 4 views",
           [py, "-m", "splatting", "cyclist", "--rider", args.rider, "--bike", bike, "--riders-root", riders,
            "--frames", str(args.frames), "--views=0,90,180,-90", "--ply", "--synthetic", "never", "--out", cyc])
    cfg_path = os.path.join(out, "dataset.yaml")
    cfg = dataset_config("cyclist", out, args.rider, riders, bike, {"name": "demo", "count": args.coco_count})
    write_config(cfg_path, cfg)
    coco = os.path.join(out, "coco")
    st.run("COCO set", [py, "-m", "splatting", "dataset", "--config", cfg_path, "--out", coco, "--quiet"])
    from splatting.dataset.preview import coco_preview, relit_preview

    coco_preview(coco, os.path.join(out, "coco_preview.png"))
    # the COCO set's first samples relit, each under its own sun (same seed: same poses and cameras)
    rcfg_path = os.path.join(out, "relit.yaml")
    write_config(rcfg_path, dict(cfg, name="demo_relit", count=args.relit_count, lighting={"mode": "relit"}))
    relit = os.path.join(out, "relit")
    st.run("relit images", [py, "-m", "splatting", "dataset", "--config", rcfg_path, "--out", relit, "--quiet"])
    relit_preview(coco, relit, os.path.join(out, "relit_preview.png"), n=args.relit_count)
    # a few street images (docs/street_scenes.md): the same rider and bike, several per image
    scfg = dataset_config("street", out, args.rider, riders, bike, {"name": "demo_street", "count": 3},
                          {"labels": {"formats": ["coco", "kitti"]}})
    scfg["camera"] = dict(scfg.get("camera", {}), scale=0.5)
    scfg_path = os.path.join(out, "street.yaml")
    write_config(scfg_path, scfg)
    street = os.path.join(out, "street")
    st.run("street images", [py, "-m", "splatting", "dataset", "--config", scfg_path, "--out", street, "--quiet"])
    coco_preview(street, os.path.join(out, "street_preview.png"), n=3)
    kitti_frames(st, py, out, args.rider, riders, bike)
    street_sequence(st, py, out, args.rider, riders, bike)
    st.run("contact sheet", [py, "-m", "splatting", "contact-sheet", "--bikes", os.path.join(out, "bikes"), "--view", "3",
                             "--out", os.path.join(out, "contact_sheet.png")])
    plys = sorted(glob.glob(os.path.join(cyc, "ply", "*.ply")))
    if not plys:
        raise UserError(f"the cyclist step wrote no .ply under {cyc}/ply")
    # Gaussian mode (ellipsoids, falloff, SH) costs ~250 s per 512² 16-spp Cycles render on 2 cores;
    # 256² at 8 spp keeps the demo's step near half a minute
    st.run("Gaussians into Blender + Cycles render", [py, bs("import_splats.py"), "--ply", plys[0], "--size", "256",
                                                     "--samples", "8", "--render", os.path.join(out, "cyclist_blender.png")])
    report(out, bike, args, st.times, time.time() - t0)
    print(f"demo: finished; see {os.path.join(out, 'report.md')}")


def dataset_config(template, out, rider, riders, bike, head, tail=None):
    """blend_assets/datasets/<template>.yaml with the demo's rider and trained bike; `head` keys go
    before the asset keys and `tail` keys after them (the written YAML keeps that order)."""
    with open(os.path.join(ROOT, "blend_assets", "datasets", template + ".yaml")) as f:
        cfg = yaml.safe_load(f)
    cfg.update({**head, "riders": [rider], "riders_root": riders, "bikes": [os.path.basename(bike)],
                "bikes_root": os.path.join(out, "bikes"), "synthetic_assets": "never", **(tail or {})})
    return cfg


def write_config(path, cfg):
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            yaml.safe_dump(cfg, f, sort_keys=False)


def kitti_frames(st, py, out, rider, riders, bike):
    """A few real KITTI development frames with the demo's cyclist inserted (docs/kitti_insert.md),
    when ../shared/realism/kitti_dev is there; says so when it is not."""
    from splatting.dataset.frames.sheet import sheet
    from splatting.dataset.frames.source import development_frames
    dev = development_frames()
    if dev is None:
        print("demo: KITTI frames: no development frames (../shared/realism/kitti_dev), step skipped", flush=True)
        return
    kcfg = dataset_config("kitti-insert", out, rider, riders, bike, {"name": "demo_kitti", "count": 4, "frames": dev})
    kpath = os.path.join(out, "kitti_insert.yaml")
    write_config(kpath, kcfg)
    kout = os.path.join(out, "kitti_insert")
    st.run("KITTI frames with cyclists", [py, "-m", "splatting", "dataset", "--config", kpath, "--out", kout, "--quiet"])
    sheet(kout, os.path.join(out, "kitti_insert.png"))


def street_sequence(st, py, out, rider, riders, bike):
    """A short street sequence (docs/sequences.md): cyclists crossing, turning and overtaking in
    front of a moving camera, in the three tracking formats, and a strip of its frames with tracks."""
    from splatting.dataset.sequences.strip import main as strip
    qcfg = dataset_config("street-sequence", out, rider, riders, bike, {"name": "demo_sequence", "count": 1, "seed": 4})
    qcfg["camera"] = dict(qcfg.get("camera", {}), scale=0.5)
    qcfg["street"] = dict(qcfg["street"], cyclists=[3, 3], parked_bikes=[1, 1], distance_m=[8, 25])
    qcfg["sequence"] = dict(qcfg["sequence"], length=30, fps=5,
                            manoeuvres={"straight": 0, "turn_left": 1, "turn_right": 0, "cross": 3, "overtake": 1,
                                        "stop": 0, "start": 0, "swerve": 0}, ego={"motion": "moving", "speed_mps": [2, 3]})
    qpath = os.path.join(out, "sequence.yaml")
    write_config(qpath, qcfg)
    qout = os.path.join(out, "sequence")
    st.run("street sequence", [py, "-m", "splatting", "dataset", "--config", qpath, "--out", qout, "--quiet"],
           done=os.path.join(qout, "annotations.json"))
    if strip(["--dataset", qout, "--out", os.path.join(out, "sequence_strip.png")]) != 0:
        raise UserError(f"the sequence strip of {qout} failed")


def report(out, bike, args, times, wall):
    rel = lambda p: os.path.relpath(p, out)  # noqa: E731
    lines = ["# Demo report", "", f"Generated {time.strftime('%Y-%m-%d %H:%M')} on {os.cpu_count()} cores; "
             f"total wall time of the steps run now: {wall / 60:.1f} min (steps done earlier are not counted).", "",
             "## Steps (wall seconds)", "", "| step | s |", "| --- | --- |"]
    lines += [f"| {k} | {v:.0f} |" for k, v in times.items()]
    lines += ["", f"## Part Gaussians of {os.path.basename(bike)} (held-out views)", "",
              "| part | PSNR dB | PSNR object box dB | SSIM | Gaussians | wall s |", "| --- | --- | --- | --- | --- | --- |"]
    for part in bike_parts(bike):
        m = read_json_or_none(os.path.join(bike, "gaussians", f"{part}.json"))
        if m:
            lines.append(f"| {part} | {m['psnr']:.2f} | {m.get('psnr_crop', float('nan')):.2f} | {m['ssim']:.4f} | "
                         f"{m['gaussians']} | {m['wall_s']:.0f} |")
    frames = sorted(glob.glob(os.path.join(out, "cyclist", "frame_*.json")))
    if frames:
        res = [max(read_json_or_none(f)["ik"]["residual_m"].values()) for f in frames]
        flagged = sum(any(read_json_or_none(f)["ik"]["flagged"].values()) for f in frames)
        lines += ["", "## Cyclist sequence", "", f"{len(frames)} frames; IK worst residual per frame: median "
                  f"{sorted(res)[len(res) // 2] * 1000:.1f} mm, max {max(res) * 1000:.1f} mm; frames with a flagged target: {flagged}."]
    ann = read_json_or_none(os.path.join(out, "coco", "annotations.json"))
    if ann:
        lines += ["", "## COCO set", "", f"{len(ann['images'])} images, {len(ann['annotations'])} annotations "
                  f"({', '.join(c['name'] for c in ann['categories'])}) in `coco/`."]
    ann = read_json_or_none(os.path.join(out, "relit", "annotations.json"))
    if ann:
        suns = ", ".join(f"{im['lighting']['elevation_deg']:.0f}/{im['lighting']['azimuth_deg']:.0f}" for im in ann["images"])
        lines += ["", "## Relit images", "", f"The first {len(ann['images'])} COCO samples rendered again with "
                  f"`lighting: {{mode: relit}}` in `relit/`: a sun per image (elevation/azimuth in degrees: {suns}), "
                  "recorded in each image record's `lighting`; same masks, boxes and keypoints."]
    ann = read_json_or_none(os.path.join(out, "street", "annotations.json"))
    if ann:
        lines += ["", "## Street images", "", f"{len(ann['images'])} images "
                  f"({ann['images'][0]['width']}x{ann['images'][0]['height']}), {len(ann['annotations'])} annotations "
                  f"in `street/` (COCO) and `street/kitti/` (KITTI)."]
    ann = read_json_or_none(os.path.join(out, "kitti_insert", "annotations.json"))
    if ann:
        n = sum(len(im["instances"]) for im in ann["images"])
        lines += ["", "## KITTI frames with cyclists", "", f"{len(ann['images'])} real KITTI development frames with "
                  f"{n} inserted instances in `kitti_insert/` (COCO) and `kitti_insert/kitti/` (KITTI, with velodyne)."]
    else:
        lines += ["", "## KITTI frames with cyclists", "", "Not made: the development frames "
                  "(../shared/realism/kitti_dev) are not present."]
    ann = read_json_or_none(os.path.join(out, "sequence", "annotations.json"))
    if ann:
        crossing = sum(a["intention"] == "crossing" for a in ann["annotations"] if a["category_id"] == 3)
        lines += ["", "## Street sequence", "", f"{len(ann['videos'])} sequence of {len(ann['images'])} frames, "
                  f"{len(ann['tracks'])} tracks ({crossing} cyclist boxes labelled `crossing`) in `sequence/` "
                  "(COCO-video), `sequence/kitti_tracking/` (KITTI tracking) and `sequence/mot/` (MOTChallenge)."]
    lines += ["", "## Pictures", ""]
    for title, pattern in (("Contact sheet", "contact_sheet.png"), ("Cyclist preview", "cyclist/preview.png"),
                           ("COCO samples with their annotations", "coco_preview.png"),
                           ("The same samples baked (top) and relit under their own sun (bottom)", "relit_preview.png"),
                           ("Street images with their annotations", "street_preview.png"),
                           ("Real KITTI frames with inserted cyclists: visible masks, boxes, LiDAR bird's-eye view",
                            "kitti_insert.png"),
                           ("A street sequence with its tracks (amodal boxes, ids, manoeuvres, intentions, trails)",
                            "sequence_strip.png"),
                           ("Point cloud in Blender (Cycles)", "cyclist_blender.png")):
        for p in sorted(glob.glob(os.path.join(out, pattern)))[:1]:
            lines.append(f"### {title}\n\n![{title}]({rel(p)})\n")
    with atomic_path(os.path.join(out, "report.md")) as tmp:
        with open(tmp, "w") as f:
            f.write("\n".join(lines) + "\n")
