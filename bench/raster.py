"""Rasterizer benchmark (default back end: the tiled C++ one, splatting/raster/).

Keys (medians, 512^2, `threads` OpenMP threads, 2 by default as on the target machine):
  raster_fwdbwd_s       {"10k", "50k", "100k"}: rasterize + L1 loss + backward, seconds
  raster_fwd_ms         {"50k"}: rasterize under no_grad (an image for the dataset), milliseconds
  raster_tiles_vs_torch {"fwdbwd_torch_s", "fwdbwd_tiles_s", "speedup"} at 50k: the two back ends
                        measured interleaved (one of each per round), so machine load hits both
  raster_thread_scaling {"1_thread_s", "2_threads_s", "speedup", "speedup_of_fastest"}: fwd+bwd at
                        50k, 1 vs 2 threads, interleaved (medians; and the fastest round of each)
  raster_cameras        {"one_call_ms", "calls_ms", "speedup", "one_call_cpu_ms", "calls_cpu_ms",
                        "cameras", "threads"}: 4 cameras at 50k, no grad (a dataset's views), rendered
                        by ONE rasterization() call (one C++ pass over camera x tile) against one call
                        per camera; alternating rounds, medians; *_cpu_ms: time.process_time (all
                        threads' CPU, the least sensitive to other processes)
  raster_cameras_stages_cpu_ms  the same two ways at ONE thread, CPU ms per stage (one_* / calls_*:
                        preprocess, bin_blend, glue, total) and bound = calls_total / one_bin_blend,
                        the most the one call could gain if its projection, SH and glue were free
  raster_stages_cpu_ms  at 50k, ONE thread, CPU time (time.process_time: the least sensitive to
                        other processes on a shared machine), medians: each C++ stage of the tiled
                        back end (preprocess, bin, blend, blend_bwd, preprocess_bwd) and the torch /
                        Python glue around them (fwd_glue, bwd_glue: total minus the stages; the
                        loss and its backward count as glue), fwd_total, bwd_total
A synthetic bike-like part (two wheels, tubes, a few mm-to-cm Gaussians) about 1.7 m long around
the origin, seen by ring view 3 (12 m away, focal 2085, 512^2): it spans ~300 px like the real
parts. Run alone: `python -m bench.raster [--threads N] [--sizes 10k,50k] [--only cameras]`.

OMP_WAIT_POLICY=PASSIVE: on the shared 2-core machine, torch's OpenMP threads otherwise spin at
every barrier while the other core runs someone else's process; measured 2.2 s -> 0.3 s per 50k
iteration with 2 threads under load. It only takes effect if set before torch is first imported.
"""
import argparse
import math
import os
import statistics
import time

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
import torch  # noqa: E402

SIZES = {"10k": 10_000, "50k": 50_000, "100k": 100_000}


def bike_like_gaussians(n, sh_degree=3, seed=0, dtype=torch.float32):
    """Means on two wheels (tori) and six tubes in the Z = 0 plane, bike-part-sized scales."""
    g = torch.Generator().manual_seed(seed)
    rnd = lambda *s: torch.rand(*s, generator=g, dtype=torch.float64)
    n_wheel = n * 6 // 10
    # wheels: radius 0.35 m centred at x = +-0.55, y = 0.35; tyre tube radius 2 cm
    t = rnd(n_wheel) * 2 * math.pi
    cx = torch.where(rnd(n_wheel) < 0.5, torch.tensor(-0.55), torch.tensor(0.55)).double()
    p = rnd(n_wheel) * 2 * math.pi
    rr = 0.35 + 0.02 * torch.cos(p)
    wheel = torch.stack([cx + rr * torch.cos(t), 0.35 + rr * torch.sin(t), 0.02 * torch.sin(p)], 1)
    # tubes: frame triangle, fork, handlebar, seat post; radius 1.5 cm
    segs = torch.tensor([[-0.55, 0.35, 0, 0.0, 0.35, 0], [0.0, 0.35, 0, -0.15, 0.9, 0],
                         [-0.15, 0.9, 0, 0.45, 0.85, 0], [0.0, 0.35, 0, 0.45, 0.85, 0],
                         [0.45, 0.85, 0, 0.55, 0.35, 0], [0.45, 0.95, -0.25, 0.45, 0.95, 0.25]],
                        dtype=torch.float64)
    m = n - n_wheel
    k = torch.randint(0, len(segs), (m,), generator=g)
    s = rnd(m, 1)
    tube = segs[k, :3] * (1 - s) + segs[k, 3:] * s + (rnd(m, 3) - 0.5) * 0.03
    means = torch.cat([wheel, tube]) - torch.tensor([0.0, 0.5, 0.0], dtype=torch.float64)
    # scales: log-uniform 1 mm .. 2 cm per axis (0.2 .. 3.5 px std at 12 m)
    scales = torch.exp(math.log(1e-3) + rnd(n, 3) * math.log(20.0))
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    opac = 0.1 + 0.9 * rnd(n)
    sh = torch.randn(n, (sh_degree + 1) ** 2, 3, generator=g, dtype=torch.float64) * 0.2
    return [x.to(dtype) for x in (means, quats, scales, opac, sh)]


