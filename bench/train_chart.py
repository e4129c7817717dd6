"""Chart: held-out PSNR against wall time and against Gaussian count, for several budgets.

Trains one part (default: the frame of the first bike with views) once per `--max-gaussians`
budget and draws both curves from the trainer's PSNR history (held-out views, object box) into
one PNG; the raw histories go to a JSON beside it. Run alone:
`python -m bench.train_chart --bikes out/bench/bikes --budgets 5000,15000,40000`.
"""
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
    from splatting.training.trainer import TrainConfig, train_views
    from splatting.training.views import load_views

    b, parts = find_bike(bikes_dir, bike)
    if part not in parts:
        print(f"train_chart: skipped, no complete views/{part} under {bikes_dir}", flush=True)
        return results
    views = load_views(os.path.join(bikes_dir, b, "views", part))
    runs = []
    for budget in budgets:
        cfg = TrainConfig(threads=threads)
        cfg.densify.max_gaussians = budget
        if time_budget_s:
            cfg.time_budget_s = time_budget_s
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


if __name__ == "__main__":
    from bench.train_parts import training_args
    ap = training_args(__doc__)
    ap.add_argument("--part", default="frame")
    ap.add_argument("--budgets", default=",".join(map(str, BUDGETS)))
    ap.add_argument("--png", default="out/bench/train_chart.png")
    a = ap.parse_args()
    sys.path.insert(0, os.getcwd())
    run({}, a.bikes, a.bike, a.part, [int(x) for x in a.budgets.split(",")], a.threads, a.png, a.time_budget_s)
