"""Chart: held-out PSNR against wall time and against Gaussian count, for several budgets.

Trains one part (default: the frame of the first bike with views) once per `--max-gaussians`
budget and draws both curves from the trainer's PSNR history (held-out views, object box) into
one PNG; the raw histories go to a JSON beside it. Run alone:
`python -m bench.train_chart --bikes out/bench/bikes --budgets 5000,15000,40000`.

Fidelity runs (`--runs RUNS.json --reference REF_VIEWS`): each run is {"label", "views" (a views
folder of the part, e.g. rendered with other Cycles samples / denoising), and any TrainConfig
field ("max_gaussians", "antialiased", "iterations", "time_budget_s", ...)}; every trained model is
scored against a clean reference of the held-out cameras (a views folder of the same part where
only those cameras were rendered, e.g. at 1024 spp without denoising): box PSNR (RGB on black in
the union of both masks' box + 8 px) and mask IoU, as bench/blender_compare.py scores whole bikes.
That chart (box PSNR vs training time and vs Gaussians) is what chose the training defaults
(docs/training.md).
"""
import json
import os
import sys

BUDGETS = (5000, 15000, 40000)


def draw(runs, png, title=""):
    """runs: [{"budget", "history": [[it, wall_s, psnr, n], ...], "psnr", "gaussians", "wall_s"}]."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for r in runs:
        h = r["history"]
        lab = f"budget {r['budget'] // 1000}k: {r['psnr']:.1f} dB whole image, {r['gaussians']} G, {r['wall_s']:.0f} s"
        line, = a.plot([x[1] for x in h], [x[2] for x in h], marker="o", ms=3, label=lab)
        b.plot([x[3] for x in h], [x[2] for x in h], marker="o", ms=3, color=line.get_color())
        b.plot([h[-1][3]], [h[-1][2]], marker="*", ms=12, color=line.get_color())
    a.set_xlabel("wall time (s)")
    a.set_ylabel("held-out PSNR, object box (dB)")
    b.set_xlabel("Gaussians")
    b.set_xscale("log")
    a.axhline(30, color="grey", lw=0.8, ls="--")
    b.axhline(30, color="grey", lw=0.8, ls="--")
    a.legend(fontsize=7, loc="lower right")
    a.grid(alpha=0.3)
    b.grid(alpha=0.3)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
    from cyclist_formats.atomic import atomic_path

    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def run(results, bikes_dir="out/bikes", bike=None, part="frame", budgets=BUDGETS, threads=1,
        png="out/bench/train_chart.png", time_budget_s=None):
    from bench.train_parts import find_bike
    from cyclist_formats.atomic import write_json
    from cyclist_formats.typed_config import updated
    from splatting.training.trainer import TrainConfig, train_views
    from splatting.training.views import load_views

    b, parts = find_bike(bikes_dir, bike)
    if part not in parts:
        print(f"train_chart: skipped, no complete views/{part} under {bikes_dir}", flush=True)
        from bench.provenance import not_measured
        not_measured(results, "train_chart (chart only)", f"no complete views/{part} under {bikes_dir}")
        return results
    views = load_views(os.path.join(bikes_dir, b, "views", part))
    runs = []
    for budget in budgets:
        cfg = updated(TrainConfig(threads=threads), densify={"max_gaussians": budget},
                      **({"time_budget_s": time_budget_s} if time_budget_s else {}))
        print(f"train_chart: {b}/{part}, budget {budget} ...", flush=True)
        _, m = train_views(views, cfg)
        runs.append({"budget": budget, "history": m["psnr_history"], "psnr": m["psnr"], "ssim": m["ssim"],
                     "gaussians": m["gaussians"], "wall_s": m["wall_s"], "iterations": m["iterations"]})
        print(f"train_chart: budget {budget}: {m['psnr']:.2f} dB, {m['gaussians']} Gaussians, {m['wall_s']:.0f} s",
              flush=True)
    draw(runs, png, f"{b}/{part}: held-out views 3, 12, 21, 30; {threads} CPU threads (shared machine)")
    write_json(os.path.splitext(png)[0] + ".json", {"bike": b, "part": part, "threads": threads, "runs": runs})
    print(f"train_chart: wrote {png}", flush=True)
    return results


# -- fidelity against a clean reference ------------------------------------------------------------

def clean_fidelity(g, reference_dir, antialiased=False, eps2d=0.3):
    """Mean box PSNR and mask IoU of Gaussians g over the cameras that have an image in
    reference_dir (a views folder: cameras.json + rgba/cameraNNNN/0000.png), and the count.
    antialiased, eps2d: as g was trained (TrainConfig)."""
    import numpy as np
    import torch

    from bench.compare import load_rgba, union_box
    from bench.compare import mask_iou, psnr
    from splatting.raster.camera import load_cameras
    from splatting.raster.api import render_gaussians

    cams, _ = load_cameras(os.path.join(reference_dir, "cameras.json"))
    ps, ious = [], []
    for cam in cams:
        path = os.path.join(reference_dir, "rgba", cam.name, "0000.png")
        if not os.path.isfile(path):
            continue
        ref, m_ref = load_rgba(path)
        with torch.no_grad():
            o = render_gaussians(g, cam, antialiased=antialiased, eps2d=eps2d)
        img = o["rgb"].clamp(0, 1).double().numpy()
        m = o["alpha"].numpy() > 0.5
        x0, y0, x1, y1 = union_box(m, m_ref, pad=8)
        ps.append(psnr(img[y0:y1, x0:x1], ref[y0:y1, x0:x1]))
        ious.append(mask_iou(m, m_ref))
    if not ps:
        raise ValueError(f"train_chart: no reference images under {reference_dir}/rgba")
    return float(np.mean(ps)), float(np.mean(ious)), len(ps)


def config_for(spec, threads):
    """A TrainConfig from a run spec: TrainConfig fields, or DensifyConfig fields (max_gaussians...)."""
    from cyclist_formats.typed_config import updated
    from splatting.training.strategy import DensifyConfig
    from splatting.training.trainer import TrainConfig

    top, dens = {"threads": threads, "progress": False}, {}
    for k, v in spec.items():
        if k in ("label", "views"):
            continue
        if k in DensifyConfig.model_fields:
            dens[k] = v
        elif k in TrainConfig.model_fields:
            top[k] = tuple(v) if isinstance(v, list) else v
        else:
            raise ValueError(f"train_chart: unknown run field {k!r} (not in TrainConfig or DensifyConfig)")
    return updated(TrainConfig(), **top, densify=dens)


def run_fidelity(specs, reference_dir, png, threads=1, out_json=None):
    """Train every run spec, score it against the clean reference; chart + JSON (resumable: a run
    already in the JSON is reused, marked "reused": true, only when its spec, training views, reference
    folder and content, threads and code version all match: fidelity_key)."""
    from cyclist_formats.atomic import write_json
    from splatting.training.trainer import train_views
    from splatting.training.views import load_views

    out_json = out_json or os.path.splitext(png)[0] + ".json"
    done = []
    if os.path.isfile(out_json):
        with open(out_json) as f:
            done = json.load(f).get("runs", [])
    runs = []
    for spec in specs:
        key = fidelity_key(spec, reference_dir, threads)
        prev = next((r for r in done if r.get("key") == key), None)
        if prev:
            runs.append(dict(prev, reused=True))
            print(f"train_chart: {spec['label']}: reused (same spec, views, reference, threads and code)", flush=True)
            continue
        cfg = config_for(spec, threads)
        print(f"train_chart: {spec['label']} ...", flush=True)
        load0 = os.getloadavg()[0]
        g, m = train_views(load_views(spec["views"]), cfg)
        box, iou, n = clean_fidelity(g, reference_dir, cfg.antialiased, cfg.eps2d)
        r = {"spec": spec, "key": key, "reused": False, "label": spec["label"], "clean_box_psnr": box, "clean_iou": iou, "reference_views": n,
             "psnr_crop": m["psnr_crop"], "gaussians": m["gaussians"], "wall_s": m["wall_s"], "iterations": m["iterations"],
             "stopped": m["stopped"], "load_1min": [round(load0, 2), round(os.getloadavg()[0], 2)]}
        runs.append(r)
        print(f"train_chart: {spec['label']}: clean box PSNR {box:.2f} dB, IoU {iou:.4f}, {m['gaussians']} Gaussians, "
              f"{m['wall_s']:.0f} s, {m['iterations']} it ({m['stopped']}); own held-out box {m['psnr_crop']:.2f} dB",
              flush=True)
        write_json(out_json, {"reference": os.path.abspath(reference_dir), "threads": threads, "runs": runs})
    draw_fidelity(runs, png, f"held-out cameras vs clean reference ({os.path.basename(os.path.dirname(reference_dir))}"
                             f"/{os.path.basename(reference_dir)}); {threads} thread, shared 2-core machine")
    return runs


def draw_fidelity(runs, png, title=""):
    """Clean box PSNR of each run against its training wall time and its Gaussian count."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cyclist_formats.atomic import atomic_path

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.4), sharey=True)
    for i, r in enumerate(runs):
        mk = "os^Dv<>p*h"[i % 10]
        lab = f"{r['label']}: {r['clean_box_psnr']:.2f} dB, IoU {r['clean_iou']:.3f}{' (reused)' if r.get('reused') else ''}"
        line, = a.plot([r["wall_s"]], [r["clean_box_psnr"]], marker=mk, ms=8, ls="", label=lab)
        b.plot([r["gaussians"]], [r["clean_box_psnr"]], marker=mk, ms=8, ls="", color=line.get_color())
    a.set_xlabel("training wall time (s)")
    a.set_ylabel("box PSNR vs clean reference (dB)")
    b.set_xlabel("Gaussians")
    b.set_xscale("log")
    for ax in (a, b):
        ax.grid(alpha=0.3)
    a.legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(png)), exist_ok=True)
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


