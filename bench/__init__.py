"""Benchmarks for `make bench`: each module exposes run(results: dict)."""
import argparse
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def bench_parser(name, doc):
    """`python -m bench.<name>`'s command line: the module docstring's first line as its
    description and --out, the bench output folder (default out/bench)."""
    ap = argparse.ArgumentParser(prog=f"python -m bench.{name}", description=doc.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    return ap


def worker_or_standalone(ap, worker):
    """A Blender comparison bench's command line, parsed: with --worker JOB this is the bpy side, which
    runs `worker(JOB)` and gets None back; a standalone run needs --out and gets the arguments."""
    a = ap.parse_args()
    if a.worker:
        worker(a.worker)
        return None
    if not a.out:
        ap.error("--out is required")
    return a
