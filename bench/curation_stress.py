"""Curation under the transformations real files come with: the development models, transformed (issue 27).

For every development model (bench/real_bikes.py's MODELS) and variant (bench/curation_variants.py's
VARIANTS: up axis, yaw, unit x0.01 / x100, origin far away, joined into one mesh, half the faces,
mirrored, glTF / FBX / OBJ round trips) write the variant as a new file (a bpy subprocess), curate it
(blender_scripts/curate.py, one at a time, nice 10) and compare with the untransformed model's
curation: a variant is usable when it curates and every keypoint lies within TOL_M (3 cm) of the
untransformed one's after mapping back (a mirrored bike: lateral coordinate negated, left and right
swapped); a refusal (one line) is not usable; a crash (a Python traceback, or an exit code other than
0 / 2) is counted apart.  Models whose own curation fails are reported but not scored.

Reuse: each curation's record (status, first error line, keypoints, CPU s) is kept beside it, keyed
by the model's hash, the variant and the curation and variant code; an interrupted sweep resumes.
Key: curation_stress = {usable, scored, usable_share, crashes, per_variant, per_model}.

    .venv/bin/python -m bench.curation_stress --out out/bench [--models arfun_bicycle ...] [--variants z_up mirrored ...]
"""
import argparse
import json
import os
import shutil
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

from bench.curation_variants import VARIANTS  # noqa: E402
from bench.provenance import code_version, record  # noqa: E402
from bench.real_bikes import CURATE_CODE, MODELS, input_hash, models_dir, models_dir_or_skip  # noqa: E402
from cyclist_formats.atomic import read_json_or_none, write_json  # noqa: E402

TOL_M = 0.03
TIMEOUT_S = 900
# the default sweep: the exporter alone (the control), then the variants most likely to break first (CPU: a curation is 5-45 s on two cores)
DEFAULT_VARIANTS = ("glb", "z_up", "mirrored", "joined", "scale0.01", "scale100", "yaw37", "yaw143", "yaw251", "far", "decimated",
                    "fbx", "obj")
STRESS_CODE = CURATE_CODE + ("bench/curation_variants.py",)


def _cpu():
    t = os.times()
    return t.children_user + t.children_system


def _status(rc, stderr):
    """'ok', 'refused' (a clean one-line refusal or a partial curation) or 'crash' (a traceback)."""
    if "Traceback (most recent call last)" in stderr or rc not in (0, 2):
        return "crash"
    return "ok" if rc == 0 else "refused"


def curate_variant(model_path, mid, variant, folder, log=print):
    """-> record {status, reason, keypoints, cpu_s, reused} of `variant` ('base': the file itself)."""
    rec_path = os.path.join(folder, "record.json")
    key = {"input": input_hash(model_path), "variant": variant, "code": code_version(*STRESS_CODE)}
    rec = read_json_or_none(rec_path)
    if rec and rec.get("key") == key:
        return {**rec["result"], "reused": True}
    if os.path.isdir(folder):
        shutil.rmtree(folder)
    os.makedirs(folder)
    nice = ["nice", "-n", "10", sys.executable]
    c0, t0 = _cpu(), time.time()
    src = model_path
    if variant != "base":
        src = os.path.join(folder, "model" + VARIANTS[variant]["ext"])
        r = subprocess.run(nice + ["-m", "bench.curation_variants", "--input", model_path, "--variant", variant,
                                   "--out", src], cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True, timeout=TIMEOUT_S)
        if r.returncode != 0:
            raise RuntimeError(f"writing {variant} of {mid} failed: {r.stderr.strip().splitlines()[-1:]}")
    log(f"curation_stress: curating {mid} / {variant}")
    bike = os.path.join(folder, "bike")
    try:
        r = subprocess.run(nice + [os.path.join(ROOT, "blender_scripts", "curate.py"), "--input", src, "--out", bike],
                           cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, timeout=TIMEOUT_S)
        rc, err = r.returncode, r.stderr
    except subprocess.TimeoutExpired:
        rc, err = None, f"curate.py: timed out after {TIMEOUT_S} s"
    status = "timeout" if rc is None else _status(rc, err)
    lines = [ln for ln in err.strip().splitlines() if ln.startswith("curate.py: error") or ln.startswith("curate.py: timed")]
    tb = err[err.find("Traceback"):].strip().splitlines()[-1:] if "Traceback" in err else []
    kp = read_json_or_none(os.path.join(bike, "keypoints.json")) if status == "ok" else None
    result = {"status": status, "reason": (tb or lines or [None])[-1] if status != "ok" else None,
              "keypoints": (kp or {}).get("keypoints"), "cpu_s": round(_cpu() - c0, 1),
              "wall_s": round(time.time() - t0, 1)}
    for p in (bike, src, os.path.splitext(src)[0] + ".mtl", bike + ".partial.blend"):   # only the record is kept
        if os.path.isdir(p):
            shutil.rmtree(p)
        elif os.path.isfile(p) and p != model_path:
            os.remove(p)
    write_json(rec_path, {"key": key, "result": result})
    return {**result, "reused": False}


def mapped_back(variant, keypoints):
    """A variant's canonical keypoints as the untransformed model's: a mirror image has its lateral
    (canonical Z) coordinate negated and its left and right keypoints swapped."""
    if not VARIANTS[variant].get("mirror"):
        return keypoints
    swap = {"left": "right", "right": "left"}
    out = {}
    for name, (x, y, z) in keypoints.items():
        parts = name.split("_")
        out["_".join(swap.get(p, p) for p in parts)] = [x, y, -z]
    return out


