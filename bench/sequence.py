"""Street-sequence benchmark (issue 29).

Keys:
- `sequence_frames_per_hour`: frames per hour written by `dataset` with 2 worker processes for one
  sequence on the nuScenes camera (1600x900) with 4 cyclists and labels in all three formats
  (COCO-video, KITTI tracking, MOTChallenge), start to the assembled files (start-up included).
  The issue's sequence has 100 frames; `--frames` (default 20 in `make bench`, to keep the stage
  short on a shared machine) sets the length measured, and the result says which.
- `sequence_frames_per_hour_cpu_time`: 2 x 3600 / the median CPU seconds per frame of one
  in-process worker (the rate of two unshared cores).
- `sequence_kitti_cpu_s_per_frame`: median CPU seconds per frame of one in-process worker for a
  sequence in a real KITTI frame (preset kitti-sequence, development frame KITTI_FRAME of
  ../shared/realism/kitti_dev, 4 cyclists, the three formats with the scan ray-cast per frame; the
  draw and its placement checks outside the timing, reported as `draw_s`); skipped without the frames.
- `sequence_plausibility`: over `--plaus-sequences` drawn sequences (4 cyclists each, every
  manoeuvre, 10 s sampled at 100 Hz so that finite differences measure the motion, not the frame
  rate), all from the trajectories' poses and positions:
  max lateral acceleration (|v x a| / |v| of the rear contact point's path; the bound is
  sequence.max_lateral_accel_mps2), lean error (|theta_X + atan(v^2 kappa / g)| with kappa measured
  from the path, degrees), slip (|contact point's speed along the heading - wheel rate x r|, m/s)
  and cadence error (|crank angle rate measured on the posed pedal - wheel rate / gear| while
  pedalling, rad/s).

Run alone: `python -m bench.sequence [--out DIR] [--frames N] [--bikes-root DIR --riders-root DIR]`.
"""
import json
import os
import shutil
import statistics
import sys
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench import bench_parser  # noqa: E402

RIDER = "m_adult_average_185"
KITTI_FRAME = "000001"  # a development frame with room for four tracks (a road; 000000 is a courtyard)


def bench_config(scratch, out_dir, frames, bikes_root=None, riders_root=None):
    from bench.dataset import pick_assets
    from splatting.dataset.config import load_yaml, preset_path
    if bikes_root:
        bikes = sorted(d for d in os.listdir(bikes_root) if os.path.isdir(os.path.join(bikes_root, d, "gaussians")))
        synth, desc = "never", f"trained part Gaussians of {len(bikes)} bikes in {bikes_root}"
    else:
        bikes_root, bikes, synth, desc = pick_assets(out_dir, scratch)
    riders_root = riders_root or os.path.join(ROOT, "data", "riders")
    if synth == "never" and not os.path.isfile(os.path.join(riders_root, RIDER, "skinning.npz")):
        synth = "auto"
    cfg = load_yaml(preset_path("street-sequence"))
    cfg.update(name="bench_sequence", count=1, bikes=bikes, bikes_root=bikes_root, synthetic_assets=synth,
               riders=[RIDER], riders_root=riders_root)
    cfg["camera"] = {"preset": "nuscenes"}
    cfg["street"] = dict(cfg.get("street", {}), cyclists=[4, 4], parked_bikes=[0, 0])
    cfg["sequence"] = dict(cfg["sequence"], length=frames)
    return cfg, desc


def cpu_per_frame(cfg, n):
    """Median CPU seconds per frame of one in-process worker over n frames spread through the
    sequence (assets loaded outside the timing)."""
    import numpy as np
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.config import resolve_assets, validate
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.output import write_frame
    cfg = resolve_assets(validate(cfg))
    assets = Assets(cfg)
    scratch = tempfile.mkdtemp(prefix="bench_seq_cpu_")
    try:
        write_frame(cfg, 0, scratch, assets)
        rows = []
        length = cfg.sequence.length
        for i in sorted({int(round(x)) for x in np.linspace(1, length - 1, n)}):  # spread over the sequence
            c = time.process_time()
            write_frame(cfg, i, scratch, assets)
            rows.append(time.process_time() - c)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return statistics.median(rows), len(rows)


