"""The library's records: one JSON per completed task, and library.json summing them up.

Layout under the library root OUT (the folder holding bikes/):
    OUT/bikes/<id>/views/<part>/, OUT/bikes/<id>/gaussians/<part>.ply   (the assets; with the posed
                                     stage the train tasks write <part>_rest.{ply,json} and the posed
                                     task <part>.ply, posed_train.json and views/posed/; without it
                                     the train tasks write <part>.{ply,json})
    OUT/library/tasks/<task>.json    written atomically when a task has finished: its outputs
                                     with hashes, metrics, wall time and settings.  Its presence
                                     is what makes a rerun skip the task.
    OUT/library/gt/<bike>/           the ground-truth renders of each bike
    OUT/library.json                 every asset: files + hashes, quality, build time, settings,
                                     usable (quality floor); written by the driver only
No two tasks write the same file: each task's outputs are its own folders/files.
"""
import hashlib
import json
import os
import time

from cyclist_formats.atomic import is_temp_name, read_json_or_none, write_json
from cyclist_formats.errors import UserError

MANIFEST = "library.json"
# the quality floor's defaults (settings.Floors declares the fields with these; the command's --help
# reads them from here without loading pydantic)
FLOORS = {"min_part_psnr": 20.0, "min_gt_iou": 0.85, "min_gt_box_psnr": 18.0, "min_rider_psnr": 20.0}


def sha256(path, chunk=1 << 20):
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(chunk), b""):
            h.update(block)
    return h.hexdigest()


def tree_hash(folder):
    """One hash over every file below folder (relative names + contents), temporaries excluded."""
    h = hashlib.sha256()
    n = 0
    for d, dirs, files in os.walk(folder):
        dirs.sort()
        for name in sorted(files):
            if is_temp_name(name):
                continue
            p = os.path.join(d, name)
            h.update(os.path.relpath(p, folder).encode() + b"\0" + sha256(p).encode())
            n += 1
    return h.hexdigest(), n


def task_file(root, task_id):
    return os.path.join(root, "library", "tasks", task_id.replace(":", "__") + ".json")


def read_record(root, task_id):
    return read_json_or_none(task_file(root, task_id))  # missing or unreadable: the task is redone


def files_record(root, paths):
    """{relative path: sha256} of output files (relative to the library root)."""
    return {os.path.relpath(p, root): sha256(p) for p in paths}


def write_record(root, task_id, record):
    write_json(task_file(root, task_id), dict(record, task=task_id, finished=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())))


def differ(old, new):
    """The sorted keys whose values two settings dicts disagree on (a key one lacks counts)."""
    return sorted(k for k in set(old) | set(new) if old.get(k) != new.get(k))


def check_settings(root, task_id, settings):
    """A done task built with other settings is an error (mixing budgets in one library would make
    its quality numbers meaningless); None when not done, the record when done with these settings."""
    rec = read_record(root, task_id)
    if rec is None:
        return None
    if rec.get("settings") != settings:
        raise UserError(f"task {task_id} in {root} was built with other settings ({', '.join(differ(rec.get('settings') or {}, settings))} "
                        f"differ); use another --out, or delete {task_file(root, task_id)} to rebuild it")
    return rec


def check_all_settings(root, task_settings):
    """check_settings over [(task id, settings)], naming every clashing task in one line (a changed
    fine-tune setting clashes with the posed and ground-truth records of every bike at once)."""
    bad, was_posed = [], None
    for tid, s in task_settings:
        rec = read_record(root, tid)
        if rec is not None and rec.get("settings") != s:
            bad.append((tid, differ(rec.get("settings") or {}, s)))
            if "posed_train" in bad[-1][1] and was_posed is None:
                was_posed = bool((rec.get("settings") or {}).get("posed_train"))
    if not bad:
        return
    keys = sorted({k for _, d in bad for k in d})
    ids, names = [t for t, _ in bad], [os.path.basename(task_file(root, t)) for t, _ in bad]
    more = " ..." if len(bad) > 4 else ""
    hint = "" if was_posed is None else (
        "; it was built with the posed fine-tune: drop --no-posed-train" if was_posed
        else "; it was built without the posed fine-tune: add --no-posed-train")
    raise UserError(f"{len(bad)} task{'s' if len(bad) > 1 else ''} in {root} ({', '.join(ids[:4])}{more}) "
                    f"{'were' if len(bad) > 1 else 'was'} built with other settings ({', '.join(keys)} differ); "
                    f"use another --out, or delete their records in {os.path.dirname(task_file(root, ids[0]))} "
                    f"({' '.join(names[:4])}{more}) to rebuild them{hint}")


