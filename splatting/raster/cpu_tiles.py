"""Tiled multi-threaded CPU compositing (csrc/tiles.cpp) as a torch autograd Function.

composite_tiles(means2d, conics, opacities, feats, depths, radii, boxes, H, W, split=(Cf,)) ->
(one contiguous (H, W, c) image per entry c of split (c == 1: (H, W)), T_final (H, W)): the Cf
channels of sum_k w_k feats_k over the Gaussians at each pixel front to back, w_k = alpha_k T_k,
feats (N, Cf) or a list of (N, c_i) parts whose columns are the Cf channels in that order (the
C++ gathers each Gaussian's channels from the parts: no concatenated (N, Cf) table is built),
T_final the transmittance left (alpha = 1 - T_final), cut into consecutive channel groups (colour,
extra features, depth) that the C++ writes and reads as separate images. Differentiable in
means2d, conics, opacities and feats (any number Cf of channels). Same image formation as
splatting/raster/sparse.py's torch path; see docs/rasterizer.md.

Steps (all threads: torch.get_num_threads()):
  1. gs_bin: one record per Gaussian, its pixel rectangle (3-sigma box clipped to where alpha can
     reach 1/255); the visible ones sorted by camera z (stable radix sort: ties in index order, as
     the torch path's stable argsort); per-tile counts and offsets;
  2. gs_forward: tile lists filled in depth order, then per 16x16 tile front-to-back blending with
     early termination;
  3. gs_backward: per tile back to front, per-(tile, Gaussian) sums, then per Gaussian.
Optionally (groups, forward only) each group's transmittance as if it were rendered alone, from
the same pass (csrc/tiles.cpp, forward<S, GROUPS>): what amodal instance masks need.
"""
import ctypes
import threading

import torch

from . import build

_SUFFIX = {torch.float32: "f32", torch.float64: "f64"}


def _ptr(t):
    return t.data_ptr()


def _nptr(t):
    return None if t is None else t.data_ptr()


_scratch = threading.local()


def _buffer(name, numel, dtype, reuse):
    """torch.empty(numel) of dtype; with reuse, a view of this thread's buffer `name`, kept (and
    grown) across calls: the scratch of a render that no backward will read (records, tile lists,
    sorted channels), so a forward-only render gets no fresh pages to fault in for it (at 512 px
    and 45k Gaussians ~7 MB, and page faults were most of what a relit render paid over a baked
    one, docs/relighting.md)."""
    if not reuse:
        return torch.empty(numel, dtype=dtype)
    pool = getattr(_scratch, "pool", None)
    if pool is None:
        pool = _scratch.pool = {}
    b = pool.get(name)
    if b is None or b.dtype != dtype or b.numel() < numel:
        b = pool[name] = torch.empty(max(numel, 1), dtype=dtype)
    return b[:numel]


def _ptrs(ts):
    """A C array of the tensors' data pointers (null for None)."""
    return (ctypes.c_void_p * len(ts))(*[None if t is None else t.data_ptr() for t in ts])


