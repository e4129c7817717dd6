"""The library's task kinds and the graph over them.

    views:<bike>          blender_scripts/render_views.py (subprocess): views/{frame,steering,crank,whole} and
                          the sub-parts' views/{front_wheel,rear_wheel,pedal_left,pedal_right} (meta.json sub_parts)
    train:<bike>:<part>   python -m splatting train (subprocess): gaussians/<part>_rest.{ply,json} (the
                          rest-trained part; gaussians/<part>.{ply,json} with the posed stage off); after views
    posed:<bike>          python -m splatting bike-posed-train --from-rest (subprocess): gaussians/<part>.ply,
                          gaussians/posed_train.json, views/posed/; after every train of the bike
    gt:<bike>             ground-truth check (splatting.library.gt); after posed (or every train when it is off)
    avatar:<rider>        python -m splatting rider-avatar (subprocess): RIDERS/<rider>/

The posed stage (the asset recipe's fine-tune through the 8-DoF pose, docs/training.md) is on by
default; settings.budget.posed_train False (`--no-posed-train`) leaves the graph and layout without it.

Every task is a function of (library root, settings: a splatting.library.settings.LibrarySettings)
that does its work in subprocesses, writes only its own outputs (atomically, by the commands it runs) and returns its record; the engine
writes the record (manifest.write_record) once the task succeeded.  Blender and training run in
subprocesses so an engine (a local pool, a Ray worker) only supervises: a crash there is a failed
task that is retried, never a dead engine.
"""
import json
import os
import subprocess
import sys
import time
from dataclasses import dataclass, field

from cyclist_formats import bike_folder
from cyclist_formats.errors import UserError
from splatting.library import manifest
from splatting.library.gt import ground_truth
from splatting.rider.avatar import PLY_NAME, SKINNING_NAME
from splatting.rider.avatar_look import LOOK_NAME

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PARTS = ("frame", "steering", "crank")


@dataclass
class Task:
    id: str
    kind: str
    asset: str
    deps: list = field(default_factory=list)
    cpus: int = 1
    bike_dir: str = None
    part: str = None


def bike_parts(bike_dir):
    """The trainable parts of a bike (crankless rideables have no crank), then the sub-parts its
    meta.json lists (wheels, pedals: each rendered and trained as its own Gaussians)."""
    try:
        meta = bike_folder.read_meta(bike_dir)
    except UserError:
        raise UserError(f"{bike_dir}: no readable meta.json (not a generated bike folder)") from None
    has_crank = bool(meta.get("has_crank", True))
    try:
        subs = bike_folder.sub_parts(meta)
    except UserError as e:
        raise UserError(f"{bike_dir}/{e}") from None
    return [p for p in PARTS if p != "crank" or has_crank] + subs


def make_graph(root, bikes, riders, posed=True):
    """bikes: {id: folder}; riders: [ids] -> [Task] in dependency order.  posed: the posed:<bike>
    fine-tune between a bike's trains and its ground-truth check."""
    graph = []
    for b, d in bikes.items():
        views = Task(f"views:{b}", "views", b, [], 1, d)
        trains = [Task(f"train:{b}:{p}", "train", b, [views.id], 1, d, p) for p in bike_parts(d)]
        last = [Task(f"posed:{b}", "posed", b, [t.id for t in trains], 1, d)] if posed else []
        gt = Task(f"gt:{b}", "gt", b, [t.id for t in (last or trains)], 1, d)
        graph += [views, *trains, *last, gt]
    for r in riders:
        graph.append(Task(f"avatar:{r}", "avatar", r, [], 1))
    return graph