def kitti_cpu_per_frame(cfg, n, scratch):
    """(median CPU s per frame, frames, draw s, tracks placed) of a kitti-sequence set in the development
    frame KITTI_FRAME with cfg's assets, or None without the development frames."""
    from splatting.dataset.config import load_yaml, preset_path
    from splatting.dataset.frames.source import development_frames
    from splatting.dataset.sequences.draw import draw_sequence
    dev = development_frames()
    if dev is None:
        return None
    one = os.path.join(scratch, "kitti_one")  # a folder of that one frame: sequence 0 falls on it
    for d in ("image_2", "calib", "label_2", "planes", "velodyne"):
        src = [f for f in os.listdir(os.path.join(dev, d)) if f.startswith(KITTI_FRAME + ".")]
        if src:
            os.makedirs(os.path.join(one, d), exist_ok=True)
            os.symlink(os.path.join(dev, d, src[0]), os.path.join(one, d, src[0]))
    k = load_yaml(preset_path("kitti-sequence"))
    k.update({f: cfg[f] for f in ("bikes", "bikes_root", "synthetic_assets", "riders", "riders_root")},
             name="bench_kitti_sequence", count=1, frames=one)
    k["street"] = dict(k["street"], cyclists=[4, 4], parked_bikes=[0, 0])
    k["sequence"] = dict(k["sequence"], length=cfg["sequence"]["length"])
    from splatting.dataset.config import resolve_assets, validate
    t = time.process_time()
    placed = len(draw_sequence(resolve_assets(validate(k)), 0)["instances"])
    draw_s = time.process_time() - t
    cpu, frames = cpu_per_frame(k, n)
    return cpu, frames, draw_s, placed


def plausibility(bikes_root, bikes, n_seq=25):
    """Worst values over n_seq drawn sequences of 4 cyclists (module docstring)."""
    import numpy as np
    import torch
    from cyclist_formats.bike_folder import read_keypoints
    from splatting.dataset.config import validate
    from splatting.dataset.sequences.draw import draw_sequence
    from splatting.dataset.sequences.trajectory import G
    from splatting.bike.pose import posed_bike_keypoints
    fps = 100.0
    cfg = validate({"mode": "street", "camera": {"preset": "nuscenes"}, "bikes": bikes, "bikes_root": bikes_root,
                    "riders": [RIDER], "street": {"cyclists": [4, 4], "parked_bikes": [0, 0]},
                    "sequence": {"enabled": True, "length": 1001, "fps": fps}})
    a_max = cfg.sequence.max_lateral_accel_mps2
    worst = {"max_lateral_accel_mps2": 0.0, "lean_error_deg": 0.0, "slip_mps": 0.0, "cadence_error_rad_s": 0.0}
    count = 0
    for seq in range(n_seq):
        for inst in draw_sequence(cfg, seq)["instances"]:
            tr, geo = inst["traj"], inst["geometry"]
            count += 1
            rear = tr["rear_xz"]
            v1 = np.gradient(rear, axis=0) * fps
            a1 = np.gradient(v1, axis=0) * fps
            sp = np.linalg.norm(v1, axis=1)
            lat = (v1[:, 0] * a1[:, 1] - v1[:, 1] * a1[:, 0]) / np.maximum(sp, 1e-9)
            kap = -lat / np.maximum(sp, 1e-9) ** 2  # theta_Y grows to the left (towards -Z)
            ok = slice(2, -2)
            worst["max_lateral_accel_mps2"] = max(worst["max_lateral_accel_mps2"], float(np.abs(lat[ok]).max()))
            moving = sp[ok] > 0.3
            lean = np.degrees(np.arctan(tr["speed"] ** 2 * kap / G))
            if moving.any():
                worst["lean_error_deg"] = max(worst["lean_error_deg"],
                                              float(np.abs(tr["theta_x_deg"][ok] + lean[ok])[moving].max()))
            kp = read_keypoints(os.path.join(bikes_root, inst["bike"]))
            P = torch.tensor(np.column_stack([tr["theta_p_deg"], tr["theta_s_deg"], tr["theta_x_deg"], tr["theta_y_deg"],
                                              np.zeros(len(rear)), tr["origin_xz"][:, 0], np.zeros(len(rear)),
                                              tr["origin_xz"][:, 1]]), dtype=torch.float64)
            pk = {k: v.numpy() for k, v in posed_bike_keypoints(kp, P).items()}
            yaw = np.radians(tr["theta_y_deg"])
            fwd = np.stack([np.cos(yaw), np.zeros_like(yaw), -np.sin(yaw)], 1)
            gv = np.gradient(pk["ground"], axis=0) * fps
            slip = np.abs(np.sum(gv * fwd, 1) - tr["wheel_rate"] * geo["r"])[ok]
            worst["slip_mps"] = max(worst["slip_mps"], float(slip.max()))
            ped = pk["pedal_left"] - pk["crank_axle"]
            up = pk["crank_axle"] - np.column_stack([tr["origin_xz"][:, 0], np.zeros(len(rear)), tr["origin_xz"][:, 1]])
            up /= np.linalg.norm(up, axis=1, keepdims=True)
            ang = np.unwrap(np.arctan2(np.sum(ped * fwd, 1), np.sum(ped * up, 1)))
            rate = np.gradient(ang) * fps
            ped_on = tr["pedalling"].copy()
            ped_on[1:] &= tr["pedalling"][:-1]
            ped_on[:-1] &= tr["pedalling"][1:]  # away from the switch between pedalling and coasting
            err = np.abs(rate - tr["wheel_rate"] / inst["gear_ratio"])[ped_on][2:-2] if ped_on.sum() > 4 else [0.0]
            worst["cadence_error_rad_s"] = max(worst["cadence_error_rad_s"], float(np.max(err)))
    out = {k: round(v, 5) for k, v in worst.items()}
    out.update(cyclists=count, sequences=n_seq, sampled_hz=fps, lateral_accel_bound_mps2=a_max)
    return out


