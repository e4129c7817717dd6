"""Dataset samples as Ray tasks over index ranges (`python -m splatting dataset --engine ray`).

Each task renders a contiguous slice of the not-yet-done indices with the same pure function of
(config, index) the local engine uses (splatting.dataset.generate.write_sample), writing the same
per-sample image + shard files, so the merged annotations are byte-identical to a one-process run.
A task whose worker dies is retried by Ray and skips the samples already written; a killed driver
is rerun and skips them too.  One declared CPU and one torch thread per task.  Sequences shard by
sequence: one task renders one sequence's frames (in order, its draw made once), so the parallelism is
the number of sequences.
"""
from splatting.dataset.generate import Assets, sample_done, write_sample
from splatting.dataset.sequences.output import frame_done, write_frame

from splatting.library.engine import ensure_ray

import torch

_CACHE = {}  # per worker process: (the DatasetConfig as JSON, out dir) -> Assets, reused by later tasks


def _render_range(cfg, out_dir, indices):

    torch.set_num_threads(1)
    key = (cfg.model_dump_json(), out_dir)
    if key not in _CACHE:
        _CACHE.clear()
        _CACHE[key] = Assets(cfg)
    for i in indices:
        if sequences(cfg):  # a sequence's frames (splatting/dataset/sequences): one task per sequence
            if not frame_done(out_dir, i, cfg):
                write_frame(cfg, i, out_dir, _CACHE[key])
        elif not sample_done(out_dir, i):
            write_sample(cfg, i, out_dir, _CACHE[key])
    return len(indices)


def sequences(cfg):
    return bool(cfg.sequence.enabled)


def by_sequence(todo, length):
    """todo frame indices (sequence s, frame f is s * length + f) grouped by sequence, in order: a task
    draws its sequence once (trajectories, placement checks) and renders its frames."""
    out = {}
    for i in todo:
        out.setdefault(i // length, []).append(i)
    return [out[s] for s in sorted(out)]


def chunks(todo, parts):
    """todo split into `parts` contiguous slices of near-equal size (none empty)."""
    parts = max(1, min(parts, len(todo)))
    q, r = divmod(len(todo), parts)
    out, s = [], 0
    for k in range(parts):
        e = s + q + (1 if k < r else 0)
        out.append(todo[s:e])
        s = e
    return out


def generate_ray(cfg, out_dir, todo, address=None, tick=None, tasks_per_cpu=4, retries=3):
    """Render the indices in todo as Ray tasks; tick(done samples) after each finished task."""
    ray = ensure_ray(address)
    cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
    remote = ray.remote(num_cpus=1, max_retries=retries, retry_exceptions=True)(_render_range)
    parts = by_sequence(list(todo), int(cfg.sequence.length)) if sequences(cfg) else \
        chunks(list(todo), cpus * tasks_per_cpu)
    refs = [remote.remote(cfg, out_dir, c) for c in parts]
    done = 0
    while refs:
        ready, refs = ray.wait(refs, num_returns=1)
        done += ray.get(ready[0])
        if tick:
            tick(done)