def _camera_and_params(n):
    from splatting.raster.camera import ring_camera

    return ring_camera(30.0), [p.requires_grad_(True) for p in bike_like_gaussians(n)]


def _fwdbwd_once(params, cam, backend=None):
    from splatting.raster.api import rasterize

    t0 = time.perf_counter()
    out = rasterize(*params, cam, backend=backend)
    out["rgb"].abs().mean().backward()  # L1 to a black target
    dt = time.perf_counter() - t0
    for p in params:
        p.grad = None
    return dt, out


def time_fwdbwd(n, iters=7, warmup=2, camera=None, backend=None):
    cam, params = _camera_and_params(n)
    cam = camera or cam
    times = []
    for i in range(warmup + iters):
        dt, out = _fwdbwd_once(params, cam, backend)
        if i >= warmup:
            times.append(dt)
    return statistics.median(times), min(times), out


def time_fwd_ms(n, iters=9, warmup=2, backend=None):
    from splatting.raster.api import rasterize

    cam, params = _camera_and_params(n)
    params = [p.detach() for p in params]
    times = []
    with torch.no_grad():
        for i in range(warmup + iters):
            t0 = time.perf_counter()
            rasterize(*params, cam, backend=backend)
            if i >= warmup:
                times.append(time.perf_counter() - t0)
    return 1e3 * statistics.median(times)


def interleaved(n, variants, rounds=7, warmup=1):
    """variants: name -> (backend, threads). One run of each per round; medians per name."""
    cam, params = _camera_and_params(n)
    times = {k: [] for k in variants}
    old = torch.get_num_threads()
    try:
        for r in range(warmup + rounds):
            for name, (backend, threads) in variants.items():
                torch.set_num_threads(threads)
                dt, _ = _fwdbwd_once(params, cam, backend)
                if r >= warmup:
                    times[name].append(dt)
    finally:
        torch.set_num_threads(old)
    return {k: statistics.median(v) for k, v in times.items()}, {k: min(v) for k, v in times.items()}


def time_cameras(n, cameras=4, threads=2, rounds=9, warmup=1):
    """Forward without grad of `cameras` ring views (90 degrees apart / cameras): all of them in one
    rasterization() call against one call per camera, alternating within each round (so the
    machine's load hits both alike). Medians in ms, and the medians of the per-round ratios."""
    from splatting.raster.api import rasterization
    from splatting.raster.camera import ring_camera

    params = [p.detach() for p in bike_like_gaussians(n)]
    cams = [ring_camera(30.0 + 360.0 * i / cameras) for i in range(cameras)]
    one, calls, one_cpu, calls_cpu = [], [], [], []
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with torch.no_grad():
            for r in range(warmup + rounds):
                c0, t0 = time.process_time(), time.perf_counter()
                out = rasterization(*params, cameras=cams, per_camera=True)
                c1, t1 = time.process_time(), time.perf_counter()
                for cam in cams:
                    rasterization(*params, cameras=[cam], per_camera=True)
                c2, t2 = time.process_time(), time.perf_counter()
                if r >= warmup:
                    one.append(t1 - t0)
                    calls.append(t2 - t1)
                    one_cpu.append(c1 - c0)
                    calls_cpu.append(c2 - c1)
    finally:
        torch.set_num_threads(old)
    assert all(o["alpha"].max() > 0.5 for o in out)  # every view sees the bike
    ratio = statistics.median(c / o for c, o in zip(calls, one))
    return {"one_call_ms": round(1e3 * statistics.median(one), 2), "calls_ms": round(1e3 * statistics.median(calls), 2),
            "speedup": round(ratio, 2), "one_call_cpu_ms": round(1e3 * statistics.median(one_cpu), 2),
            "calls_cpu_ms": round(1e3 * statistics.median(calls_cpu), 2), "cameras": cameras, "threads": threads}


