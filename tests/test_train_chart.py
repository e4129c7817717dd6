"""bench/train_chart.py --bike-fidelity: reference folders rendered before the sun fix (their job.json
has no "lighting", bench/blender_compare.REFERENCE_LIGHTING) are refused, before any work."""
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def _run(tmp_path, job):
    bike, ref = tmp_path / "bike", tmp_path / "ref"
    bike.mkdir()
    ref.mkdir()
    (ref / "job.json").write_text(json.dumps(job))
    return subprocess.run([sys.executable, "bench/train_chart.py", "--bike-fidelity", f"a={bike}",
                           "--bike-reference", str(ref), "--png", str(tmp_path / "chart.png")],
                          cwd=ROOT, capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=ROOT))


def test_old_references_are_refused(tmp_path):
    r = _run(tmp_path, {"poses": [[0.0] * 8], "cameras": [0], "size": 64})
    assert r.returncode == 2 and "sun fix" in r.stderr and len(r.stderr.strip().splitlines()) == 1, r.stderr
    assert not (tmp_path / "chart.png").exists() and not (tmp_path / "chart.json").exists()


def test_current_references_pass_the_check(tmp_path):
    from bench.blender_compare import REFERENCE_LIGHTING

    # past the check it loads the (empty) bike folder and refuses it in one line, not on the references
    r = _run(tmp_path, {"poses": [[0.0] * 8], "cameras": [0], "size": 64, "lighting": REFERENCE_LIGHTING})
    assert r.returncode == 2 and "sun fix" not in r.stderr, r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "a=" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert not (tmp_path / "chart.png").exists() and not (tmp_path / "chart.json").exists()
