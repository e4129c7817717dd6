"""The Gaussian path against Blender at equal fidelity (issue 14): one interleaved run.

For N random 8-DoF poses of a trained bike (bike_gt's sampler: random pose, random ring camera),
a 512-sample Cycles reference (no denoising, adaptive threshold 0.005, its own seed) and, per pose,
every method rendered by persistent workers (bench/render_workers.py) that loaded their scene or
model once: Cycles 1, 2, 4, 8, 16 spp with and without OpenImageDenoise, Workbench, and our part
Gaussians. Timing modes, interleaved per pose (the method order rotates with the pose):
  "2 threads"   one worker, 2 threads;
  "2 processes" two workers with 1 thread each rendering at the same time; s/image = the slower
                one's time / 2 (throughput: what a 2-core machine produces per second);
  "1 thread"    one worker, 1 thread (Gaussians only by default).
Fidelity against the reference: box PSNR (RGB on black inside the union of both masks' box plus
8 px, as bike_relit) and mask IoU (alpha > 0.5); means over poses, times are medians.

Keys: blender_compare = {poses, size, reference_spp, rows}; bike_fidelity = {box_psnr, iou, ...} of our
Gaussians (issue 14's goal: ≥ 32 dB, ≥ 0.97); gaussian_vs_blender_equal_fidelity =
images/hour of our Gaussians ÷ images/hour of the cheapest Cycles setting that matches our box PSNR
(interpolated in log-spp between its sample counts), both as 2-process throughput;
gaussian_vs_blender_match says which setting that was. Chart: gaussian_vs_blender.png.
Run alone: `python -m bench.blender_compare --bike out/demo/bikes/city_00 --out out/bench`.
"""
import argparse
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

# the converged reference every Gaussian benchmark scores against
from bench.compare import REFERENCE_ADAPTIVE, REFERENCE_SAMPLES as REFERENCE_SPP

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SPP = (1, 2, 4, 8, 16)
# recorded in the references' job.json: references rendered before render.setup_lighting placed its
# suns at once were lit from straight above (the workers read the suns before any update), so a
# job.json without this value is another job and its references are rendered again
REFERENCE_LIGHTING = "studio suns following the pose"
GAUSS = "gaussians"


def methods(spp=SPP, workbench=True, antialiased=False):
    """name -> (worker engine, method spec, timing modes)."""
    m = {}
    for dn in ("NONE", "FAST"):
        for s in spp:
            name = f"cycles_{s}spp" + ("_denoised" if dn != "NONE" else "")
            m[name] = ("blender", {"engine": "cycles", "samples": s, "denoise": dn, "adaptive": 0.05, "seed": 0},
                       ("2t", "2p"))
    if workbench:
        m["workbench"] = ("blender", {"engine": "workbench"}, ("2t", "2p"))
    m[GAUSS] = ("gauss", {"engine": "gauss", "antialiased": antialiased}, ("1t", "2t", "2p"))
    return m


# -- the key ---------------------------------------------------------------------------------------

def match_cycles(curve, target_psnr):
    """Cheapest point of one Cycles family reaching target_psnr.

    curve: [(spp, box_psnr, s_per_image)] in increasing spp. Between the first two sample counts
    that bracket the target, spp and time are interpolated linearly in log2(spp). Returns
    {"spp", "s_per_image", "bound"}: bound "interpolated", "at_min" (the lowest spp already
    matches: its cost is an upper bound on what matching costs) or "above_max" (no setting
    reaches the target: the highest spp's cost is a lower bound). None for an empty curve."""
    if not curve:
        return None
    curve = sorted(curve)
    if curve[0][1] >= target_psnr:
        return {"spp": float(curve[0][0]), "s_per_image": curve[0][2], "bound": "at_min"}
    for (s0, p0, t0), (s1, p1, t1) in zip(curve, curve[1:]):
        if p0 < target_psnr <= p1:
            f = (target_psnr - p0) / (p1 - p0)
            l0, l1 = math.log2(s0), math.log2(s1)
            spp = 2 ** (l0 + f * (l1 - l0))
            return {"spp": spp, "s_per_image": t0 + f * (t1 - t0), "bound": "interpolated"}
    s, _, t = curve[-1]
    return {"spp": float(s), "s_per_image": t, "bound": "above_max"}