def _run(cmd, what, env_threads=1):
    env = dict(os.environ, OMP_NUM_THREADS=str(env_threads), OMP_WAIT_POLICY="PASSIVE",
               PYTHONPATH=ROOT + os.pathsep + os.environ.get("PYTHONPATH", ""))
    r = subprocess.run(cmd, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    if r.returncode != 0:
        tail = " | ".join(r.stdout.strip().splitlines()[-3:])
        raise RuntimeError(f"{what} failed (exit {r.returncode}): {tail}")
    return r.stdout


def run_views(task, root, s):
    b = s.budget
    cmd = [sys.executable, os.path.join(ROOT, "blender_scripts", "render_views.py"), "--bike", task.bike_dir,
           "--parts", "all", "--size", str(b.view_size), "--threads", "1"]
    if b.samples:
        cmd += ["--samples", str(b.samples)]
    t = time.time()
    _run(cmd, f"views of {task.asset}")
    wall = time.time() - t
    views_root = os.path.join(task.bike_dir, "views")
    files, n = {}, 0
    for part in sorted(os.listdir(views_root)):
        h, k = manifest.tree_hash(os.path.join(views_root, part))
        files[os.path.relpath(os.path.join(views_root, part), root) + "/"] = h
        n += k
    views = sum(len(os.listdir(os.path.join(views_root, p, "rgba"))) for p in os.listdir(views_root)
                if os.path.isdir(os.path.join(views_root, p, "rgba")))
    return {"files": files, "metrics": {"views": views, "files": n, "s_per_view": round(wall / max(views, 1), 3)},
            "wall_s": round(wall, 2)}


def part_file(bike_dir, part, posed_train):
    """The train task's part file: <part>_rest.ply when the posed task writes <part>.ply from it."""
    return os.path.join(bike_dir, "gaussians", part + ("_rest.ply" if posed_train else ".ply"))


def run_train(task, root, s):
    b = s.budget
    out = part_file(task.bike_dir, task.part, b.posed_train)
    cmd = [sys.executable, "-m", "splatting", "train", "--views", os.path.join(task.bike_dir, "views", task.part),
           "--out", out, "--iterations", str(b.iterations), "--max-gaussians", str(b.max_gaussians),
           "--time-budget-s", str(b.time_budget_s), "--seed", "0", "--threads", "1", "--quiet"]
    if b.antialiased:  # the fidelity recipe's parts (splatting/bike/recipes.py)
        cmd.append("--antialiased")
    t = time.time()
    _run(cmd, f"training {task.asset}/{task.part}")
    wall = time.time() - t
    metrics_path = out[:-4] + ".json"
    with open(metrics_path) as f:
        m = json.load(f)
    return {"files": manifest.files_record(root, [out, metrics_path]),
            "metrics": {"psnr": m.get("psnr"), "box_psnr": m.get("psnr_crop"), "ssim": m.get("ssim"),
                        "gaussians": m.get("gaussians"), "iterations": m.get("iterations")},
            "wall_s": round(wall, 2)}


def run_posed(task, root, s):
    """The parts fine-tuned together through the pose on posed Blender renders; its metrics are the
    fine-tune's held-out posed renders (the last 4) before and after."""
    gdir, p = os.path.join(task.bike_dir, "gaussians"), s.posed
    cmd = [sys.executable, "-m", "splatting", "bike-posed-train", "--bike", task.bike_dir, "--from-rest",
           "--poses", str(p.poses), "--iterations", str(p.iterations),
           "--samples", str(p.samples), "--sh-degree", str(p.sh_degree), "--quiet",
           "--render-threads", "1",  # the task declares one CPU
           "--densify-max", str(p.densify_max), "--lr-decay", repr(p.lr_decay),
           "--lr-tail", str(p.lr_tail), "--eps2d", repr(p.eps2d)]
    if p.densify:
        cmd.append("--densify")
    t = time.time()
    _run(cmd, f"posed fine-tune of {task.asset}")
    wall = time.time() - t
    meta = os.path.join(gdir, "posed_train.json")
    with open(meta) as f:
        m = json.load(f)
    # the record says which configuration made these parts: the one the subprocess really ran
    want = s.posed_record()
    have = m.get("config") or {}
    diff = manifest.differ(have, want)
    if diff:
        raise RuntimeError(f"bike-posed-train ran another configuration than the library's settings ({', '.join(diff)})")
    files = manifest.files_record(root, [os.path.join(gdir, p + ".ply") for p in bike_parts(task.bike_dir)] + [meta])
    posed_dir = os.path.join(task.bike_dir, "views", "posed")
    files[os.path.relpath(posed_dir, root) + "/"] = manifest.tree_hash(posed_dir)[0]
    keys = ("held_out_box_psnr_before", "held_out_iou_before", "held_out_box_psnr_after", "held_out_iou_after",
            "poses", "held_out_poses", "gaussians")
    return {"files": files, "metrics": {k: m.get(k) for k in keys}, "wall_s": round(wall, 2)}


def run_gt(task, root, s):
    t = time.time()
    out_dir = os.path.join(root, "library", "gt", task.asset)
    m, files = ground_truth(task.bike_dir, out_dir, s.budget.gt_poses, s.budget.samples, seed=s.budget.gt_seed)
    return {"files": manifest.files_record(root, files), "metrics": m, "wall_s": round(time.time() - t, 2)}


def run_avatar(task, root, s):
    b = s.budget
    folder = os.path.join(b.riders_root, task.asset)
    cmd = [sys.executable, "-m", "splatting", "rider-avatar", "--id", task.asset, "--out", folder,
           "--iterations", str(b.rider_iterations), "--max-gaussians", str(b.max_gaussians), "--threads", "1"]
    if b.samples:
        cmd += ["--samples", str(b.samples)]
    t = time.time()
    _run(cmd, f"avatar of {task.asset}")
    wall = time.time() - t
    paths = [os.path.join(folder, n) for n in (PLY_NAME, SKINNING_NAME, "rider.json")]
    with open(paths[2]) as f:
        m = json.load(f)
    look = os.path.join(folder, LOOK_NAME)  # what datasets dress the avatar from; absent only in an
    if os.path.isfile(look):                # avatar folder begun before avatars recorded their look
        paths.append(look)
    return {"files": {os.path.abspath(p): manifest.sha256(p) for p in paths}, "folder": os.path.abspath(folder),
            "metrics": {"psnr": m.get("psnr"), "box_psnr": m.get("psnr_crop"), "gaussians": m.get("gaussians")},
            "wall_s": round(wall, 2)}


RUNNERS = {"views": run_views, "train": run_train, "posed": run_posed, "gt": run_gt, "avatar": run_avatar}
# the settings each kind depends on: a task is redone/refused only when these change.  "posed_*":
# every posed_<field> setting (the fine-tune's whole configuration, command.posed_settings)
_TRAIN = ("view_size", "samples", "iterations", "max_gaussians", "time_budget_s", "antialiased")
SETTING_KEYS = {"views": ("view_size", "samples"),
                "train": _TRAIN + ("posed_train",),  # where it writes: <part>_rest.ply or <part>.ply
                "posed": _TRAIN + ("posed_train", "posed_*"),
                "gt": _TRAIN + ("posed_train", "posed_*", "gt_poses", "gt_seed"),
                "avatar": ("samples", "rider_iterations", "max_gaussians", "riders_root")}


def task_settings(kind, settings):
    """The settings a task of this kind depends on (from the LibrarySettings' record, the flat dict
    the library writes).  With the posed stage off every posed key is left out, so records written
    before the stage existed still match; so is "antialiased" unless the recipe trains so (records
    written before the fidelity recipe)."""
    rec = settings.record()
    out = {}
    for k in SETTING_KEYS[kind]:
        if k.startswith("posed_") and not settings.budget.posed_train:
            continue
        if k == "antialiased" and not settings.budget.antialiased:
            continue
        if k == "posed_*":
            out.update({n: v for n, v in sorted(rec.items()) if n.startswith("posed_") and n != "posed_train"})
        else:
            out[k] = rec.get(k)
    return out


def execute(task, root, settings):
    """Run one task unless its record exists; write the record.  Returns (record, skipped)."""
    mine = task_settings(task.kind, settings)
    rec = manifest.check_settings(root, task.id, mine)
    if rec is not None:
        return rec, True
    rec = RUNNERS[task.kind](task, root, settings)
    rec["settings"] = mine
    manifest.write_record(root, task.id, rec)
    return rec, False
