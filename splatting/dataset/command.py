"""`python -m splatting dataset --config CONFIG.yaml | --preset NAME [--out DIR]`: a COCO training set.

Output: DIR/images/%06d.png, DIR/annotations.json (COCO: visible and amodal RLE masks and boxes,
keypoints with visibility and sigmas, occlusion, truncation, 3D pose; docs/labels.md),
DIR/config.json (the resolved config); with `--format kitti` also DIR/kitti/ (KITTI object layout).
Per-sample shards (DIR/shards/%06d.json) are written atomically after the sample's image; a rerun
skips samples whose shard and image exist and merges all shards at the end, so a run killed at
any moment and rerun gives the same bytes as an uninterrupted one.
"""
import os
import sys
import time

from cyclist_formats import checks
from cyclist_formats.atomic import write_json
from cyclist_formats.errors import UserError
from cyclist_formats.text_files import read_json
from cyclist_formats.typed_config import add_model_arguments, overrides_of
from splatting.dataset.config_models import CLI_OVERRIDES, DatasetConfig, require_config
from splatting.library.ray_address import check_address

# The stage's modules are imported inside the functions below, not at the top: they load torch
# (~2.5 s, python -X importtime), and `--help` and the argument checks answer before that (0.2-0.5 s).
# config_models is torch-free (pydantic and the field declarations), so the flags come from it here.


