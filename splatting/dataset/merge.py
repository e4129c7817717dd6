"""Per-sample shards -> DIR/annotations.json (the command: `python -m splatting dataset merge --out DIR`).

The step after sharded or distributed generation (`dataset --shard K/N`, a Slurm array, a
Kubernetes Indexed Job, `--engine ray`): it reads the resolved config the generators stored in
DIR/config.json (back into a DatasetConfig: config.from_record), refuses while any sample is
missing (naming how many and the command that finishes them), and writes annotations.json
atomically.  Idempotent: the shards fully determine
the output, so running it twice, or after a single-process run, gives the same bytes.
"""
import json
import os

from cyclist_formats.errors import UserError
from splatting.dataset.coco import merge
from splatting.dataset.config import from_record
from splatting.dataset.generate import sample_done
from splatting.dataset.kitti import write_imagesets
from splatting.dataset.labels import categories
from splatting.dataset.sequences import output as sequence_output


def coco_info(cfg):
    return {"description": f"3DArticCyclists synthetic {cfg.mode} set '{cfg.name}'", "seed": cfg.seed,
            "count": cfg.count, "image_size": cfg.image_size, "person_keypoints": cfg.keypoints.person,
            "camera": cfg.camera.preset, "labels": "docs/labels.md"}


def read_config(out_dir):
    """DIR/config.json -> DatasetConfig (its sections left out in the record are their defaults)."""
    path = os.path.join(out_dir, "config.json")
    if not os.path.isfile(path):
        raise UserError(f"{out_dir} holds no dataset (no config.json); generate it with "
                        f"`python -m splatting dataset --config ... --out {out_dir}` first")
    try:
        with open(path) as f:
            record = json.load(f)
    except (OSError, ValueError) as e:
        raise UserError(f"cannot read {path}: {e}") from None
    if not isinstance(record, dict) or not isinstance(record.get("count"), int):
        raise UserError(f"{path} is not a dataset config (no integer 'count')")
    return from_record(record, f"{path}:")


def missing_samples(out_dir, cfg):
    if cfg.sequence.enabled:  # sequences: every frame
        return [i for i in range(sequence_output.total(cfg)) if not sequence_output.frame_done(out_dir, i, cfg)]
    return [i for i in range(cfg.count) if not sample_done(out_dir, i, cfg)]


def merge_dataset(out_dir):
    """Merge every shard of the dataset in out_dir; returns the annotations.json path."""
    cfg = read_config(out_dir)
    missing = missing_samples(out_dir, cfg)
    if missing:
        n = cfg.count * cfg.sequence.length if cfg.sequence.enabled else cfg.count
        raise UserError(f"{out_dir}: {len(missing)} of {n} samples are not generated yet "
                        f"(e.g. {', '.join(map(str, missing[:3]))}); finish them with "
                        f"`python -m splatting dataset --config {os.path.join(out_dir, 'config.json')} --out {out_dir}` "
                        f"(or the missing --shard runs), then merge again")
    if cfg.sequence.enabled:
        return sequence_output.assemble(out_dir, cfg, coco_info(cfg), categories(cfg.labels, cfg.keypoints.person))
    path = merge(out_dir, cfg.count, coco_info(cfg), categories(cfg.labels, cfg.keypoints.person))
    if "kitti" in cfg.labels.formats:
        write_imagesets(out_dir, cfg.count)
    return path
