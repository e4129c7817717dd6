"""Build (or find) the tiled CPU rasterizer library csrc/*.cpp -> _build/libtiles-<hash>.so.

`python -m splatting.raster.build` builds it (make setup runs this); `load()` returns the ctypes
library, building it first when missing (a few seconds of g++; one line on stderr says so).
The file name carries a hash of the source and flags, so an edited source is never run stale.
Importing this module builds nothing.
"""
import argparse
import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
# -march=native: the library is built on the machine that runs it (make setup / first use).
FLAGS = ["-O3", "-march=native", "-fopenmp", "-fPIC", "-std=c++17"]
# Per source, on top of FLAGS. tiles.cpp: -ffp-contract=off, because the forward and the backward
# must take identical alpha-test decisions (it fuses with explicit FMAs, alike in both).
# project.cpp: per-Gaussian formulas whose forward and backward never compare decisions, so FMA
# contraction is free to apply; no errno / trapping math lets sqrt and the clamps vectorise.
# (Not -ffast-math: the culling relies on isfinite and NaN comparisons.)
SOURCES = {HERE / "csrc" / "tiles.cpp": ["-ffp-contract=off"],
           HERE / "csrc" / "project.cpp": ["-ffp-contract=fast", "-fno-math-errno", "-fno-trapping-math"],
           # relit shading (splatting/relight/render.py): a serial per-pixel formula; -ffast-math lets
           # the sRGB encoding's powf vectorise (glibc's SIMD variants); no NaN or inf reach it
           HERE.parent / "relight" / "csrc" / "shade.cpp": ["-ffast-math"]}
SRCS = list(SOURCES)
BUILD_DIR = HERE / "_build"

_lib = None


def compiler():
    return os.environ.get("CXX") or shutil.which("g++") or shutil.which("c++")


def lib_path():
    flags = " ".join(FLAGS + [f for p in SRCS for f in SOURCES[p]])
    h = hashlib.sha1(b"".join(p.read_bytes() for p in SRCS) + flags.encode()).hexdigest()[:12]
    return BUILD_DIR / f"libtiles-{h}.so"


def build(quiet=False):
    """Compile into a temporary file and rename it into place (concurrent builders are safe)."""
    path = lib_path()
    if path.exists():
        return path
    cxx = compiler()
    if cxx is None:
        raise RuntimeError("the tiled rasterizer needs a C++ compiler (apt-get install g++), "
                           "or pass backend='torch' to rasterize()")
    BUILD_DIR.mkdir(exist_ok=True)
    if not quiet:
        print(f"splatting.raster: building {path.name} with {cxx} (once)", file=sys.stderr, flush=True)
    with tempfile.TemporaryDirectory(dir=BUILD_DIR) as tmpdir:
        objs = []
        for src, extra in SOURCES.items():  # one object per source: each with its own flags
            obj = os.path.join(tmpdir, src.stem + ".o")
            _run([cxx, *FLAGS, *extra, "-c", str(src), "-o", obj])
            objs.append(obj)
        tmp = os.path.join(tmpdir, path.name)
        _run([cxx, *FLAGS, "-shared", "-o", tmp, *objs])
        os.replace(tmp, path)  # atomic: concurrent builders and users never see a partial file
    for old in BUILD_DIR.glob("libtiles-*.so"):  # superseded builds (a process still using one keeps it)
        if old != path:
            old.unlink(missing_ok=True)
    return path


def _run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise RuntimeError(f"building the tiled rasterizer failed:\n{r.stderr.strip()}")


def load():
    global _lib
    if _lib is None:
        lib = ctypes.CDLL(str(build()))
        i64, i32, p = ctypes.c_int64, ctypes.c_int, ctypes.c_void_p
        for sfx in ("f32", "f64"):
            f = getattr(lib, f"gs_bin_{sfx}")
            f.argtypes, f.restype = [i64, p, p, p, p, p, p, i32, i32, i32, p, p, p, p, p, p, p], None
            f = getattr(lib, f"gs_forward_{sfx}")
            f.argtypes, f.restype = [i64, p, i32, p, p, i32, i32, i32, i32, p, p, p, p, p, p, p, i32, p, p, p, p, p, p, i32, p, p, p, p, i32], i32
            f = getattr(lib, f"gs_backward_{sfx}")
            f.argtypes, f.restype = [i64, i64, p, p, i32, i32, i32, i32, p, p, p, p, p, p, p, p, i32, p, p, p, p, p, p, p, p, p, p], None
            f = getattr(lib, f"gs_preprocess_fwd_{sfx}")
            f.argtypes, f.restype = [i64, p, p, p, i32, i32, p, p, p, p, p, i32, i32, i32, p, p, p, p, p, p, p], None
            f = getattr(lib, f"gs_preprocess_bwd_{sfx}")
            f.argtypes, f.restype = [i64, p, p, p, i32, i32, p, p, p, p, p, i32, i32, i32, p, p, p, p, p, p, p, p, p], None
            f = getattr(lib, f"gs_preprocess_fwd_cams_{sfx}")
            f.argtypes, f.restype = [i32, i64, p, p, p, i32, i32, p, p, p, p, p, i32, i32, i32, p, p, p, p, p, p, p], None
            f = getattr(lib, f"gs_forward_cameras_{sfx}")
            f.argtypes, f.restype = [i32, i64, p, p, p, p, p, p, i32, i32, i32, i32, p, p, p, i32, i32, p, p, p, p], None
        _lib = lib
    return _lib


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.parse_args(argv)
    try:
        print(build())
    except RuntimeError as e:
        print(f"error: {str(e).splitlines()[0]}", file=sys.stderr)
        print(e, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