def run(results, out_dir, frames=20, bikes_root=None, riders_root=None, plaus_sequences=25, cpu_frames=8):
    import torch
    torch.set_num_threads(1)
    from bench.dataset import timed_generate
    scratch = tempfile.mkdtemp(prefix="bench_sequence_")
    try:
        cfg, desc = bench_config(scratch, out_dir, frames, bikes_root, riders_root)
        print(f"sequence bench: bikes: {desc}; rider from {cfg['riders_root']} ({cfg['synthetic_assets']})")
        out = os.path.join(scratch, "out")
        doc, wall, load = timed_generate(cfg, out, workers=2)
        fph = frames * 3600.0 / wall
        print(f"sequence bench: 1 sequence of {frames} frames 1600x900, 4 cyclists, {len(doc['annotations'])} "
              f"annotations, COCO-video + KITTI tracking + MOT, 2 workers: {wall:.1f} s -> {fph:.0f} frames/hour "
              f"(1-min load average {load[0]} before, {load[1]} after)")
        cpu, n_cpu = cpu_per_frame(cfg, cpu_frames)
        cpu_fph = 2 * 3600.0 / cpu
        print(f"sequence bench: {cpu:.2f} CPU s per frame (median of {n_cpu}) -> {cpu_fph:.0f} frames/hour on 2 unshared cores")
        kit = kitti_cpu_per_frame(cfg, cpu_frames, scratch)
        if kit is not None:
            print(f"sequence bench: in KITTI frame {KITTI_FRAME}: {kit[0]:.2f} CPU s per frame (median of {kit[1]}), "
                  f"draw {kit[2]:.2f} CPU s, {kit[3]} tracks placed")
            results["sequence_kitti_cpu_s_per_frame"] = round(kit[0], 3)
            results["sequence_kitti_bench"] = {"frame": KITTI_FRAME, "frames": kit[1], "draw_s": round(kit[2], 3),
                                               "tracks": kit[3], "size": "1242x375"}
        else:
            print("sequence bench: no development KITTI frames (../shared/realism/kitti_dev): KITTI sequence skipped")
        plaus = plausibility(cfg["bikes_root"], cfg["bikes"], plaus_sequences)
        print(f"sequence bench: plausibility {plaus}")
        results["sequence_frames_per_hour"] = round(fph, 1)
        results["sequence_frames_per_hour_cpu_time"] = round(cpu_fph, 1)
        results["sequence_bench"] = {"frames": frames, "issue_frames": 100, "workers": 2, "wall_s": round(wall, 2),
                                     "camera": "nuscenes 1600x900", "cyclists": 4, "bikes": desc,
                                     "load_avg_1m_before_after": load, "cpu_s_per_frame": round(cpu, 3)}
        results["sequence_plausibility"] = plaus
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return results


def main(argv=None):
    ap = bench_parser("sequence", __doc__)
    ap.add_argument("--frames", type=int, default=20, help="sequence length measured (the issue's is 100)")
    ap.add_argument("--bikes-root", help="a folder of trained bikes (default: bench.dataset's pick)")
    ap.add_argument("--riders-root", help="a folder of rider avatars (default: data/riders)")
    ap.add_argument("--plaus-sequences", type=int, default=25)
    args = ap.parse_args(argv)
    if args.frames < 4 or args.plaus_sequences < 1:
        sys.stderr.write("bench.sequence: error: --frames must be >= 4 and --plaus-sequences >= 1\n")
        return 2
    results = {}
    run(results, args.out, args.frames, args.bikes_root, args.riders_root, args.plaus_sequences)
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