# -- whole bikes at random poses ---------------------------------------------------------------------

def bike_fidelity(bike_dir, reference_dir, model=None):
    """Box PSNR and mask IoU (means) of a bike's composed parts at the poses of a blender_compare
    reference folder (ref_NNN.png + job.json), scored as blender_compare scores its Gaussians (8-bit
    straight-alpha PNG, union box + 8 px), and the bike's one-time training wall time (parts +
    bike-posed-train, from their JSONs). model: the bike if already loaded (BikeModel.load(bike_dir))."""
    import numpy as np
    import torch

    from bench.blender_compare import cameras, fidelity
    from cyclist_formats.atomic import atomic_path
    from splatting.bike.model import BikeModel, part_metrics_path
    from splatting.raster.camera import from_numpy
    from splatting.raster.api import render_gaussians

    with open(os.path.join(reference_dir, "job.json")) as f:
        job = json.load(f)
    model = BikeModel.load(bike_dir) if model is None else model
    cams = cameras(bike_dir, job["cameras"], job["size"])
    ps, ious = [], []
    import tempfile

    tmpdir = tempfile.mkdtemp(prefix="bike_fidelity_")
    for i, pose in enumerate(job["poses"]):
        with torch.no_grad():
            o = render_gaussians(model.pose(torch.tensor(pose, dtype=torch.float64)).gaussians, from_numpy(*cams[i]),
                                 antialiased=model.antialiased, eps2d=model.eps2d)  # drawn as trained
        a = o["alpha"].clamp(0, 1)
        rgba = torch.cat([(o["rgb"] / a.clamp_min(1e-6)[..., None]).clamp(0, 1), a[..., None]], -1)
        from PIL import Image
        png = os.path.join(tmpdir, f"{i:03d}.png")  # the PNG blender_compare's gauss worker writes
        with atomic_path(png) as tmp:
            Image.fromarray((rgba.numpy() * 255).round().astype(np.uint8), "RGBA").save(tmp, format="PNG")
        p, iou = fidelity(os.path.join(reference_dir, f"ref_{i:03d}.png"), png)
        os.remove(png)
        ps.append(p)
        ious.append(iou)
    os.rmdir(tmpdir)
    gdir = os.path.join(bike_dir, "gaussians")
    # every part's training metrics are required (a missing one added 0 s before); the posed fine-tune
    # is optional (a bike without it has no posed_train.json), but one that ran must say how long
    walls = [_wall_s(part_metrics_path(gdir, name), f"{bike_dir}: part {name}") for name in model.part_names]
    posed = os.path.join(gdir, "posed_train.json")
    if os.path.isfile(posed):
        walls.append(_wall_s(posed, f"{bike_dir}: posed fine-tune"))
    return {"box_psnr": float(np.mean(ps)), "iou": float(np.mean(ious)), "poses": len(ps), "train_wall_s": float(sum(walls)),
            "posed_train": os.path.isfile(posed), "gaussians": len(model), "eps2d": model.eps2d,
            "per_pose": [{"box_psnr": round(float(p), 4), "iou": round(float(i), 5)} for p, i in zip(ps, ious)]}


