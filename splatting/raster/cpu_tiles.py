"""Tiled multi-threaded CPU compositing (csrc/tiles.cpp) as a torch autograd Function.

composite_tiles(means2d, conics, opacities, planes, depths, radii, boxes, H, W, background=None) ->
(one contiguous image per plane (H, W, c), or (H, W) for a 1-channel plane, alpha (H, W),
T_final (H, W)): for each plane (N, c) or (N,) of per-Gaussian channels (colour, extra features,
depth), sum_k w_k plane_k over the Gaussians at each pixel front to back, w_k = alpha_k T_k;
T_final the transmittance left and alpha = 1 - T_final (both written by the C++, both
differentiable; T_final is None when no gradient can flow). background (c,) for the first plane:
its image is composited over it (+ T_final * background) in the same pass, and its gradient
summed there too. The planes are read and their gradients written in place by the C++: no
concatenated (N, Cf) table and no slicing of its gradient. Differentiable in means2d, conics,
opacities, the planes and the background. Same image formation as splatting/raster/sparse.py's torch path; see
docs/rasterizer.md.

Steps (all threads: torch.get_num_threads()):
  1. gs_bin: one record per Gaussian, its pixel rectangle (3-sigma box clipped to where alpha can
     reach 1/255); the visible ones sorted by camera z (stable radix sort: ties in index order, as
     the torch path's stable argsort); per-tile counts and offsets;
  2. gs_forward: tile lists filled in depth order, then per 16x16 tile front-to-back blending with
     early termination;
  3. gs_backward: per tile back to front, per-(tile, Gaussian) sums, then per Gaussian.
Optionally (groups, forward only) each group's alpha as if it were rendered alone, from
the same pass (csrc/tiles.cpp, forward<S, GROUPS>): what amodal instance masks need.

Relit renders (forward only): shade=TileShade(...) shades each tile as it is finished
(csrc/shade.cpp rl_shade_tile_f32, the compositor's epilogue): the first plane (the reflectance)
comes back as the display colour and the feature plane is not written unless asked for, so no
feature image is written and read back (splatting/relight/render.py, docs/relighting.md).

Glue kept small on purpose: every torch op here runs between the parallel C calls on one thread
(and a parallel one, >= 32k elements, first wakes the other thread: ~50-100 us under
OMP_WAIT_POLICY=PASSIVE). Gradients are not materialised (an unused output's gradient is a null
pointer), the gradient buffers are allocated uninitialised (the C++ writes every entry).
"""
import ctypes
import threading
from typing import NamedTuple

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
    and 45k Gaussians ~7 MB; docs/relighting.md)."""
    if not reuse:
        return torch.empty(numel, dtype=dtype)
    pool = getattr(_scratch, "pool", None)
    if pool is None:
        pool = _scratch.pool = {}
    b = pool.get(name)
    if b is None or b.dtype != dtype or b.numel() < numel:
        b = pool[name] = torch.empty(max(numel, 1), dtype=dtype)
    return b[:numel]


class TileShade(NamedTuple):
    """The relit shading as the compositor's tile epilogue (csrc/shade.cpp rl_shade_tile_f32):
    params (24,) float32 and flags as rl_shade_f32 takes them (splatting/relight/render.py
    shade_params / shade_flags); the planes must be the reflectance (3) then the relight features
    the flags name.  features: also write the composited feature plane (else it is None)."""
    params: torch.Tensor
    flags: int
    features: bool = False


def _ptrs(ts):
    """A C array of the tensors' data pointers (null for None)."""
    return (ctypes.c_void_p * len(ts))(*[None if t is None else t.data_ptr() for t in ts])