def camera_stages_cpu_ms(n, cameras=4, rounds=9, warmup=2):
    """One thread, CPU ms of time_cameras' two ways split by stage: preprocess (projection and SH of
    every camera), bin_blend (binning, sort, tile lists, blending: per camera by nature, each camera
    its own depth order and its own pixels) and glue (the rest: Python, torch); medians.  bound: the
    speed-up the one call would have if its preprocess and glue took no time at all."""
    from splatting.raster import build
    from splatting.raster.api import rasterization
    from splatting.raster.camera import ring_camera

    params = [p.detach() for p in bike_like_gaussians(n)]
    cams = [ring_camera(30.0 + 360.0 * i / cameras) for i in range(cameras)]
    old, lib = torch.get_num_threads(), build.load()
    rows = {"one": [], "calls": []}
    torch.set_num_threads(1)
    try:
        with torch.no_grad():
            for r in range(warmup + rounds):
                for way, groups in (("one", [cams]), ("calls", [[c] for c in cams])):
                    build._lib = clock = _StageClock(lib)
                    t0 = time.process_time()
                    for g in groups:
                        rasterization(*params, cameras=g, per_camera=True)
                    total = 1e3 * (time.process_time() - t0)
                    st = {k: 1e3 * v for k, v in clock.times.items()}
                    st["bin_blend"] = st.pop("bin_blend", 0.0) + st.pop("bin", 0.0) + st.pop("blend", 0.0)
                    st["glue"], st["total"] = total - st["preprocess"] - st["bin_blend"], total
                    if r >= warmup:
                        rows[way].append(st)
    finally:
        build._lib = lib
        torch.set_num_threads(old)
    res = {f"{way}_{k}": round(statistics.median(x[k] for x in rs), 2) for way, rs in rows.items() for k in rs[0]}
    res["bound"] = round(res["calls_total"] / res["one_bin_blend"], 2)
    return res


def run_cameras(results, threads=2):
    r = time_cameras(SIZES["50k"], threads=threads)
    results["raster_cameras"] = r
    print(f"raster {r['cameras']} cameras 50k, no grad, {threads} thread(s): one call {r['one_call_ms']:.1f} ms, "
          f"one call each {r['calls_ms']:.1f} ms, {r['speedup']:.2f}x (median of per-round ratios; CPU time of all "
          f"threads {r['one_call_cpu_ms']:.1f} against {r['calls_cpu_ms']:.1f} ms; {_load()})",
          flush=True)
    st = camera_stages_cpu_ms(SIZES["50k"])
    results["raster_cameras_stages_cpu_ms"] = st
    print("raster 4 cameras 50k, 1 thread, CPU ms: " + ", ".join(f"{k} {v:.2f}" for k, v in st.items())
          + f" ({_load()})", flush=True)
    return results


class _StageClock:
    """Stands in for the tiled back end's ctypes library and times each C call (CPU time)."""

    NAMES = {"gs_preprocess_fwd": "preprocess", "gs_bin": "bin", "gs_forward": "blend",
             "gs_backward": "blend_bwd", "gs_preprocess_bwd": "preprocess_bwd",
             # the several-camera pass: bin and blend of every camera are one C call
             "gs_preprocess_fwd_cams": "preprocess", "gs_forward_cameras": "bin_blend"}

    def __init__(self, lib):
        self._lib, self.times = lib, {}

    def __getattr__(self, name):
        f = getattr(self._lib, name)
        stage = self.NAMES.get(name.rsplit("_", 1)[0])
        if stage is None:
            return f

        def timed(*args):
            t0 = time.process_time()
            r = f(*args)
            self.times[stage] = self.times.get(stage, 0.0) + time.process_time() - t0
            return r
        return timed