def _wall_s(path, what):
    """wall_s of a training metrics JSON; a ValueError naming it when the file or the number is missing."""
    from cyclist_formats.atomic import read_json_or_none

    m = read_json_or_none(path) if path is not None and os.path.isfile(path) else None
    if not isinstance(m, dict) or not isinstance(m.get("wall_s"), (int, float)):
        raise ValueError(f"train_chart: {what}: no training wall_s ({path or 'no metrics JSON'})")
    return float(m["wall_s"])


def fidelity_key(spec, reference_dir, threads):
    """What a fidelity run's numbers depend on: its spec, the training views' and the clean reference's
    content, the thread count and the training/scoring code."""
    from bench.provenance import code_version, tree_hash

    return {"spec": spec, "views": tree_hash(spec["views"]), "reference": os.path.abspath(reference_dir),
            "reference_hash": tree_hash(reference_dir), "threads": threads,
            "code": code_version("splatting", "cyclist_formats", "bench/train_chart.py", "bench/compare.py")}


def draw_bike_fidelity(rows, png, title=""):
    """Whole-bike box PSNR and IoU at random poses against the one-time training wall time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cyclist_formats.atomic import atomic_path

    fig, (a, b) = plt.subplots(1, 2, figsize=(11, 4.2))
    for i, r in enumerate(rows):
        mk = "os^Dv<>p*h"[i % 10]
        line, = a.plot([r["train_wall_s"]], [r["box_psnr"]], marker=mk, ms=9, ls="",
                       label=f"{r['label']}: {r['box_psnr']:.2f} dB, IoU {r['iou']:.3f}")
        b.plot([r["train_wall_s"]], [r["iou"]], marker=mk, ms=9, ls="", color=line.get_color())
    a.axhline(32, color="grey", lw=0.8, ls="--")
    b.axhline(0.97, color="grey", lw=0.8, ls="--")
    a.set_ylabel("box PSNR vs 512-spp Cycles (dB)")
    b.set_ylabel("mask IoU")
    for ax in (a, b):
        ax.set_xlabel("training wall time, all parts (s, shared machine)")
        ax.grid(alpha=0.3)
    a.legend(fontsize=7, loc="best")
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    with atomic_path(png) as tmp:
        fig.savefig(tmp, dpi=110, format="png")
    plt.close(fig)


if __name__ == "__main__":
    from bench.train_parts import training_args
    ap = training_args(__doc__)
    ap.add_argument("--part", default="frame")
    ap.add_argument("--budgets", default=",".join(map(str, BUDGETS)))
    ap.add_argument("--png", default="out/bench/train_chart.png")
    ap.add_argument("--runs", help="JSON list of run specs (fidelity mode, see above)")
    ap.add_argument("--reference", help="views folder with clean renders of the held-out cameras (fidelity mode)")
    ap.add_argument("--bike-fidelity", metavar="LABEL=BIKE,...",
                    help="whole trained bikes scored at the poses of --bike-reference (blender_compare's reference folder)")
    ap.add_argument("--bike-reference", help="a blender_compare reference folder (ref_NNN.png, job.json)")
    a = ap.parse_args()
    sys.path.insert(0, os.getcwd())
    if a.bike_fidelity or a.bike_reference:
        specs = [x.split("=", 1) for x in (a.bike_fidelity or "").split(",") if x]
        if not (a.bike_fidelity and a.bike_reference) or any(len(x) != 2 or not os.path.isdir(x[1]) for x in specs) \
                or not os.path.isfile(os.path.join(a.bike_reference, "job.json")):
            sys.stderr.write("train_chart: error: --bike-fidelity LABEL=BIKE_DIR,... needs existing bike folders and "
                             "--bike-reference a folder with job.json\n")
            raise SystemExit(2)
        from bench.blender_compare import REFERENCE_LIGHTING
        from cyclist_formats.atomic import read_json_or_none

        job = read_json_or_none(os.path.join(a.bike_reference, "job.json"))
        if not isinstance(job, dict) or job.get("lighting") != REFERENCE_LIGHTING:
            sys.stderr.write(f"train_chart: error: {a.bike_reference}: references from before the sun fix (lit from "
                             "above, not as the training views); render them again with bench/blender_compare.py\n")
            raise SystemExit(2)
        from cyclist_formats.errors import UserError
        from splatting.bike.model import BikeModel

        models = []
        for label, d in specs:  # every bike readable before any scoring: one line, not a traceback
            try:
                models.append(BikeModel.load(d))
            except (UserError, OSError, ValueError, KeyError) as e:
                sys.stderr.write(f"train_chart: error: --bike-fidelity {label}={d}: {e}\n")
                raise SystemExit(2)
        rows = []
        for (label, d), model in zip(specs, models):
            rows.append(dict(bike_fidelity(d, a.bike_reference, model), label=label, bike=d))
            print(json.dumps(rows[-1]), flush=True)
        from cyclist_formats.atomic import write_json
        write_json(os.path.splitext(a.png)[0] + ".json", {"reference": os.path.abspath(a.bike_reference), "rows": rows})
        draw_bike_fidelity(rows, a.png, f"whole bike at {rows[0]['poses']} random 8-DoF poses vs 512-spp Cycles "
                                        f"({os.path.basename(os.path.normpath(specs[0][1]))}); shared 2-core machine")
        raise SystemExit(0)
    if bool(a.runs) != bool(a.reference):
        sys.stderr.write("train_chart: error: --runs and --reference go together\n")
        raise SystemExit(2)
    if a.runs:
        from cyclist_formats.bike_folder import read_json
        from cyclist_formats.errors import UserError
        try:
            specs = read_json(a.runs, "run specs")
            for sp in specs:
                config_for(sp, a.threads)
                if not os.path.isfile(os.path.join(sp["views"], "cameras.json")):
                    raise UserError(f"run {sp.get('label')!r}: no cameras.json in {sp['views']}")
            if not os.path.isfile(os.path.join(a.reference, "cameras.json")):
                raise UserError(f"--reference {a.reference} has no cameras.json")
        except (UserError, ValueError, KeyError, TypeError) as e:
            sys.stderr.write(f"train_chart: error: {e}\n")
            raise SystemExit(2)
        run_fidelity(specs, a.reference, a.png, a.threads)
    else:
        run({}, a.bikes, a.bike, a.part, [int(x) for x in a.budgets.split(",")], a.threads, a.png, a.time_budget_s)
