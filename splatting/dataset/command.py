"""`python -m splatting dataset --config CONFIG.yaml | --preset NAME [--out DIR]`: a COCO training set.

Output: DIR/images/%06d.png, DIR/annotations.json (COCO: visible and amodal RLE masks and boxes,
keypoints with visibility and sigmas, occlusion, truncation, 3D pose; docs/labels.md),
DIR/config.json (the resolved config); with `--format kitti` also DIR/kitti/ (KITTI object layout).
Per-sample shards (DIR/shards/%06d.json) are written atomically after the sample's image; a rerun
skips samples whose shard and image exist and merges all shards at the end, so a run killed at
any moment and rerun gives the same bytes as an uninterrupted one.
"""
import json
import os
import sys
import time

from cyclist_formats.atomic import write_json
from cyclist_formats.errors import UserError


def add_arguments(p):
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", help="YAML config (see docs/cyclists_and_datasets.md)")
    src.add_argument("--preset", help="built-in config from blend_assets/datasets/ (bike-only, cyclist, street)")
    p.add_argument("--out", help="output folder (default: out/datasets/<name>)")
    p.add_argument("--count", type=int, help="override the config's count")
    p.add_argument("--seed", type=int, help="override the config's seed")
    p.add_argument("--image-size", type=int, help="override the config's image_size")
    p.add_argument("--bikes-root", help="override the config's bikes_root")
    p.add_argument("--format", action="append", choices=("coco", "kitti"),
                   help="label format(s) to write (repeat for both); overrides the config's labels.formats")
    p.add_argument("--camera", help="override the config's camera.preset (street mode)")
    p.add_argument("--workers", type=int, default=1, help="worker processes, one torch thread each (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")


_WORKER = {}


def _init_worker(cfg, out_dir):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.generate import Assets
    _WORKER.update(cfg=cfg, out=out_dir, assets=Assets(cfg))


def _work(index):
    from splatting.dataset.generate import write_sample
    return write_sample(_WORKER["cfg"], index, _WORKER["out"], _WORKER["assets"])


def generate(cfg, out_dir, workers=1, log=print, progress=True):
    """Make (or finish) the dataset in out_dir; returns {"annotations", "generated", "skipped", "wall_s"}."""
    from splatting.dataset.coco import merge
    from splatting.dataset.config import resolve_assets
    from splatting.dataset.generate import config_record, sample_done

    cfg = config_record(resolve_assets(cfg))
    os.makedirs(out_dir, exist_ok=True)
    cpath = os.path.join(out_dir, "config.json")
    if os.path.isfile(cpath):
        with open(cpath) as f:
            old = json.load(f)
        if old != cfg:
            diff = sorted(k for k in set(old) | set(cfg) if old.get(k) != cfg.get(k))
            raise UserError(f"{out_dir} holds a dataset made with a different config (fields {', '.join(diff)} "
                            f"differ); use another --out or delete it")
    else:
        write_json(cpath, cfg)
    todo = [i for i in range(cfg["count"]) if not sample_done(out_dir, i, cfg)]
    skipped = cfg["count"] - len(todo)
    if skipped:
        log(f"dataset: {skipped} of {cfg['count']} samples already done, resuming")
    t0, last = time.time(), 0.0

    def tick(done):
        nonlocal last
        now = time.time()
        if progress and (now - last > 2.0 or done == len(todo)):
            last = now
            rate = done / max(now - t0, 1e-9)
            eta = (len(todo) - done) / rate if rate > 0 else float("inf")
            sys.stderr.write(f"dataset: {skipped + done}/{cfg['count']} samples, {rate:.2f} img/s, eta {eta:.0f} s\n")
            sys.stderr.flush()

    if todo:
        if workers <= 1:
            _init_worker(cfg, out_dir)
            _WORKER["assets"].log = log
            for n, i in enumerate(todo, 1):
                _work(i)
                tick(n)
        else:
            import multiprocessing as mp
            with mp.get_context("fork").Pool(workers, _init_worker, (cfg, out_dir)) as pool:
                for n, _ in enumerate(pool.imap_unordered(_work, todo, chunksize=1), 1):
                    tick(n)
    from splatting.dataset.labels import categories
    info = {"description": f"3DArticCyclists synthetic {cfg['mode']} set '{cfg['name']}'", "seed": cfg["seed"],
            "count": cfg["count"], "image_size": cfg["image_size"], "person_keypoints": cfg["keypoints"]["person"],
            "camera": cfg["camera"]["preset"], "labels": "docs/labels.md"}
    path = merge(out_dir, cfg["count"], info, categories(cfg["labels"], cfg["keypoints"]["person"]))
    if "kitti" in cfg["labels"]["formats"]:
        from splatting.dataset.kitti import write_imagesets
        write_imagesets(out_dir, cfg["count"])
    return {"annotations": path, "generated": len(todo), "skipped": skipped, "wall_s": time.time() - t0}


def run(args):
    from splatting.dataset.config import load_config
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    nested = {}
    if args.format:
        nested["labels"] = {"formats": list(dict.fromkeys(args.format))}
    if args.camera:
        nested["camera"] = {"preset": args.camera}
    cfg = load_config(args.config, args.preset, {"count": args.count, "seed": args.seed,
                                                 "image_size": args.image_size, "bikes_root": args.bikes_root},
                      nested)
    out = args.out or os.path.join("out", "datasets", cfg["name"])
    log = (lambda *a: None) if args.quiet else (lambda m: print(m, flush=True))
    r = generate(cfg, out, args.workers, log=log, progress=not args.quiet)
    print(f"dataset: {cfg['count']} images in {out} ({r['generated']} generated, {r['skipped']} resumed, "
          f"{r['wall_s']:.1f} s); annotations: {r['annotations']}")