def add_arguments(p):
    src = p.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", help="YAML config (see docs/cyclists_and_datasets.md)")
    src.add_argument("--preset", help="built-in config from blend_assets/datasets/ (bike-only, cyclist, street, street-sequence, kitti-insert, kitti-sequence)")
    p.add_argument("--out", help="output folder (default: out/datasets/<name>)")
    # the top-level fields a run may override: flags typed and described by the config's models
    add_model_arguments(p, DatasetConfig, CLI_OVERRIDES)
    p.add_argument("--format", action="append", choices=("coco", "kitti", "mot"),
                   help="label format(s) to write (repeat for several); overrides the config's labels.formats "
                        "(sequences: kitti = KITTI tracking, mot = MOTChallenge; docs/sequences.md)")
    p.add_argument("--camera", help="override the config's camera.preset (street mode)")
    p.add_argument("--workers", type=int, default=1, help="worker processes, one torch thread each (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    # scale-out (docs/scale_out.md)
    p.add_argument("--shard", help="K/N: generate only the samples whose index is K mod N, no merge "
                                   "(a Slurm array / Kubernetes Indexed Job task); then `dataset merge --out DIR`")
    p.add_argument("--engine", choices=("local", "ray"), default="local",
                   help="local: a process pool (--workers); ray: Ray tasks over index ranges, merged at the end")
    p.add_argument("--address", help="with --engine ray: 'auto' or HOST:PORT of a running cluster "
                                     "(default: start a local one)")
    p.add_argument("--allow-low-quality", action="store_true",
                   help="use library assets marked below the quality floor in library.json")


_WORKER = {}


def _init_worker(cfg, out_dir):
    import torch
    torch.set_num_threads(1)
    from splatting.dataset.generate import Assets
    _WORKER.update(cfg=cfg, out=out_dir, assets=Assets(cfg))


def _work(index):
    from splatting.dataset.generate import write_sample
    if _sequences(_WORKER["cfg"]):  # a frame of a street sequence (splatting/dataset/sequences)
        from splatting.dataset.sequences.output import write_frame
        return write_frame(_WORKER["cfg"], index, _WORKER["out"], _WORKER["assets"])
    return write_sample(_WORKER["cfg"], index, _WORKER["out"], _WORKER["assets"])


def _sequences(cfg):
    return cfg.sequence.enabled


def generate(cfg, out_dir, workers=1, log=print, progress=True, shard=None, engine="local", address=None):
    """Make (or finish) the dataset in out_dir; returns {"annotations", "generated", "skipped", "wall_s"}.

    cfg: the validated DatasetConfig (config.load_config / validate); a plain dict is refused.  Its
    record (generate.config_record, made here once) is written as config.json and is the key a
    resumed run must match.  shard (k, n): only indices = k mod n, and no merge (annotations
    None).  engine "ray": the samples as Ray tasks (splatting.library.dataset_ray), merged here at
    the end."""
    from splatting.dataset.config import resolve_assets
    from splatting.dataset.generate import config_record, sample_done
    from splatting.dataset.merge import merge_dataset

    cfg = resolve_assets(require_config(cfg, "dataset generate"))
    record = config_record(cfg)
    os.makedirs(out_dir, exist_ok=True)
    cpath = os.path.join(out_dir, "config.json")
    if os.path.isfile(cpath):
        old = read_json(cpath, "dataset config record")
        if not isinstance(old, dict):
            raise UserError(f"{cpath} is not a dataset config record; use another --out or delete it")
        if old != record:
            diff = sorted(k for k in set(old) | set(record) if old.get(k) != record.get(k))
            raise UserError(f"{out_dir} holds a dataset made with a different config (fields {', '.join(diff)} "
                            f"differ); use another --out or delete it")
    else:
        write_json(cpath, record)
    total, done = cfg.count, sample_done
    if _sequences(cfg):  # the work items are frames: sequence s, frame f is index s * length + f
        from splatting.dataset.sequences.output import frame_done as done, total as frames_total
        total = frames_total(cfg)
    mine = range(total) if shard is None else range(shard[0], total, shard[1])
    todo = [i for i in mine if not done(out_dir, i, cfg)]
    skipped = len(mine) - len(todo)
    if skipped:
        log(f"dataset: {skipped} of {total} samples already done, resuming")
    t0, last = time.time(), 0.0

    def tick(done):
        nonlocal last
        now = time.time()
        if progress and (now - last > 2.0 or done == len(todo)):
            last = now
            rate = done / max(now - t0, 1e-9)
            eta = (len(todo) - done) / rate if rate > 0 else float("inf")
            sys.stderr.write(f"dataset: {skipped + done}/{total} samples, {rate:.2f} img/s, eta {eta:.0f} s\n")
            sys.stderr.flush()

    if todo and engine == "ray":
        from splatting.library.dataset_ray import generate_ray
        generate_ray(cfg, out_dir, todo, address=address, tick=tick)
    elif todo:
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
    path = None if shard is not None else merge_dataset(out_dir)
    return {"annotations": path, "generated": len(todo), "skipped": skipped, "wall_s": time.time() - t0}


def check_args(args):
    """Impossible overrides, an empty config file and an unusable --out, before any work."""
    if args.config is not None:
        checks.non_empty_file("config", args.config)
    checks.count("count", args.count)
    checks.integer("seed", args.seed, 0)
    checks.image_size("image_size", args.image_size)
    checks.integer("workers", args.workers, 1, 1024)
    checks.output_dir("out", args.out)
    if args.frames is not None and not os.path.isdir(args.frames):
        raise UserError(f"--frames {args.frames}: no such folder")
    parse_shard(args.shard)
    if args.shard and args.engine == "ray":
        raise UserError("--shard is the engine-free form (one process per shard); leave out --engine ray")
    if args.address and args.engine != "ray":
        raise UserError("--address goes with --engine ray")
    check_address(args.address)


def run(args):
    from splatting.dataset.config import load_config
    if args.workers < 1:
        raise UserError("--workers must be >= 1")
    from splatting.library.use import check_dataset_assets
    shard = parse_shard(args.shard)
    nested = {}
    if args.format:
        nested["labels"] = {"formats": list(dict.fromkeys(args.format))}
    if args.camera:
        nested["camera"] = {"preset": args.camera}
    cfg = load_config(args.config, args.preset, overrides_of(args, CLI_OVERRIDES), nested)
    if args.frames is not None and cfg.mode != "frames":
        raise UserError(f"--frames goes with mode: frames (e.g. --preset kitti-insert); this config's mode is {cfg.mode}")
    checks.image_size("config field 'image_size'", cfg.image_size)
    checks.count("config field 'count'", cfg.count)
    out = args.out or checks.inside(os.path.join("out", "datasets"), os.path.join("out", "datasets", cfg.name),
                                    "the default output folder")
    checks.output_dir("out", out)
    check_dataset_assets(cfg, allow_low_quality=args.allow_low_quality)  # trained assets only, unless opted out
    log = (lambda *a: None) if args.quiet else (lambda m: print(m, flush=True))
    r = generate(cfg, out, args.workers, log=log, progress=not args.quiet, shard=shard, engine=args.engine,
                 address=args.address)
    if shard is not None:
        print(f"dataset: shard {shard[0]}/{shard[1]} of {out} done ({r['generated']} generated, {r['skipped']} resumed, "
              f"{r['wall_s']:.1f} s); when every shard is done: python -m splatting dataset merge --out {out}")
        return
    what = (f"{cfg.count} sequences of {cfg.sequence.length} frames" if cfg.sequence.enabled
            else f"{cfg.count} images")
    print(f"dataset: {what} in {out} ({r['generated']} generated, {r['skipped']} resumed, "
          f"{r['wall_s']:.1f} s); annotations: {r['annotations']}")


def parse_shard(text):
    """'K/N' -> (K, N) with 0 <= K < N, or None."""
    if text is None:
        return None
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise UserError(f"--shard wants K/N (e.g. 0/16), got {text!r}") from None
    if not (n >= 1 and 0 <= k < n):
        raise UserError(f"--shard {text}: need N >= 1 and 0 <= K < N")
    return k, n


class Merge:
    """`python -m splatting dataset merge --out DIR`: a sharded dataset's samples -> DIR/annotations.json
    (splatting/dataset/merge.py)."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--out", required=True, help="the dataset folder the shard runs wrote (holds config.json, shards/)")

    @staticmethod
    def check_args(args):
        checks.input_dir("out", args.out)

    @staticmethod
    def run(args):
        from splatting.dataset.merge import merge_dataset, read_config

        path = merge_dataset(args.out)
        cfg = read_config(args.out)
        print(f"dataset merge: {cfg.count} samples -> {path}")
        return 0


class LooksSheet:
    """`python -m splatting dataset looks-sheet --out FILE.png`: one cyclist in N sampled looks
    (splatting/dataset/looks_sheet.py)."""

    @staticmethod
    def add_arguments(p):
        p.add_argument("--out", required=True, help="PNG to write")
        p.add_argument("--bike", help="bike folder (default: a stand-in from the procedural spec)")
        p.add_argument("--rider", default="m_adult_average_185", help="roster rider id")
        p.add_argument("--riders-root", default="data/riders")
        p.add_argument("--count", type=int, default=12)
        p.add_argument("--seed", type=int, default=0)
        p.add_argument("--accessories", action="store_true",
                       help="vary the rider's per-instance accessories (helmet, hair, backpack) instead of the colours")
        p.add_argument("--scale", type=float, default=1.0, help="camera resolution scale (0.05-4; the tiles' size)")

    @staticmethod
    def check_args(args):
        if args.count < 1:
            raise UserError("--count must be >= 1")
        if not 0.05 <= args.scale <= 4:  # also refuses nan
            raise UserError(f"--scale must be within 0.05..4, got {args.scale}")
        if not args.out.lower().endswith(".png"):
            raise UserError("--out must be a .png file")

    @staticmethod
    def run(args):
        from splatting.dataset.looks_sheet import write_looks_sheet

        print(write_looks_sheet(args.out, args.bike, args.rider, args.riders_root, args.count, args.seed,
                                accessories_only=args.accessories, scale=args.scale))
        return 0


class FramesSheet:
    """`python -m splatting dataset frames-sheet DATASET OUT.png`: a frames-mode dataset's samples with their
    labels on one PNG; the module parses its own arguments (splatting/dataset/frames/sheet.py)."""

    @staticmethod
    def main(argv):
        from splatting.dataset.frames.sheet import main

        return main(argv)


class SequenceStrip:
    """`python -m splatting dataset strip --dataset DIR --out FILE.png`: a sequence's frames with track boxes;
    the module parses its own arguments (splatting/dataset/sequences/strip.py)."""

    @staticmethod
    def main(argv):
        from splatting.dataset.sequences.strip import main

        return main(argv)