class _TileComposite(torch.autograd.Function):
    """The planes' images, alpha (H, W), T_final (H, W), A_groups. A gradient that autograd hands
    over as None (an output nobody used, e.g. alpha under an RGB loss) goes to the C++ as a null
    pointer rather than as a zero image; a plane whose image got no gradient gets None back."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, depths, radii, boxes, background, H, W, groups, n_groups, keep,
                shade, unwritten, nparts, *parts):
        lib = build.load()
        dt = means2d.dtype
        if dt not in _SUFFIX:
            raise TypeError(f"tiled rasterizer: float32 or float64 tensors, got {dt}")
        sfx = _SUFFIX[dt]
        nt = max(1, torch.get_num_threads())
        n = means2d.shape[0]
        isz = [1 if p.dim() == 1 else p.shape[1] for p in parts]
        cuts = [sum(nparts[:i]) for i in range(len(nparts) + 1)]  # plane i: parts cuts[i]..cuts[i+1]-1
        split = [sum(isz[cuts[i]:cuts[i + 1]]) for i in range(len(nparts))]
        cf = sum(split)
        m2 = means2d.detach().contiguous()
        cn = conics.detach().to(dt).contiguous()
        op = opacities.detach().to(dt).contiguous()
        fe = [p.detach().to(dt).contiguous() for p in parts]
        z = depths.detach().to(dt).contiguous()
        rd = radii.to(torch.int64).contiguous()
        bx = boxes.to(torch.int64).contiguous()
        bg = None if background is None else background.detach().to(dt).contiguous()
        tile = lib.gs_tile_size()
        ntiles = -(-W // tile) * -(-H // tile)
        # the binning's and blending's scratch: kept for the backward, or reused when there is none
        reuse = not keep
        recs = _buffer("recs", max(n, 1) * getattr(lib, f"gs_rec_bytes_{sfx}")(), torch.uint8, reuse)
        order = _buffer("order", max(n, 1), torch.int32, reuse)
        rank = _buffer("rank", max(n, 1), torch.int32, reuse)
        cursor = _buffer("cursor", lib.gs_chunks(nt) * ntiles, torch.int64, reuse)
        tile_off = _buffer("tile_off", ntiles + 1, torch.int64, reuse)
        goff = _buffer("goff", n + 1, torch.int64, reuse)
        sizes = torch.empty(2, dtype=torch.int64)
        getattr(lib, f"gs_bin_{sfx}")(n, _ptr(m2), _ptr(cn), _ptr(op), _ptr(z), _ptr(rd), _ptr(bx), W, H, nt,
                                      _ptr(recs), _ptr(order), _ptr(rank), _ptr(cursor), _ptr(tile_off),
                                      _ptr(goff), _ptr(sizes))
        nv, total = sizes.tolist()
        lst = _buffer("lst", max(total, 1), torch.int32, reuse)
        slot = torch.empty(max(total, 1), dtype=torch.int64) if keep else None
        fs = _buffer("fs", max(nv, 1) * cf, dt, reuse).view(max(nv, 1), cf)
        outs = [None if i in unwritten else torch.empty((H, W, c) if c > 1 else (H, W), dtype=dt)
                for i, c in enumerate(split)]
        alpha = torch.empty(H, W, dtype=dt)
        # T_final, last and slot only for a backward (a no-grad render skips their ~3 MB of stores)
        T_final = torch.empty(H, W, dtype=dt) if keep else None
        last = torch.empty(H, W, dtype=torch.int32) if keep else None
        ng = int(n_groups) if groups is not None else 0
        gr = groups.to(torch.int32).contiguous() if ng else None
        g_sorted = _buffer("g_sorted", max(nv, 1), torch.int32, reuse) if ng else None
        A_groups = torch.empty(ng, H, W, dtype=dt)
        osz = (ctypes.c_int * len(split))(*split)
        sprm = None if shade is None else shade.params.to(torch.float32).contiguous()
        rc = getattr(lib, f"gs_forward_{sfx}")(nv, _ptr(order), len(fe), (ctypes.c_int * len(fe))(*isz), _ptrs(fe), cf,
                                          W, H, nt, _ptr(recs), _ptr(cursor),
                                          _ptr(tile_off), _ptr(goff), _ptr(lst), _nptr(slot), _ptr(fs),
                                          len(split), osz, _ptrs(outs), _nptr(T_final), _ptr(alpha), _nptr(last),
                                          _nptr(gr), ng, _nptr(g_sorted), _ptr(A_groups) if ng else None, _nptr(bg),
                                          _nptr(sprm), 0 if shade is None else int(shade.flags))
        if rc != 0:  # composite_tiles checked these first: this is a caller of _TileComposite's mistake
            raise ValueError("composite_tiles: the tile shading needs float32, no groups, no background, a "
                             "3-channel first plane and the feature channels its flags name")
        ctx.mark_non_differentiable(A_groups)
        ctx.set_materialize_grads(False)
        ctx.geom = (n, cf, H, W, nv, order, rank, recs, tile_off, goff, lst, slot, fs, last, split, bg)
        if T_final is not None:
            ctx.save_for_backward(T_final)
        ctx.dtypes = (conics.dtype, opacities.dtype, [p.dtype for p in parts])
        ctx.parts = (cuts, [p.dim() for p in parts], isz)
        ctx.bg_dtype = None if background is None else background.dtype
        return (*outs, alpha, T_final, A_groups)

    @staticmethod
    def backward(ctx, *grads):
        n, cf, H, W, nv, order, rank, recs, tile_off, goff, lst, slot, fs, last, split, bg = ctx.geom
        (T_final,) = ctx.saved_tensors
        dt = T_final.dtype
        sfx = _SUFFIX[dt]
        np_ = len(split)
        g_outs = [None if g is None else g.to(dt).contiguous() for g in grads[:np_]]
        g_alpha, g_T = (None if g is None else g.to(dt).contiguous() for g in grads[np_:np_ + 2])
        g_m2 = torch.empty(n, 2, dtype=dt)
        g_cn = torch.empty(n, 3, dtype=dt)
        g_op = torch.empty(n, dtype=dt)
        dc, do, dps = ctx.dtypes
        # a plane's gradient is w-weighted dL/d(its image): none without one
        g_planes = [None if g is None else torch.empty((n, c) if c > 1 else (n,), dtype=dt)
                    for g, c in zip(g_outs, split)]
        g_bg = torch.empty(split[0], dtype=dt) if bg is not None and ctx.needs_input_grad[6] and g_outs[0] is not None \
            else None
        lib = build.load()
        getattr(lib, f"gs_backward_{sfx}")(n, nv, _ptr(order), _ptr(rank), cf, W, H, max(1, torch.get_num_threads()), _ptr(recs),
                                           _ptr(tile_off), _ptr(goff), _ptr(lst), _ptr(slot), _ptr(fs),
                                           _ptr(T_final), _ptr(last), np_, (ctypes.c_int * np_)(*split),
                                           _ptrs(g_outs), _nptr(g_T), _nptr(g_alpha), _ptr(g_m2), _ptr(g_cn),
                                           _ptr(g_op), _ptrs(g_planes), _nptr(bg), _nptr(g_bg))
        cuts, dims, isz = ctx.parts
        g_parts = []
        for i, g in enumerate(g_planes):  # each plane's gradient cut back into its parts' columns
            g2 = None if g is None else g.reshape(n, sum(isz[cuts[i]:cuts[i + 1]]))
            for j in range(cuts[i], cuts[i + 1]):
                c0 = sum(isz[cuts[i]:j])
                gj = None if g2 is None else g2[:, c0:c0 + isz[j]]
                g_parts.append(None if gj is None else (gj if dims[j] == 2 else gj[:, 0]).to(dps[j]))
        g_planes = g_parts
        g_bg = None if g_bg is None else g_bg.to(ctx.bg_dtype)
        return (g_m2, g_cn.to(dc), g_op.to(do), None, None, None, g_bg, None, None, None, None, None, None, None, None,
                *g_planes)


def composite_tiles(means2d, conics, opacities, planes, depths, radii, boxes, H, W, groups=None, n_groups=0,
                    background=None, shade=None):
    """See the module docstring. CPU tensors only; float32 or float64 (means2d's dtype).
    planes: a list of (N, c) or (N,) tensors (at least one; the caller's colour, features, depth);
    a plane may also be a list of such parts (its channels in that order, e.g. relit normals and
    gloss luminance): the C++ gathers them without a concatenated table.
    depths (N,): the depth-sort key (not differentiated here).
    groups (N,) int in [-1, n_groups) (-1: in no group), n_groups >= 1: also returns A_groups
    (n_groups, H, W), each group's alpha rendered alone (not differentiable).
    background: None or one value per channel of the first plane (differentiable).
    shade: None or a TileShade (forward only: no input may require a gradient under grad mode;
    float32; no groups, no background): the first image is the shaded display colour, and the
    second plane's image is None unless shade.features.
    -> (*images, alpha, T_final) or (*images, alpha, T_final, A_groups) with groups; T_final is None when
    no gradient can flow (grad mode off or no input requiring one)."""
    if means2d.device.type != "cpu":
        raise ValueError("the tiled rasterizer runs on CPU tensors; use backend='torch' for "
                         f"{means2d.device.type} tensors")
    n = means2d.shape[0]
    # a plane given as a list of parts: its columns, gathered by the C++ without a concatenation
    nparts = tuple(1 if torch.is_tensor(p) else len(p) for p in planes)
    parts = [q for p in planes for q in ((p,) if torch.is_tensor(p) else p)]
    if not planes or min(nparts) < 1 or any(p.dim() not in (1, 2) or p.shape[0] != n or (p.dim() == 2 and p.shape[1] < 1)
                                           for p in parts):
        raise ValueError(f"composite_tiles: planes must be one or more (N,) or (N, c >= 1) tensors, N = {n}; got "
                         f"{[tuple(p.shape) for p in parts]}")
    c0 = sum(1 if p.dim() == 1 else p.shape[1] for p in parts[:nparts[0]])
    if background is not None and background.shape != (c0,):
        raise ValueError(f"composite_tiles: background must be ({c0},) for the first plane, got {tuple(background.shape)}")
    # what only a backward reads is kept only when one can follow
    keep = torch.is_grad_enabled() and any(t is not None and t.requires_grad
                                           for t in (means2d, conics, opacities, background, *parts))
    unwritten = ()
    if shade is not None:
        cs = sum(1 if p.dim() == 1 else p.shape[1] for p in parts)
        need = 6 + sum(bool(shade.flags & b) for b in (1, 2, 4, 16))
        bad = [what for no, what in ((keep, "a gradient is wanted"), (means2d.dtype != torch.float32, "not float32"),
                                     (groups is not None, "groups"), (background is not None, "a background"),
                                     (c0 != 3, f"a first plane of {c0} channels, not 3"),
                                     (cs != need, f"{cs} channels where flags {shade.flags} need {need}"),
                                     (shade.params.shape != (24,), "params not (24,)")) if no]
        if bad:
            raise ValueError(f"composite_tiles: cannot shade the tiles: {', '.join(bad)}")
        unwritten = () if shade.features else tuple(range(1, len(planes)))
    if groups is not None:
        if n_groups < 1 or groups.shape != (n,):
            raise ValueError(f"composite_tiles: groups must be ({n},) with n_groups >= 1")
        if len(groups) and not (int(groups.min()) >= -1 and int(groups.max()) < n_groups):
            raise ValueError(f"composite_tiles: group ids must lie in [-1, {n_groups})")
        return _TileComposite.apply(means2d, conics, opacities, depths, radii, boxes, background, H, W, groups,
                                    n_groups, keep, None, (), nparts, *parts)
    return _TileComposite.apply(means2d, conics, opacities, depths, radii, boxes, background, H, W, None, 0, keep,
                                shade, unwritten, nparts, *parts)[:-1]


def composite_cameras(means2d, conics, opacities, planes, depths, radii, boxes, H, W, background=None):
    """composite_tiles() for C cameras of one size in one C call (csrc/tiles.cpp forward_cameras:
    threads over camera x chunk and camera x tile), forward only (no gradient).
    means2d (C,N,2), conics (C,N,3), opacities (C,N), depths (C,N) (the sort key), radii (C,N),
    boxes (C,N,4): each camera's projection (preprocess_cameras). planes: a list of planes, each a
    tensor or a list of parts; a part is (C, N, c) (per camera: the colour, the depth as (C, N, 1))
    or (N, c) / (N,) (shared by every camera: instance one-hots, labels). background: None or
    (C, c0) for the first plane. -> ([per plane (C, H, W, c), or (C, H, W) for one channel], alpha
    (C, H, W)); camera c's images are bit-identical to composite_tiles() of that camera alone."""
    C, n = means2d.shape[:2]
    dt = means2d.dtype
    if dt not in _SUFFIX:
        raise TypeError(f"tiled rasterizer: float32 or float64 tensors, got {dt}")
    if torch.is_grad_enabled() and any(t.requires_grad for t in (means2d, conics, opacities)):
        raise ValueError("composite_cameras renders without a gradient (use composite_tiles per camera)")
    nparts = [1 if torch.is_tensor(p) else len(p) for p in planes]
    parts = [q for p in planes for q in ((p,) if torch.is_tensor(p) else p)]
    isz, stride, fe = [], [], []
    for p in parts:
        per = p.dim() == 3
        if (per and p.shape[:2] != (C, n)) or (not per and (p.dim() not in (1, 2) or p.shape[0] != n)):
            raise ValueError(f"composite_cameras: a part must be ({C}, {n}, c), ({n}, c) or ({n},), got {tuple(p.shape)}")
        c = 1 if p.dim() == 1 else p.shape[-1]
        isz.append(c)
        stride.append(n * c if per else 0)
        fe.append(p.detach().to(dt).contiguous())
    split = [sum(isz[sum(nparts[:i]):sum(nparts[:i + 1])]) for i in range(len(nparts))]
    if background is not None and tuple(background.shape) != (C, split[0]):
        raise ValueError(f"composite_cameras: background must be ({C}, {split[0]}), got {tuple(background.shape)}")
    outs = [torch.empty((C, H, W, c) if c > 1 else (C, H, W), dtype=dt) for c in split]
    alpha = torch.empty(C, H, W, dtype=dt)
    bg = None if background is None else background.detach().to(dt).contiguous()
    m2, cn, op, z = (t.detach().to(dt).contiguous() for t in (means2d, conics, opacities, depths))
    rd, bx = radii.to(torch.int64).contiguous(), boxes.to(torch.int64).contiguous()
    getattr(build.load(), f"gs_forward_cameras_{_SUFFIX[dt]}")(
        C, n, _ptr(m2), _ptr(cn), _ptr(op), _ptr(z), _ptr(rd), _ptr(bx), W, H, max(1, torch.get_num_threads()),
        len(fe), (ctypes.c_int * len(fe))(*isz), _ptrs(fe), (ctypes.c_int64 * len(fe))(*stride), sum(isz),
        len(split), (ctypes.c_int * len(split))(*split), _ptrs(outs), _ptr(alpha), _nptr(bg))
    return outs, alpha