def equal_fidelity(rows):
    """rows: the stage's per-method rows ({method, family, spp, box_psnr, s_2p}). Returns
    (ratio, match): our images/hour ÷ those of the cheapest matching Cycles family point."""
    ours = next(r for r in rows if r["method"] == GAUSS)
    best = None
    for fam in ("cycles", "cycles_denoised"):
        curve = [(r["spp"], r["box_psnr"], r["s_2p"]) for r in rows if r.get("family") == fam]
        m = match_cycles(curve, ours["box_psnr"])
        if m and (best is None or m["s_per_image"] < best["s_per_image"]):
            best = dict(m, family=fam)
    if best is None:
        return None, None
    ratio = (3600 / ours["s_2p"]) / (3600 / best["s_per_image"])
    best.update(target_box_psnr=ours["box_psnr"], gaussian_s_2p=ours["s_2p"],
                gaussian_images_per_hour=3600 / ours["s_2p"], cycles_images_per_hour=3600 / best["s_per_image"])
    return ratio, best


# -- metrics ---------------------------------------------------------------------------------------

def fidelity(ref_png, png):
    from bench.compare import load_rgba, mask_iou, psnr, union_box

    ref, m_ref = load_rgba(ref_png)
    img, m = load_rgba(png)
    x0, y0, x1, y1 = union_box(m, m_ref, pad=8)
    return psnr(img[y0:y1, x0:x1], ref[y0:y1, x0:x1]), mask_iou(m, m_ref)


# -- workers ---------------------------------------------------------------------------------------

