"""Benchmarks for `make bench`: each module exposes run(results: dict)."""
