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