def keypoint_error(base, variant, keypoints):
    """Largest distance (m) between a variant's keypoints, mapped back, and the base's."""
    m = mapped_back(variant, keypoints)
    if set(m) != set(base):
        return float("inf")
    return max(float(np.linalg.norm(np.subtract(m[k], base[k]))) for k in base)


def score(base, variant, rec):
    """'usable', 'off' (curated, keypoints > TOL_M from the base), 'refused', 'crash' or 'timeout'."""
    if rec["status"] != "ok":
        return rec["status"], None
    err = keypoint_error(base["keypoints"], variant, rec["keypoints"])
    return ("usable" if err <= TOL_M else "off"), err


def table(rows, variants, models):
    """The per-variant and per-model tables (markdown lines)."""
    scored = [r for r in rows if r["score"] is not None]
    lines = ["| variant | usable | off > 3 cm | refused | crash | worst (model: why) |", "| --- | --- | --- | --- | --- | --- |"]
    for v in variants:
        rs = [r for r in scored if r["variant"] == v]
        if not rs:
            continue
        n = {s: sum(r["score"] == s for r in rs) for s in ("usable", "off", "refused", "crash", "timeout")}
        bad = [r for r in rs if r["score"] != "usable"]
        why = "; ".join(f"{r['model']}: " + (f"{r['error_m'] * 100:.0f} cm" if r["score"] == "off" else str(r["reason"])[:90])
                        for r in bad[:2])
        lines.append(f"| {v} | {n['usable']}/{len(rs)} | {n['off']} | {n['refused']} | {n['crash'] + n['timeout']} | {why} |")
    lines += ["", "| model | usable | not usable (variants) |", "| --- | --- | --- |"]
    for mid in models:
        rs = [r for r in rows if r["model"] == mid]
        if rs and rs[0]["score"] is None:
            lines.append(f"| {mid} | not scored: its own curation failed ({rs[0]['reason']}) | |")
            continue
        rs = [r for r in rs if r["score"] is not None]
        if rs:
            lines.append(f"| {mid} | {sum(r['score'] == 'usable' for r in rs)}/{len(rs)} | "
                         + ", ".join(f"{r['variant']} ({r['score']})" for r in rs if r["score"] != "usable") + " |")
    return lines


def run(results, out_dir, models=None, variants=None, log=print):
    """make bench's stage: every model's base curation, then the variants family by family."""
    mdir = models_dir_or_skip(results, "curation_stress", log)
    if mdir is None:
        return None
    models = [m for m in (models or MODELS) if os.path.isfile(os.path.join(mdir, MODELS[m]))]
    variants = list(variants or DEFAULT_VARIANTS)
    root = os.path.join(out_dir, "curation_stress")
    base = {m: curate_variant(os.path.join(mdir, MODELS[m]), m, "base", os.path.join(root, m, "base"), log) for m in models}
    rows = []
    for v in variants:          # family by family: a partial sweep still covers every model
        for m in models:
            rec = curate_variant(os.path.join(mdir, MODELS[m]), m, v, os.path.join(root, m, v), log)
            s, err = score(base[m], v, rec) if base[m]["status"] == "ok" else (None, None)
            rows.append({"model": m, "variant": v, "score": s, "error_m": err, "status": rec["status"],
                         "reason": rec["reason"] if base[m]["status"] == "ok" else base[m]["reason"],
                         "cpu_s": rec["cpu_s"]})
            log(f"  curation_stress: {m} / {v}: {s or 'not scored'}" + (f" ({err * 100:.1f} cm)" if err is not None else "")
                + (f" - {rec['reason']}" if rec["reason"] else ""))
    scored = [r for r in rows if r["score"] is not None]
    crashes = sum(r["status"] in ("crash", "timeout") for r in rows) + sum(b["status"] in ("crash", "timeout") for b in base.values())
    results["curation_stress"] = {
        "models": len(models), "variants": variants, "scored": len(scored),
        "usable": sum(r["score"] == "usable" for r in scored),
        "usable_share": round(sum(r["score"] == "usable" for r in scored) / len(scored), 3) if scored else None,
        "crashes": crashes, "tol_m": TOL_M,
        "base": {m: b["status"] for m, b in base.items()}, "per_case": rows}
    record(results, "curation_stress", "fresh", assets=mdir)
    lines = table(rows, variants, models)
    os.makedirs(out_dir, exist_ok=True)
    write_text = "\n".join(lines) + "\n"
    tmp = os.path.join(out_dir, ".curation_stress_table.md.tmp")
    with open(tmp, "w") as f:
        f.write(write_text)
    os.replace(tmp, os.path.join(out_dir, "curation_stress_table.md"))
    log(write_text)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m bench.curation_stress", description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=os.path.join("out", "bench"), help="bench output folder (curation_stress/ goes there)")
    ap.add_argument("--models", nargs="+", default=None, help=f"model ids (default: all: {', '.join(MODELS)})")
    ap.add_argument("--variants", nargs="+", default=None,
                    help=f"variants (default: {' '.join(DEFAULT_VARIANTS)}; known: {', '.join(VARIANTS)})")
    a = ap.parse_args(argv)
    bad = [m for m in a.models or [] if m not in MODELS]
    if bad:
        ap.exit(2, f"curation_stress: error: unknown model {bad[0]!r} (known: {', '.join(MODELS)})\n")
    bad = [v for v in a.variants or [] if v not in VARIANTS]
    if bad:
        ap.exit(2, f"curation_stress: error: unknown variant {bad[0]!r} (known: {', '.join(VARIANTS)})\n")
    if models_dir() is None:
        ap.exit(2, "curation_stress: error: no ../shared/models beside the repository\n")
    res = {}
    run(res, a.out, a.models, a.variants)
    print(json.dumps({k: v for k, v in res["curation_stress"].items() if k != "per_case"}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