def usable(asset, floors):
    """(usable, reasons) of one asset's quality against the floors (settings.Floors)."""
    q, why = asset.get("quality", {}), []
    for part, psnr in (q.get("part_psnr") or {}).items():
        if psnr is None or psnr < floors.min_part_psnr:
            why.append(f"{part} held-out PSNR {psnr} < {floors.min_part_psnr}")
    if "gt_iou" in q and q["gt_iou"] < floors.min_gt_iou:
        why.append(f"ground-truth IoU {q['gt_iou']:.3f} < {floors.min_gt_iou}")
    if "gt_box_psnr" in q and q["gt_box_psnr"] < floors.min_gt_box_psnr:
        why.append(f"ground-truth box PSNR {q['gt_box_psnr']:.2f} < {floors.min_gt_box_psnr}")
    if "rider_psnr" in q and (q["rider_psnr"] is None or q["rider_psnr"] < floors.min_rider_psnr):
        why.append(f"avatar held-out PSNR {q['rider_psnr']} < {floors.min_rider_psnr}")
    return not why, why


def build_manifest(root, graph, floors, settings, engine):
    """library.json from the task records of a finished graph (driver only, atomic); floors: a
    settings.Floors, settings: a settings.LibrarySettings (written as their records)."""
    bikes, riders = {}, {}
    for t in graph:
        rec = read_record(root, t.id)
        if rec is None:
            continue
        if t.kind == "avatar":
            a = riders.setdefault(t.asset, {"id": t.asset, "folder": rec["folder"], "files": {}, "quality": {},
                                            "build_s": 0.0, "tasks": []})
            a["quality"]["rider_psnr"] = rec["metrics"].get("psnr")
        else:
            a = bikes.setdefault(t.asset, {"id": t.asset, "folder": os.path.relpath(t.bike_dir, root), "files": {},
                                           "quality": {}, "build_s": 0.0, "tasks": []})
            if t.kind == "train":
                a["quality"].setdefault("part_psnr", {})[t.part] = rec["metrics"].get("psnr")
                a["quality"].setdefault("part_box_psnr", {})[t.part] = rec["metrics"].get("box_psnr")
            elif t.kind == "posed":  # the fine-tune's held-out posed renders, after (and before) it
                m = rec["metrics"]
                a["quality"].update({"posed_box_psnr": m.get("held_out_box_psnr_after"),
                                     "posed_iou": m.get("held_out_iou_after"),
                                     "posed_box_psnr_before": m.get("held_out_box_psnr_before"),
                                     "posed_iou_before": m.get("held_out_iou_before")})
            elif t.kind == "gt":
                a["quality"].update({k: rec["metrics"][k] for k in ("gt_iou", "gt_box_psnr", "gt_iou_min",
                                                                     "gt_box_psnr_min", "gt_poses")})
            elif t.kind == "views":
                a["views"] = rec["metrics"]
        a["files"].update(rec.get("files", {}))
        a["build_s"] = round(a["build_s"] + rec.get("wall_s", 0.0), 2)
        a["tasks"].append(t.id)
    expected = {}
    for t in graph:
        expected.setdefault((t.kind == "avatar", t.asset), []).append(t.id)
    for (is_rider, aid), ids in expected.items():
        a = (riders if is_rider else bikes).get(aid)
        if a is None:
            continue
        a["complete"] = sorted(a["tasks"]) == sorted(ids)
        ok, why = usable(a, floors)
        a["usable"] = bool(ok and a["complete"])
        a["below_floor"] = why
    doc = {"format": "3darticcyclists-library/1", "root": os.path.abspath(root), "engine": engine,
           "settings": settings.record(), "quality_floor": floors.record(), "bikes": dict(sorted(bikes.items())),
           "riders": dict(sorted(riders.items())),
           "build_s_total": round(sum(a["build_s"] for a in list(bikes.values()) + list(riders.values())), 2)}
    write_json(os.path.join(root, MANIFEST), doc)
    return doc


def load_manifest(root):
    p = os.path.join(root, MANIFEST)
    if not os.path.isfile(p):
        return None
    try:
        with open(p) as f:
            return json.load(f)
    except (OSError, ValueError) as e:
        raise UserError(f"cannot read {p}: {e}") from None
