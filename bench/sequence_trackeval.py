"""TrackEval reads a generated sequence set: its MOTChallenge and KITTI-tracking readers load the
files, and the ground truth scored as a tracker against itself gives HOTA = MOTA = IDF1 = 1.

TrackEval is not a dependency of the project; run this with an environment that has it
(`pip install trackeval` pulls numpy and scipy):

    python bench/sequence_trackeval.py DATASET   # a set written with --format mot --format kitti

MOT: the cyclists are MOT's class 1 (the class its evaluator scores, `pedestrian` in its code).
KITTI: TrackEval's KITTI evaluator scores car and pedestrian only, so for `Cyclist` rows it is the
reader that is checked (every row parsed, integer truncation and occlusion, track ids per frame);
the car and pedestrian rows (a KITTI frame's own objects in sequences in KITTI frames) are scored.
"""
import json
import os
import shutil
import sys
import tempfile


def check(dataset):
    import numpy as np
    import trackeval
    with open(os.path.join(dataset, "config.json")) as f:
        cfg = json.load(f)
    seqs = [f"{s:04d}" for s in range(cfg["count"])]
    n = cfg["sequence"]["length"]
    scratch = tempfile.mkdtemp(prefix="trackeval_")
    out = {}
    try:
        # MOTChallenge: the gt as a tracker's output
        trk = os.path.join(scratch, "mot_trackers", "gt_self", "data")
        os.makedirs(trk)
        for s in seqs:  # a tracker's rows: its targets (class 1), frame,id,x,y,w,h,conf,-1,-1,-1
            with open(os.path.join(dataset, "mot", s, "gt", "gt.txt")) as f, open(os.path.join(trk, f"{s}.txt"), "w") as g:
                for line in f.read().splitlines():
                    c = line.split(",")
                    if c[7] == "1":
                        g.write(",".join(c[:6] + ["1", "-1", "-1", "-1"]) + "\n")
        ev = trackeval.Evaluator({"USE_PARALLEL": False, "PRINT_RESULTS": False, "PRINT_CONFIG": False,
                                  "OUTPUT_SUMMARY": False, "OUTPUT_DETAILED": False, "PLOT_CURVES": False,
                                  "TIME_PROGRESS": False, "OUTPUT_EMPTY_CLASSES": False})
        ds = trackeval.datasets.MotChallenge2DBox({
            "GT_FOLDER": os.path.join(dataset, "mot"), "TRACKERS_FOLDER": os.path.join(scratch, "mot_trackers"),
            "SKIP_SPLIT_FOL": True, "SEQ_INFO": {s: None for s in seqs}, "TRACKERS_TO_EVAL": ["gt_self"],
            "PRINT_CONFIG": False, "OUTPUT_FOLDER": os.path.join(scratch, "mot_out")})
        res, _ = ev.evaluate([ds], [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR(), trackeval.metrics.Identity()])
        r = res["MotChallenge2DBox"]["gt_self"]["COMBINED_SEQ"]["pedestrian"]
        out["mot"] = {"HOTA": float(np.mean(r["HOTA"]["HOTA"])), "MOTA": float(r["CLEAR"]["MOTA"]),
                      "IDF1": float(r["Identity"]["IDF1"]), "gt_dets": int(r["CLEAR"]["CLR_TP"] + r["CLEAR"]["CLR_FN"]),
                      "gt_rows": sum(len(open(os.path.join(dataset, "mot", s, "gt", "gt.txt")).read().splitlines())
                                     for s in seqs)}
        # KITTI tracking: the reader
        gt = os.path.join(scratch, "kitti_gt")
        os.makedirs(os.path.join(gt, "label_02"))
        with open(os.path.join(gt, "evaluate_tracking.seqmap.training"), "w") as f:
            f.write("".join(f"{s} empty 000000 {n:06d}\n" for s in seqs))
        trk = os.path.join(scratch, "kitti_trackers", "gt_self", "data")
        os.makedirs(trk)
        rows = 0
        for s in seqs:
            src = os.path.join(dataset, "kitti_tracking", "training", "label_02", f"{s}.txt")
            shutil.copyfile(src, os.path.join(gt, "label_02", f"{s}.txt"))
            with open(src) as f, open(os.path.join(trk, f"{s}.txt"), "w") as g:
                lines = f.read().splitlines()
                rows += len(lines)
                g.write("".join(line + " 1.0\n" for line in lines))  # a tracker's row carries a score
        kd = trackeval.datasets.Kitti2DBox({"GT_FOLDER": gt, "TRACKERS_FOLDER": os.path.join(scratch, "kitti_trackers"),
                                            "TRACKERS_TO_EVAL": ["gt_self"], "PRINT_CONFIG": False,
                                            "OUTPUT_FOLDER": os.path.join(scratch, "kitti_out")})
        loaded = 0
        for s in seqs:
            raw = kd._load_raw_file("gt_self", s, is_gt=True)
            loaded += sum(len(ids) for ids in raw["gt_ids"])
            assert all(np.issubdtype(np.asarray(e["truncation"]).dtype, np.integer) for e in raw["gt_extras"] if len(e["truncation"]))
        out["kitti"] = {"rows": rows, "rows_loaded_by_trackeval": loaded}
        # the classes its KITTI evaluator scores (car, pedestrian: a KITTI frame's own objects, static
        # tracks in sequences in KITTI frames), the ground truth as a tracker against itself
        kres, _ = ev.evaluate([kd], [trackeval.metrics.HOTA(), trackeval.metrics.CLEAR()])
        kr = kres["Kitti2DBox"]["gt_self"]["COMBINED_SEQ"]
        out["kitti"]["scored"] = {c: {"HOTA": float(np.mean(kr[c]["HOTA"]["HOTA"])), "MOTA": float(kr[c]["CLEAR"]["MOTA"]),
                                      "gt_dets": int(kr[c]["CLEAR"]["CLR_TP"] + kr[c]["CLEAR"]["CLR_FN"])}
                                  for c in ("car", "pedestrian") if c in kr}
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
    return out


if __name__ == "__main__":
    if len(sys.argv) != 2 or not os.path.isfile(os.path.join(sys.argv[1], "config.json")):
        sys.stderr.write("usage: python bench/sequence_trackeval.py DATASET (a sequence set with --format mot --format kitti)\n")
        sys.exit(2)
    print(json.dumps(check(sys.argv[1]), indent=1))
