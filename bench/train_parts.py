"""Per-part training benchmark: `train_parts` = [{"bike", "part", "psnr", "ssim", "gaussians", "wall_s", "reused"}].

Trains every part of one procedural bike with the fidelity recipe (splatting/bike/recipes.py: the one
that claims issue 14's 32 dB, so bike_fidelity measures it; held-out views 3, 12, 21, 30; PSNR over
white, the NeRF-synthetic convention) and
writes the Gaussians where the pipeline expects them (<bike>/gaussians/<part>.ply + .json), which
the later stages (bike_gt, blender_compare) score at random poses. Resumable: a part whose PLY and
metrics exist and were trained with the same configuration is reused, not trained again (the
recipe costs minutes per part on 2 cores). Needs the views from render_views.py; skips with a
message when they are missing. Run alone: `python -m bench.train_parts --bikes out/bench/bikes`.
"""
import argparse
import glob
import os
import sys

PARTS = ("frame", "steering", "crank")
RECIPE = "fidelity"  # the bench bike's asset recipe (splatting/bike/recipes.py)


def complete_views(d, n=36):
    """A views folder render_views.py has finished: cameras.json and every view's RGBA."""
    return (os.path.isfile(os.path.join(d, "cameras.json"))
            and len(glob.glob(os.path.join(d, "rgba", "camera*", "0000.png"))) >= n)


def find_bike(bikes_dir, bike=None):
    """The named bike, or the first (sorted) with complete views for at least one part."""
    ids = [bike] if bike else sorted(os.listdir(bikes_dir)) if os.path.isdir(bikes_dir) else []
    for b in ids:
        parts = [p for p in PARTS if complete_views(os.path.join(bikes_dir, b, "views", p))]
        if parts:
            return b, parts
    return None, []


# config fields that do not change what is trained
_RUNTIME_FIELDS = ("progress", "threads", "time_budget_s")


# config fields added since, with the value every part trained before them had
_ADDED_FIELDS = {"eps2d": 0.3}


def same_recipe(a, b):
    """Two trainer config dicts (PART.json "config") describe the same training."""
    a, b = {**_ADDED_FIELDS, **a}, {**_ADDED_FIELDS, **b}
    return {k: v for k, v in a.items() if k not in _RUNTIME_FIELDS} == {k: v for k, v in b.items() if k not in _RUNTIME_FIELDS}


def trained_with(ply, cfg):
    """The metrics of <part>.ply when it exists, was trained with cfg and was not cut short by the
    time cap (a capped run's learning rate never finished decaying); else None."""
    from cyclist_formats.atomic import read_json_or_none
    from cyclist_formats.typed_config import record_of

    js = os.path.splitext(ply)[0] + ".json"
    m = read_json_or_none(js) if os.path.isfile(ply) else None
    if not isinstance(m, dict) or not isinstance(m.get("config"), dict) or m.get("stopped") == "time_budget":
        return None
    return m if same_recipe(m["config"], record_of(cfg)) else None


