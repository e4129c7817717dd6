"""Motion-blur benchmark (issue 29): sub-frame averaging (splatting/dataset/sequences/blur.py)
with N sub-frames against a many-sub-frame reference.

Keys:
- `motion_blur_box_psnr_db`: {exposure: {N: box PSNR (dB) of the N-sub-frame image against the
  REF_SUBFRAMES-sub-frame one}}, medians over the frames measured; N = 1 is the unblurred instant
  (what blur adds).  The box: the union of the cyclists' amodal boxes at the mid-exposure instant,
  each grown by BOX_GROW of its size on every side (the smear reaches beyond the instant's box).
- `motion_blur_s_per_frame`: {N: median wall seconds per frame} (one thread; every sub-frame is a
  full make_sample, labels included, so the cost is about N times the still frame's).

Scene: one street sequence on the nuScenes camera at half size (800x450), 3 cyclists riding
straight or crossing at 6-8 m/s 6-15 m from an ego camera driving at 8 m/s; frames spread over it.

Run alone: `python -m bench.motion_blur [--bikes-root DIR --riders-root DIR] [--frames 2]
[--exposures 0.02 0.05]`.
"""
import argparse
import json
import os
import statistics
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

RIDER = "m_adult_average_185"
REF_SUBFRAMES = 33
SUBFRAMES = (1, 3, 5, 9, 17)
BOX_GROW = 0.15


def bench_config(bikes_root, riders_root, exposure):
    from splatting.dataset.config import load_yaml, preset_path, validate
    cfg = load_yaml(preset_path("street-sequence"))
    bikes = sorted(d for d in os.listdir(bikes_root) if os.path.isdir(os.path.join(bikes_root, d)))[:1]
    synth = "never" if os.path.isdir(os.path.join(bikes_root, bikes[0], "gaussians")) else "always"
    if not os.path.isfile(os.path.join(riders_root, RIDER, "skinning.npz")):
        synth = "always" if synth == "always" else "auto"
    only = {m: 0.0 for m in ("turn_left", "turn_right", "overtake", "stop", "start", "swerve")}
    cfg.update(name="bench_motion_blur", count=1, bikes=bikes, bikes_root=bikes_root, riders=[RIDER],
               riders_root=riders_root, synthetic_assets=synth, camera={"preset": "nuscenes", "scale": 0.5})
    cfg["street"] = dict(cfg["street"], cyclists=[3, 3], parked_bikes=[0, 0], distance_m=[6, 15])
    cfg["sequence"] = dict(cfg["sequence"], length=20, manoeuvres=dict(only, straight=1.0, cross=2.0), speed_mps=[6, 8],
                           ego={"motion": "moving", "speed_mps": [8, 8]}, exposure_s=exposure)
    return validate(cfg), bikes[0]


def box_region(anns, W, H):
    import numpy as np
    m = np.zeros((H, W), bool)
    for a in anns:
        if a["category_id"] not in (3, 4) or a.get("parked"):
            continue
        x, y, w, h = a["bbox_amodal"]
        gx, gy = BOX_GROW * w, BOX_GROW * h
        x0, y0 = max(int(x - gx), 0), max(int(y - gy), 0)
        x1, y1 = min(int(np.ceil(x + w + gx)), W), min(int(np.ceil(y + h + gy)), H)
        m[y0:y1, x0:x1] = True
    return m


def psnr(a, b, mask):
    import numpy as np
    d = (a.astype(np.float64) - b.astype(np.float64))[mask]
    mse = float(np.mean(d ** 2))
    return float("inf") if mse == 0 else 10 * np.log10(255.0 ** 2 / mse)


def run(results, out_dir=None, bikes_root=None, riders_root=None, frames=2, exposures=(0.02, 0.05)):
    import numpy as np
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.config import resolve_assets
    from splatting.dataset.generate import Assets
    from splatting.dataset.sequences.blur import blurred_sample
    from splatting.dataset.sequences.render import drawn
    bikes_root = bikes_root or os.path.join(ROOT, "out", "bikes")
    riders_root = riders_root or os.path.join(ROOT, "data", "riders")
    if not os.path.isdir(bikes_root):
        print(f"motion blur bench: no bikes in {bikes_root}: skipped")
        return results
    out_psnr, cost = {}, {n: [] for n in SUBFRAMES + (REF_SUBFRAMES,)}
    load0 = os.getloadavg()[0]
    for e in exposures:
        cfg, bike = bench_config(bikes_root, riders_root, e)
        cfg = resolve_assets(cfg)
        assets = Assets(cfg)
        sd = drawn(cfg, 0, assets)
        n_len = cfg["sequence"]["length"]
        rows = {n: [] for n in SUBFRAMES}
        blurred_sample(cfg, 1, assets, sd, 1, e, 1)  # assets loaded outside the timing
        for f in [int(x) for x in np.linspace(3, n_len - 4, frames)]:
            t = time.perf_counter()
            ref, _, anns, _ = blurred_sample(cfg, f, assets, sd, f, e, REF_SUBFRAMES)
            cost[REF_SUBFRAMES].append((time.perf_counter() - t) / 1.0)
            mask = box_region(anns, ref.shape[1], ref.shape[0])
            if not mask.any():
                continue
            for n in SUBFRAMES:
                t = time.perf_counter()
                img = blurred_sample(cfg, f, assets, sd, f, e, n)[0]
                cost[n].append(time.perf_counter() - t)
                rows[n].append(psnr(img, ref, mask))
        out_psnr[f"{e:g}"] = {str(n): round(statistics.median(v), 2) for n, v in rows.items() if v}
        print(f"motion blur bench: exposure {e:g} s, box PSNR vs {REF_SUBFRAMES} sub-frames: {out_psnr[f'{e:g}']}")
    sec = {str(n): round(statistics.median(v), 3) for n, v in cost.items() if v}
    print(f"motion blur bench: seconds per frame (median, 1 thread): {sec}")
    results["motion_blur_box_psnr_db"] = out_psnr
    results["motion_blur_s_per_frame"] = sec
    results["motion_blur_bench"] = {"reference_subframes": REF_SUBFRAMES, "camera": "nuscenes 800x450", "cyclists": 3,
                                    "bike": bike, "frames": frames, "box_grow": BOX_GROW,
                                    "load_avg_1m_before_after": [round(load0, 2), round(os.getloadavg()[0], 2)]}
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.motion_blur", description=__doc__.splitlines()[0])
    ap.add_argument("--bikes-root", help="a folder of trained bikes (default: out/bikes)")
    ap.add_argument("--riders-root", help="a folder of rider avatars (default: data/riders)")
    ap.add_argument("--frames", type=int, default=2, help="frames measured per exposure")
    ap.add_argument("--exposures", type=float, nargs="+", default=[0.02, 0.05], help="shutter times (s)")
    args = ap.parse_args(argv)
    if args.frames < 1 or not all(0 < e <= 0.1 for e in args.exposures):
        sys.stderr.write("bench.motion_blur: error: --frames must be >= 1 and exposures within (0, 0.1] s\n")
        return 2
    for d in (args.bikes_root, args.riders_root):
        if d and not os.path.isdir(d):
            sys.stderr.write(f"bench.motion_blur: error: no such folder: {d}\n")
            return 2
    results = {}
    run(results, None, args.bikes_root, args.riders_root, args.frames, tuple(args.exposures))
    print(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