class _TileComposite(torch.autograd.Function):
    """The split's images, T_final (H, W), T_groups. A gradient that autograd hands over as None
    (an output nobody used, e.g. alpha under an RGB loss) goes to the C++ as a null pointer
    rather than as a zero image."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, depths, radii, boxes, H, W, groups, n_groups, split, reuse, *parts):
        lib = build.load()
        dt = means2d.dtype
        if dt not in _SUFFIX:
            raise TypeError(f"tiled rasterizer: float32 or float64 tensors, got {dt}")
        sfx = _SUFFIX[dt]
        nt = max(1, torch.get_num_threads())
        n = means2d.shape[0]
        m2 = means2d.detach().contiguous()
        cn = conics.detach().to(dt).contiguous()
        op = opacities.detach().to(dt).contiguous()
        fe = [p.detach().to(dt).contiguous() for p in parts]
        isz = [p.shape[1] for p in fe]
        cf = sum(isz)
        z = depths.detach().to(dt).contiguous()
        rd = radii.to(torch.int64).contiguous()
        bx = boxes.to(torch.int64).contiguous()
        tile = lib.gs_tile_size()
        ntiles = -(-W // tile) * -(-H // tile)
        # the binning's and blending's scratch: kept for the backward, or reused when there is none
        recs = _buffer("recs", max(n, 1) * getattr(lib, f"gs_rec_bytes_{sfx}")(), torch.uint8, reuse)
        order = _buffer("order", max(n, 1), torch.int32, reuse)
        cursor = _buffer("cursor", lib.gs_chunks(nt) * ntiles, torch.int64, reuse)
        tile_off = _buffer("tile_off", ntiles + 1, torch.int64, reuse)
        goff = _buffer("goff", n + 1, torch.int64, reuse)
        sizes = torch.zeros(2, dtype=torch.int64)
        getattr(lib, f"gs_bin_{sfx}")(n, _ptr(m2), _ptr(cn), _ptr(op), _ptr(z), _ptr(rd), _ptr(bx), W, H, nt,
                                      _ptr(recs), _ptr(order), _ptr(cursor), _ptr(tile_off), _ptr(goff),
                                      _ptr(sizes))
        nv, total = sizes.tolist()
        lst = _buffer("lst", max(total, 1), torch.int32, reuse)
        slot = _buffer("slot", max(total, 1), torch.int64, reuse)
        fs = _buffer("fs", max(nv, 1) * cf, dt, reuse).view(max(nv, 1), cf)
        outs = [torch.empty((H, W, c) if c > 1 else (H, W), dtype=dt) for c in split]
        T_final = torch.empty(H, W, dtype=dt)
        last = _buffer("last", H * W, torch.int32, reuse).view(H, W)
        ng = int(n_groups) if groups is not None else 0
        gr = groups.to(torch.int32).contiguous() if ng else None
        g_sorted = _buffer("g_sorted", max(nv, 1), torch.int32, reuse) if ng else None
        T_groups = torch.empty(ng, H, W, dtype=dt)
        osz = (ctypes.c_int * len(split))(*split)
        getattr(lib, f"gs_forward_{sfx}")(nv, _ptr(order), len(fe), (ctypes.c_int * len(fe))(*isz), _ptrs(fe), cf,
                                          W, H, nt, _ptr(recs), _ptr(cursor),
                                          _ptr(tile_off), _ptr(goff), _ptr(lst), _ptr(slot), _ptr(fs),
                                          len(split), osz, _ptrs(outs), _ptr(T_final), _ptr(last), _nptr(gr), ng,
                                          _nptr(g_sorted), _ptr(T_groups) if ng else None)
        ctx.mark_non_differentiable(T_groups)
        ctx.geom = (n, cf, H, W, nv, order, recs, tile_off, goff, lst, slot, fs, last, split)
        ctx.save_for_backward(T_final)
        ctx.dtypes = (conics.dtype, opacities.dtype, [p.dtype for p in parts])
        ctx.isz = isz
        return (*outs, T_final, T_groups)

    @staticmethod
    def backward(ctx, *grads):
        n, cf, H, W, nv, order, recs, tile_off, goff, lst, slot, fs, last, split = ctx.geom
        (T_final,) = ctx.saved_tensors
        dt = T_final.dtype
        sfx = _SUFFIX[dt]
        g_outs = [None if g is None else g.to(dt).contiguous() for g in grads[:len(split)]]
        g_T = grads[len(split)]
        g_T = None if g_T is None else g_T.to(dt).contiguous()
        g_m2 = torch.zeros(n, 2, dtype=dt)
        g_cn = torch.zeros(n, 3, dtype=dt)
        g_op = torch.zeros(n, dtype=dt)
        g_fe = torch.zeros(n, cf, dtype=dt)
        lib = build.load()
        getattr(lib, f"gs_backward_{sfx}")(nv, _ptr(order), cf, W, H, max(1, torch.get_num_threads()), _ptr(recs),
                                           _ptr(tile_off), _ptr(goff), _ptr(lst), _ptr(slot), _ptr(fs),
                                           _ptr(T_final), _ptr(last), len(split), (ctypes.c_int * len(split))(*split),
                                           _ptrs(g_outs), _nptr(g_T), _ptr(g_m2), _ptr(g_cn), _ptr(g_op), _ptr(g_fe))
        dc, do, df = ctx.dtypes
        g_parts = [g.to(d) for g, d in zip(g_fe.split(ctx.isz, 1), df)]
        return (g_m2, g_cn.to(dc), g_op.to(do), None, None, None, None, None, None, None, None, None, *g_parts)


def composite_tiles(means2d, conics, opacities, feats, depths, radii, boxes, H, W, groups=None, n_groups=0,
                    split=None):
    """See the module docstring. CPU tensors only; float32 or float64 (means2d's dtype).
    feats: (N, Cf), or a list of (N, c_i) parts (Cf = sum c_i).
    split: channel counts (each >= 1) summing to Cf; None: one (H, W, Cf) image.
    groups (N,) int in [-1, n_groups) (-1: in no group), n_groups >= 1: also returns T_groups
    (n_groups, H, W), each group's transmittance rendered alone (not differentiable).
    -> (*images, T_final) or (*images, T_final, T_groups) with groups."""
    if means2d.device.type != "cpu":
        raise ValueError("the tiled rasterizer runs on CPU tensors; use backend='torch' for "
                         f"{means2d.device.type} tensors")
    parts = (feats,) if torch.is_tensor(feats) else tuple(feats)
    n = means2d.shape[0]
    if not parts or any(p.dim() != 2 or p.shape[0] != n or p.shape[1] < 1 for p in parts):
        raise ValueError(f"composite_tiles: feats must be ({n}, C) tensors with C >= 1, got "
                         f"{[tuple(p.shape) for p in parts]}")
    cf = sum(p.shape[1] for p in parts)
    split = (cf,) if split is None else tuple(int(c) for c in split)
    if not split or min(split) < 1 or sum(split) != cf:
        raise ValueError(f"composite_tiles: split {split} must be channel counts >= 1 summing to {cf}")
    # no backward can follow: the scratch is reused across calls (_buffer)
    reuse = not (torch.is_grad_enabled() and any(t.requires_grad for t in (means2d, conics, opacities, *parts)))
    if groups is not None:
        if n_groups < 1 or groups.shape != (n,):
            raise ValueError(f"composite_tiles: groups must be ({n},) with n_groups >= 1")
        if len(groups) and not (int(groups.min()) >= -1 and int(groups.max()) < n_groups):
            raise ValueError(f"composite_tiles: group ids must lie in [-1, {n_groups})")
        return _TileComposite.apply(means2d, conics, opacities, depths, radii, boxes, H, W, groups, n_groups, split,
                                    reuse, *parts)
    return _TileComposite.apply(means2d, conics, opacities, depths, radii, boxes, H, W, None, 0, split, reuse,
                                *parts)[:-1]