class Worker:
    """A bench/render_workers.py process; ask() sends one command and waits for its reply."""

    def __init__(self, engine, bike_dir, log):
        self.engine = engine
        self.p = subprocess.Popen([sys.executable, "-m", "bench.render_workers", "--engine", engine, "--bike", bike_dir],
                                  cwd=ROOT, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=log, text=True,
                                  env=dict(os.environ, PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", "")))
        self.recv("start")

    def send(self, cmd):
        self.p.stdin.write(json.dumps(cmd) + "\n")
        self.p.stdin.flush()

    def recv(self, what):
        line = self.p.stdout.readline()
        if not line:
            raise RuntimeError(f"blender_compare: the {self.engine} worker died during {what} (see its log)")
        r = json.loads(line)
        if not r.get("ok"):
            raise RuntimeError(f"blender_compare: {self.engine} worker failed on {what}: {r.get('error')}")
        return r

    def ask(self, cmd, what):
        self.send(cmd)
        return self.recv(what)

    def close(self):
        if self.p.poll() is None:
            try:
                self.send({"op": "quit"})
                self.p.wait(timeout=30)
            except (OSError, subprocess.TimeoutExpired):
                self.p.kill()
                self.p.wait()


def _cmd(pose, cam, method, threads, out):
    K, R, T = cam
    return {"op": "render", "pose": [float(v) for v in pose], "K": np.asarray(K).tolist(), "R": np.asarray(R).tolist(),
            "T": np.asarray(T).tolist(), "method": method, "threads": threads, "out": out}


def cameras(bike_dir, cam_ids, size):
    """Ring cameras (views/whole/cameras.json) at `size` pixels: the same view, focal scaled."""
    from cyclist_formats import ring

    cams, _ = ring.read_cameras_json(os.path.join(bike_dir, "views", "whole", "cameras.json"))
    names = sorted(cams)
    out = []
    for c in cam_ids:
        K, R, T = (np.asarray(x, np.float64) for x in cams[names[int(c)]])
        K = K.copy()
        K[:2] *= size / (2 * K[0, 2])
        out.append((K, R, T))
    return out


def render_references(workers, poses, cams, ref_dir, spp, progress, adaptive=REFERENCE_ADAPTIVE):
    """The 512-sample references, split over the Blender workers (1 thread each); reused when the
    job file beside them matches (same bike, poses, cameras, size, spp and threshold)."""
    method = {"engine": "cycles", "samples": spp, "denoise": "NONE", "adaptive": adaptive, "seed": 1}
    todo = [i for i in range(len(poses)) if not os.path.isfile(os.path.join(ref_dir, f"ref_{i:03d}.png"))]
    for k in range(0, len(todo), len(workers)):
        batch = todo[k:k + len(workers)]
        for w, i in zip(workers, batch):
            w.send(_cmd(poses[i], cams[i], method, 1, os.path.join(ref_dir, f"ref_{i:03d}.png")))
        for w, i in zip(workers, batch):
            w.recv(f"reference {i}")
        progress(f"blender_compare: references {min(k + len(workers), len(todo))}/{len(todo)} ({spp} spp)")


def run_compare(bike_dir, out_dir, n_poses=12, size=512, seed=0, spp=SPP, reference_spp=REFERENCE_SPP,
                workbench=True, antialiased=None, progress=print):
    """The interleaved run. Returns (rows, per-pose records)."""
    from bench.bike_gt import sample_poses
    from bench.provenance import RENDER_CODE, bike_assets, code_version, file_hash
    from cyclist_formats.atomic import write_json

    if antialiased is None:
        antialiased = trained_antialiased(bike_dir)
    poses, cam_ids = sample_poses(n_poses, seed)
    cams = cameras(bike_dir, cam_ids, size)
    work = os.path.join(out_dir, "blender_compare")
    ref_dir = os.path.join(work, "reference")
    os.makedirs(ref_dir, exist_ok=True)
    job = {"bike": os.path.abspath(bike_dir), "poses": poses.tolist(), "cameras": cam_ids.tolist(), "size": size,
           "reference_spp": reference_spp, "reference_adaptive": REFERENCE_ADAPTIVE,
           "lighting": REFERENCE_LIGHTING,
           # references are reused only for the same bike files, ring cameras and render code
           "assets": bike_assets(bike_dir), "ring_cameras": file_hash(os.path.join(bike_dir, "views", "whole", "cameras.json")),
           "code": code_version(*RENDER_CODE)}
    job_path = os.path.join(ref_dir, "job.json")
    if not (os.path.isfile(job_path) and json.load(open(job_path)) == job):
        for f in os.listdir(ref_dir):  # references of another job
            os.remove(os.path.join(ref_dir, f))
        write_json(job_path, job)
    ms = methods(spp, workbench, antialiased)
    log = open(os.path.join(work, "workers.log"), "w")
    workers = {}
    try:
        engines = {e for e, _, _ in ms.values()}
        if not all(os.path.isfile(os.path.join(ref_dir, f"ref_{i:03d}.png")) for i in range(n_poses)):
            engines.add("blender")
        for eng in sorted(engines):
            workers[eng] = [Worker(eng, bike_dir, log), Worker(eng, bike_dir, log)]
        if "blender" in workers:
            render_references(workers["blender"], poses, cams, ref_dir, reference_spp, progress)
        # warm-up: first renders load kernels, build the BVH, start GL; none of that is per image
        for name, (eng, spec, _) in ms.items():
            for w in workers[eng]:
                w.ask(_cmd(poses[0], cams[0], spec, 1, os.path.join(work, "warmup.png")), f"warm-up {name}")
        recs = []
        names = list(ms)
        for i in range(n_poses):
            order = names[i % len(names):] + names[:i % len(names)]
            for name in order:
                eng, spec, modes = ms[name]
                a, b = workers[eng]
                png = os.path.join(work, f"{name}_{i:03d}.png")
                rec = {"pose": i, "method": name}
                for mode in modes:
                    if mode == "2p":
                        a.send(_cmd(poses[i], cams[i], spec, 1, png))
                        b.send(_cmd(poses[i], cams[i], spec, 1, os.path.join(work, f"{name}_{i:03d}_b.png")))
                        rec["s_2p"] = max(a.recv(name)["s"], b.recv(name)["s"]) / 2
                    else:
                        rec["s_" + mode] = a.ask(_cmd(poses[i], cams[i], spec, int(mode[0]), png), name)["s"]
                rec["box_psnr"], rec["iou"] = fidelity(os.path.join(ref_dir, f"ref_{i:03d}.png"), png)
                recs.append(rec)
            progress(f"blender_compare: pose {i + 1}/{n_poses}")
    finally:
        for ws in workers.values():
            for w in ws:
                w.close()
        log.close()
    rows = []
    for name, (eng, spec, modes) in ms.items():
        rs = [r for r in recs if r["method"] == name]
        row = {"method": name, "box_psnr": float(np.mean([r["box_psnr"] for r in rs])),
               "iou": float(np.mean([r["iou"] for r in rs]))}
        for mode in ("1t", "2t", "2p"):
            if mode in modes:
                row["s_" + mode] = float(np.median([r["s_" + mode] for r in rs]))
        if spec["engine"] == "cycles":
            row["family"] = "cycles_denoised" if spec["denoise"] != "NONE" else "cycles"
            row["spp"] = spec["samples"]
        rows.append(row)
    return rows, recs


def trained_antialiased(bike_dir):
    """Whether the bike's parts were trained with antialiased splatting (BikeModel's rule: their
    training JSONs; parts that disagree are an error)."""
    from splatting.bike.model import present_parts, trained_antialiased as parts_antialiased

    gdir = os.path.join(bike_dir, "gaussians")
    return parts_antialiased(gdir, present_parts(gdir))


# -- outputs ---------------------------------------------------------------------------------------

LABELS = {"1t": "1 thread", "2t": "2 threads", "2p": "2 processes"}


def table(rows):
    def s(r, k):
        return f"{r[k]:.3f}" if k in r else ""

    lines = ["| method | s/image, 1 thread | s/image, 2 threads | s/image, 2 processes × 1 thread | "
             "images/hour (2 processes) | box PSNR dB | mask IoU |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['method']} | {s(r, 's_1t')} | {s(r, 's_2t')} | {s(r, 's_2p')} | {3600 / r['s_2p']:.0f} "
                     f"| {r['box_psnr']:.2f} | {r['iou']:.4f} |")
    return lines


def chart(rows, match, ratio, png, title):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cyclist_formats.atomic import atomic_path

    fig, ax = plt.subplots(figsize=(7.5, 4.6))
    for fam, lab, mk in (("cycles", "Cycles, no denoising", "o"), ("cycles_denoised", "Cycles + OpenImageDenoise", "s")):
        rs = sorted((r for r in rows if r.get("family") == fam), key=lambda r: r["spp"])
        if rs:
            ax.plot([r["s_2p"] for r in rs], [r["box_psnr"] for r in rs], marker=mk, label=lab)
            for r in rs:
                ax.annotate(f"{r['spp']}", (r["s_2p"], r["box_psnr"]), textcoords="offset points", xytext=(4, -10), fontsize=7)
    for r in rows:
        if r["method"] == "workbench":
            ax.plot([r["s_2p"]], [r["box_psnr"]], marker="^", ls="", color="grey", label="Workbench")
        if r["method"] == GAUSS:
            ax.plot([r["s_2p"]], [r["box_psnr"]], marker="*", ms=14, ls="", color="crimson", label="our Gaussians")
    if match:
        ax.plot([match["s_per_image"]], [match["target_box_psnr"]], marker="x", ms=10, ls="", color="k",
                label=f"Cycles at equal fidelity ({match['spp']:.1f} spp, {match['bound']})")
    ax.set_xscale("log")
    ax.set_xlabel("s per image, 2 processes × 1 thread (throughput on 2 cores)")
    ax.set_ylabel("box PSNR vs 512-spp reference (dB)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(title + (f"\ngaussian_vs_blender_equal_fidelity = {ratio:.2f}" if ratio else ""), fontsize=8)
    fig.tight_layout()
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


def find_bike(bikes_dirs):
    """The first bike with trained frame and steering Gaussians, a .blend and ring cameras."""
    for d in bikes_dirs:
        for b in sorted(os.listdir(d)) if os.path.isdir(d) else []:
            p = os.path.join(d, b)
            if all(os.path.isfile(os.path.join(p, f)) for f in ("bike.blend", "gaussians/frame.ply", "gaussians/steering.ply",
                                                                  "views/whole/cameras.json")):
                return p
    return None


def run(results, out_dir, bike_dir=None, n_poses=12, size=512, seed=0, spp=SPP, reference_spp=REFERENCE_SPP,
        workbench=True, png=None, progress=print, tag=""):
    """tag: a suffix for the table, per-pose JSON and chart (a Gaussians-only rerun beside a full one)."""
    from bench.provenance import not_measured, record

    fallback = None
    if bike_dir is None:  # the bench's own trained bike; the demo's only as a recorded fallback
        own, demo = os.path.join(out_dir, "bikes"), os.path.join(ROOT, "out", "demo", "bikes")
        bike_dir = find_bike([own])
        if bike_dir is None:
            bike_dir = find_bike([demo])
            if bike_dir is not None:
                fallback = f"no trained bike under {own}: used the demo's {bike_dir}"
                progress(f"blender_compare: {fallback}")
    if bike_dir is None:
        why = (f"no trained bike (bike.blend + gaussians/frame.ply, steering.ply) under {out_dir}/bikes "
               "or out/demo/bikes")
        print(f"blender_compare: {why} - skipped")
        for k in ("blender_compare", "bike_fidelity", "gaussian_vs_blender_equal_fidelity"):
            not_measured(results, k, why)
        return None
    bike_dir = os.path.abspath(bike_dir)
    t = time.time()
    load0 = os.getloadavg()[0]
    rows, recs = run_compare(bike_dir, out_dir, n_poses, size, seed, spp, reference_spp, workbench, progress=progress)
    ratio, match = equal_fidelity(rows)
    results["blender_compare"] = {"bike": os.path.basename(os.path.normpath(bike_dir)), "bike_dir": bike_dir,
                                  "bike_fallback": fallback, "poses": n_poses, "size": size,
                                  "reference_spp": reference_spp, "reference_adaptive": REFERENCE_ADAPTIVE, "load_1min": [round(load0, 2), round(os.getloadavg()[0], 2)],
                                  "rows": rows}
    ours = next(r for r in rows if r["method"] == GAUSS)
    # the trained bike's fidelity at random poses against the 512-spp reference (issue 14's goal)
    results["bike_fidelity"] = {"bike": results["blender_compare"]["bike"], "poses": n_poses, "size": size,
                                "reference_spp": reference_spp, "box_psnr": ours["box_psnr"], "iou": ours["iou"]}
    if ratio is not None:
        results["gaussian_vs_blender_equal_fidelity"] = ratio
        results["gaussian_vs_blender_match"] = match
    else:
        not_measured(results, "gaussian_vs_blender_equal_fidelity", "no Cycles setting brackets the Gaussians' box PSNR")
    for k in ("blender_compare", "bike_fidelity", "gaussian_vs_blender_equal_fidelity", "gaussian_vs_blender_match"):
        if k in results:
            record(results, k, "fresh", bike=bike_dir, **({"fallback": fallback} if fallback else {}))
    from bench.compare import write_table
    from cyclist_formats.atomic import write_json

    lines = table(rows)
    if match:
        lines.append(f"\nEqual fidelity: our Gaussians reach {match['target_box_psnr']:.2f} dB box PSNR at "
                     f"{match['gaussian_images_per_hour']:.0f} images/hour; Cycles ({match['family']}) needs "
                     f"{match['spp']:.2f} spp ({match['bound']}) = {match['cycles_images_per_hour']:.0f} images/hour: "
                     f"gaussian_vs_blender_equal_fidelity = {ratio:.2f}.")
    write_table(out_dir, f"blender_compare{tag}_table.md", lines)
    write_json(os.path.join(out_dir, "blender_compare", f"per_pose{tag}.json"), recs)
    title = (f"{os.path.basename(os.path.normpath(bike_dir))}: {n_poses} random poses, {size}², vs {reference_spp}-spp Cycles; "
             f"medians, shared 2-core machine (load {load0:.1f})")
    chart(rows, match, ratio, png or os.path.join(out_dir, f"gaussian_vs_blender{tag}.png"), title)
    progress(f"blender_compare: {time.time() - t:.0f} s")
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.blender_compare", description=__doc__.splitlines()[0])
    ap.add_argument("--bike", help="trained bike folder (default: first under OUT/bikes, then out/demo/bikes)")
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    ap.add_argument("--poses", type=int, default=12)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--reference-spp", type=int, default=REFERENCE_SPP)
    ap.add_argument("--spp", default=",".join(map(str, SPP)), help="Cycles sample counts to compare")
    ap.add_argument("--no-workbench", action="store_true")
    ap.add_argument("--gaussians-only", action="store_true",
                    help="score only our Gaussians (e.g. retrained parts) against the cached references; no key")
    ap.add_argument("--quick", action="store_true", help="3 poses at 256², 128-spp reference (a smoke run)")
    ap.add_argument("--png", help="chart path (default OUT/gaussian_vs_blender.png)")
    a = ap.parse_args(argv)
    sys.path.insert(0, ROOT)
    from cyclist_formats import checks
    from cyclist_formats.errors import UserError

    try:
        if a.quick:
            a.poses, a.size, a.reference_spp = 3, 256, 128
        checks.count("poses", a.poses, hi=1000)
        checks.image_size("size", a.size)
        checks.count("reference_spp", a.reference_spp, hi=1 << 16)
        try:
            spp = tuple(sorted(int(x) for x in a.spp.split(",")))
        except ValueError:
            raise UserError(f"--spp must be comma-separated integers, got '{a.spp}'")
        for s in spp:
            checks.count("spp", s, hi=1 << 16)
        if a.bike:
            checks.input_dir("bike", a.bike)
        checks.output_dir("out", a.out)
    except UserError as e:
        sys.stderr.write(f"blender_compare: error: {e}\n")
        return 2
    os.makedirs(a.out, exist_ok=True)
    res = {}
    if a.gaussians_only:
        spp, a.no_workbench = (), True
    if run(res, a.out, a.bike, a.poses, a.size, a.seed, spp, a.reference_spp, not a.no_workbench, a.png,
           tag="_gaussians_only" if a.gaussians_only else "") is None:
        return 1
    print(json.dumps({k: v for k, v in res.items() if k != "blender_compare"}, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