def run(results, bikes_dir="out/bikes", bike=None, threads=1, max_gaussians=None, time_budget_s=None,
        parts=None):
    from bench.provenance import not_measured, record
    from cyclist_formats.typed_config import updated
    from splatting.bike.recipes import train_config
    from splatting.training.trainer import default_out, train

    b, found = find_bike(bikes_dir, bike)
    if not b:
        print(f"train_parts: skipped, no bike under {bikes_dir} has complete views/<part> folders "
              f"(run blender_scripts/render_views.py first)", flush=True)
        not_measured(results, "train_parts", f"no bike under {bikes_dir} has complete views/<part> folders")
        return results
    rows = results.setdefault("train_parts", [])
    for part in parts or found:
        if part not in found:
            print(f"train_parts: {b}/{part} has no complete views, skipped", flush=True)
            continue
        # the recipe is its iteration count: the trainer's 600 s cap would cut it short on a loaded
        # 2-core machine (the city frame took 1242 s under load 5-12), before the learning rate decays
        cfg = train_config(RECIPE, threads=threads, time_budget_s=time_budget_s or 3600.0)
        if max_gaussians:
            cfg = updated(cfg, densify={"max_gaussians": max_gaussians})
        views = os.path.join(bikes_dir, b, "views", part)
        m = trained_with(default_out(views), cfg)
        reused = m is not None
        if reused:
            print(f"train_parts: {b}/{part}: trained with this recipe already, reused", flush=True)
        else:
            print(f"train_parts: {b}/{part} ...", flush=True)
            m = train(views, None, cfg)  # newer than posed_train.json: bike_posed_train runs again
        row = {"bike": b, "part": part, "psnr": m["psnr"], "ssim": m["ssim"], "gaussians": m["gaussians"],
               "wall_s": m["wall_s"], "iterations": m["iterations"], "reused": reused}
        rows.append(row)
        print(f"train_parts: {b}/{part}: held-out PSNR {m['psnr']:.2f} dB, SSIM {m['ssim']:.4f}, "
              f"{m['gaussians']} Gaussians, {m['wall_s']:.0f} s ({m['iterations']} it, {m['stopped']}, "
              f"{m['threads']} threads{', reused' if reused else ''})", flush=True)
    if rows:
        n = sum(bool(r["reused"]) for r in rows)
        # reuse is keyed by the trainer's recipe (PART.json "config"); the views and the code that
        # trained it are not part of that key, so a reused row says so
        record(results, "train_parts", "reused" if n == len(rows) else "partly reused" if n else "fresh",
               bike=os.path.abspath(os.path.join(bikes_dir, b)),
               **({"reused_rows": f"{n} of {len(rows)}, same recipe (views and code version not checked)"} if n else {}))
    return results


def run_posed(results, bikes_dir="out/bikes", bike=None):
    """Stage bike_posed_train: the trained bike's parts fine-tuned together through the 8-DoF pose on
    posed Blender renders (splatting/bike/posed_train.py, RECIPE's second step), once:
    a bike already fine-tuned with the same config is reused. Key bike_posed_train = {bike,
    held-out posed views' box PSNR / IoU before and after, wall_s, reused}."""
    from bench.provenance import not_measured, record
    from splatting.bike.posed_train import done_with, train_bike_posed
    from splatting.bike.recipes import posed_config

    b, parts = find_bike(bikes_dir, bike)
    if not b or not all(os.path.isfile(os.path.join(bikes_dir, b, "gaussians", p + ".ply")) for p in parts):
        print(f"bike_posed_train: skipped, no bike under {bikes_dir} with trained parts", flush=True)
        not_measured(results, "bike_posed_train", f"no bike under {bikes_dir} with trained parts")
        return results
    d = os.path.join(bikes_dir, b)
    cfg = posed_config(RECIPE)
    m = done_with(d, cfg)
    reused = m is not None
    if reused:
        print(f"bike_posed_train: {b} fine-tuned with this config already, reused", flush=True)
    else:
        m = train_bike_posed(d, cfg, log=lambda s: print(s, flush=True))
    results["bike_posed_train"] = {"bike": b, "recipe": RECIPE, "reused": reused, "wall_s": m["wall_s"],
                                   **{k: m[k] for k in m if k.startswith("held_out_")}}
    record(results, "bike_posed_train", "reused" if reused else "fresh", bike=os.path.abspath(d),
           **({"reused": "same posed config (views and code version not checked)"} if reused else {}))
    return results


def training_args(doc):
    """The standalone command line shared by the training stages: which bikes, threads, time cap."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--bikes", default="out/bikes")
    ap.add_argument("--bike")
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--time-budget-s", type=float)
    return ap


if __name__ == "__main__":
    ap = training_args(__doc__)
    ap.add_argument("--parts", help="comma-separated (default: all found)")
    ap.add_argument("--max-gaussians", type=int)
    a = ap.parse_args()
    sys.path.insert(0, os.getcwd())
    r = run({}, a.bikes, a.bike, a.threads, a.max_gaussians, a.time_budget_s,
            a.parts.split(",") if a.parts else None)
    print(r)