def stage_cpu_ms(n, iters=9, warmup=2):
    """One thread, CPU ms per stage of a fwd + bwd (L1 loss) and the glue between them; medians."""
    from splatting.raster import build
    from splatting.raster.api import rasterize

    cam, params = _camera_and_params(n)
    old, lib = torch.get_num_threads(), build.load()
    rows = []
    torch.set_num_threads(1)
    try:
        for i in range(warmup + iters):
            build._lib = clock = _StageClock(lib)
            t0 = time.process_time()
            out = rasterize(*params, cam, backend="tiles")
            loss = out["rgb"].abs().mean()
            t1 = time.process_time()
            loss.backward()
            t2 = time.process_time()
            for p in params:
                p.grad = None
            st = clock.times
            if i >= warmup:
                fwd, bwd = 1e3 * (t1 - t0), 1e3 * (t2 - t1)
                row = {k: 1e3 * v for k, v in st.items()}
                row["fwd_glue"] = fwd - row["preprocess"] - row["bin"] - row["blend"]
                row["bwd_glue"] = bwd - row["blend_bwd"] - row["preprocess_bwd"]
                row["fwd_total"], row["bwd_total"] = fwd, bwd
                rows.append(row)
    finally:
        build._lib = lib
        torch.set_num_threads(old)
    return {k: round(statistics.median(r[k] for r in rows), 2) for k in rows[0]}


def _load():
    return f"OMP_WAIT_POLICY={os.environ.get('OMP_WAIT_POLICY', 'unset')}, load avg {os.getloadavg()[0]:.1f}"


def run(results, threads=2, sizes=None):
    old = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        res = {}
        for key in sizes or SIZES:
            s, fastest, out = time_fwdbwd(SIZES[key])
            res[key] = round(s, 4)
            cover = (out["alpha"] > 0.5).float().mean().item()
            print(f"raster fwd+bwd {key:>5} Gaussians, 512^2, {threads} thread(s), {out['backend']}: {s:.3f} s/iter "
                  f"median, {fastest:.3f} min (alpha>0.5 on {100 * cover:.1f}% of pixels; {_load()})", flush=True)
        results["raster_fwdbwd_s"] = res
        ms = time_fwd_ms(SIZES["50k"])
        results["raster_fwd_ms"] = {"50k": round(ms, 2)}
        print(f"raster fwd 50k, no grad, {threads} thread(s): {ms:.1f} ms median ({_load()})", flush=True)
    finally:
        torch.set_num_threads(old)
    m, _ = interleaved(SIZES["50k"], {"torch": ("torch", threads), "tiles": ("tiles", threads)})
    results["raster_tiles_vs_torch"] = {"fwdbwd_torch_s": round(m["torch"], 4), "fwdbwd_tiles_s": round(m["tiles"], 4),
                                        "speedup": round(m["torch"] / m["tiles"], 2)}
    print(f"raster fwd+bwd 50k interleaved, {threads} threads: torch {m['torch']:.3f} s, tiles {m['tiles']:.3f} s, "
          f"{m['torch'] / m['tiles']:.1f}x ({_load()})", flush=True)
    run_cameras(results, threads)
    st = stage_cpu_ms(SIZES["50k"])
    results["raster_stages_cpu_ms"] = st
    print("raster stages 50k, 1 thread, CPU ms: " + ", ".join(f"{k} {v:.1f}" for k, v in st.items())
          + f" ({_load()})", flush=True)
    # min as well as median: on a shared machine the fastest round is the one least disturbed
    m, lo = interleaved(SIZES["50k"], {"1": ("tiles", 1), "2": ("tiles", 2)}, rounds=9)
    results["raster_thread_scaling"] = {"1_thread_s": round(m["1"], 4), "2_threads_s": round(m["2"], 4),
                                        "speedup": round(m["1"] / m["2"], 2),
                                        "speedup_of_fastest": round(lo["1"] / lo["2"], 2)}
    print(f"raster fwd+bwd 50k tiles interleaved: 1 thread {m['1']:.3f} s, 2 threads {m['2']:.3f} s, "
          f"{m['1'] / m['2']:.2f}x (fastest rounds {lo['1']:.3f} / {lo['2']:.3f} s: {lo['1'] / lo['2']:.2f}x; "
          f"{_load()})", flush=True)
    return results


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--sizes", default=",".join(SIZES))
    ap.add_argument("--only", choices=["cameras"], help="measure only this (cameras: 4 cameras in one call "
                    "against 4 calls)")
    a = ap.parse_args()
    if a.threads < 1:
        ap.error("--threads must be >= 1")
    print(run_cameras({}, a.threads) if a.only == "cameras" else run({}, a.threads, a.sizes.split(",")))
