"""Differentiable Gaussian rasterizer (standard 3DGS image formation), pure torch, CPU or CUDA.

One entry point, `rasterize(...)`; see docs/rasterizer.md. Shapes (N Gaussians, K SH coeffs):
  means (N,3) world, quats (N,4) wxyz (normalised here), scales (N,3) std devs,
  opacities (N,) in [0,1], sh (N,K,3); camera: splatting.raster.camera.Camera.
eps2d: the screen-space low-pass (px^2) added to every projected covariance: a number, or a (N,)
tensor (each Gaussian its own: a scene composing models trained with different filters).
Returns a dict: rgb (H,W,3), alpha (H,W), depth (H,W), means2d (N,2) pixel coords (retain_grad'ed
when it requires grad: the densifier reads its .grad), radii (N,) long, visible (N,) bool.
depth = sum_i w_i z_i with w_i = alpha_i T_i and z_i the camera z: NOT divided by alpha (the
background counts as depth 0); depth / alpha.clamp_min(eps) is the normalised expected depth.

Pipeline: project() (EWA, per Gaussian, autograd) -> compositing, by one of two back ends:
  "tiles" (default for CPU tensors): splatting/raster/cpu_tiles.py, the fused tiled OpenMP C++
    compositor (per-tile binning, depth order, front-to-back blending, its backward);
  "torch" (reference, CUDA tensors): intersect() (sparse (pixel, Gaussian) list, no grad) ->
    _Composite (segmented front-to-back scan with a hand-written backward).
"""
import math

import torch

from splatting.gaussians.sh import eval_sh
from splatting.rotations import quat_to_rotmat  # noqa: F401  (re-exported for the projection)

from splatting.raster.constants import (ALPHA_MAX, ALPHA_MIN, CHUNK_PAIRS, EPS2D, T_MIN,  # noqa: F401  (re-exported)
                                        check_eps2d, eps2d_cat, eps2d_where)


def project(means, quats, scales, camera, near=0.01, eps2d=EPS2D):
    """EWA projection (eps2d: a number or a (N,) tensor, check_eps2d). Returns means2d (N,2), conics (N,3) = (a,b,c) of the inverse 2D covariance,
    depths (N,) camera z, radii (N,) long (3 sigma of the largest eigenvalue, 0 = culled),
    boxes (N,4) long pixel ranges [u0, u1, v0, v1] inclusive (empty when u1 < u0)."""
    dt, dev = means.dtype, means.device
    eps2d = check_eps2d(eps2d, means.shape[0], "project")
    if torch.is_tensor(eps2d):
        eps2d = eps2d.to(dev, dt)
    R = camera.R.to(dev, dt)
    T = camera.T.to(dev, dt)
    fx, fy = float(camera.K[0, 0]), float(camera.K[1, 1])
    cx, cy = float(camera.K[0, 2]), float(camera.K[1, 2])
    W, H = camera.width, camera.height

    p = means @ R.T + T
    z = p[:, 2]
    valid = z > near
    zs = torch.where(valid, z, torch.ones_like(z))  # keep culled ones finite
    x, y = p[:, 0], p[:, 1]
    means2d = torch.stack([fx * x / zs + cx, fy * y / zs + cy], -1)

    # perspective Jacobian at the FOV-clamped point (INRIA: 1.3x the half-FOV; gsplat form for any cx)
    limx_pos, limx_neg = (W - cx) / fx + 0.3 * W / (2 * fx), cx / fx + 0.3 * W / (2 * fx)
    limy_pos, limy_neg = (H - cy) / fy + 0.3 * H / (2 * fy), cy / fy + 0.3 * H / (2 * fy)
    tx = torch.clamp(x / zs, -limx_neg, limx_pos) * zs
    ty = torch.clamp(y / zs, -limy_neg, limy_pos) * zs
    q = quats / quats.norm(dim=-1, keepdim=True)
    M = quat_to_rotmat(q) * scales[:, None, :]  # cov3d = M M^T
    # rows of R M via one (3N,3) x (3,3) matmul (batched 3x3 bmm is ~3x slower on CPU)
    RMt = (M.transpose(1, 2).reshape(-1, 3) @ R.T).reshape(-1, 3, 3)
    r0, r1, r2 = RMt[..., 0], RMt[..., 1], RMt[..., 2]
    # A = J R M with the perspective Jacobian J = [[fx/z, 0, -fx tx/z^2], [0, fy/z, -fy ty/z^2]]
    iz = 1.0 / zs
    A0 = (fx * iz)[:, None] * r0 - (fx * tx * iz * iz)[:, None] * r2
    A1 = (fy * iz)[:, None] * r1 - (fy * ty * iz * iz)[:, None] * r2
    a = (A0 * A0).sum(-1) + eps2d  # cov2d = A A^T + eps2d I
    b = (A0 * A1).sum(-1)
    c = (A1 * A1).sum(-1) + eps2d
    det = a * c - b * b
    valid = valid & (det > 0)
    det_s = torch.where(valid, det, torch.ones_like(det))
    conics = torch.stack([c / det_s, -b / det_s, a / det_s], -1)

    with torch.no_grad():
        mid = 0.5 * (a + c)
        lam = mid + torch.sqrt(torch.clamp_min(mid * mid - det, 0.1))
        r = torch.ceil(3.0 * torch.sqrt(lam))
        r = torch.where(valid, r, torch.zeros_like(r))
        # pixel u is touched when its centre u+0.5 lies within [mx - r, mx + r]
        m2 = means2d.detach().clamp(-1e7, 1e7)
        u0 = torch.ceil(m2[:, 0] - r - 0.5).clamp(0, W)
        u1 = torch.floor(m2[:, 0] + r - 0.5).clamp(-1, W - 1)
        v0 = torch.ceil(m2[:, 1] - r - 0.5).clamp(0, H)
        v1 = torch.floor(m2[:, 1] + r - 0.5).clamp(-1, H - 1)
        boxes = torch.stack([u0, u1, v0, v1], -1).long()
        onscreen = valid & (boxes[:, 1] >= boxes[:, 0]) & (boxes[:, 3] >= boxes[:, 2])
        radii = torch.where(onscreen, r, torch.zeros_like(r)).long()
    return means2d, conics, z, radii, boxes


def _ceil_i(x):
    return torch.ceil(x).long()


def _floor_i(x):
    return torch.floor(x).long()


def _expand(counts):
    """Segments of the given lengths laid end to end: the segment id of every element (int32) and
    each segment's start. (A cumsum of start markers: ~10x faster than repeat_interleave on CPU.)"""
    ends = torch.cumsum(counts, 0)
    n = int(ends[-1]) if len(ends) else 0
    marks = torch.zeros(n + 1, dtype=torch.int32, device=counts.device)
    marks.index_add_(0, ends, torch.ones_like(ends, dtype=torch.int32))
    return torch.cumsum(marks[:-1], 0, dtype=torch.int32), ends - counts


@torch.no_grad()
def intersect(means2d, conics, opacities, depths, boxes, radii, W, H, margin=1e-3, chunk_pairs=None):
    """Sparse list of the (pixel, Gaussian) pairs that contribute: alpha >= 1/255, inside the
    Gaussian's 3-sigma box, in front of the pixel's transmittance cut-off; grouped by pixel and
    front to back inside a pixel.

    Candidates are generated row by row from the ellipse sigma <= ln(255 o) (where alpha can reach
    1/255) rather than from the whole square box, which on bike-part scenes holds ~3x more pixels
    than survive the alpha test. They are processed front to back in chunks of ~chunk_pairs so that
    pixels already past the cut-off get no more pairs (at 100k Gaussians ~70% of candidates are
    behind it). Returns pix (P,) int32 flat pixel ids (sorted), gid (P,) int32, dx, dy (P,) pixel
    centre minus projected mean, alpha_raw (P,) = o exp(-sigma), unclamped."""
    dev, dt = means2d.device, means2d.dtype
    chunk_pairs = chunk_pairs or CHUNK_PAIRS
    vis = torch.nonzero(radii > 0).squeeze(1)
    vis = vis.index_select(0, torch.argsort(depths.index_select(0, vis), stable=True))
    sel = lambda t: t.index_select(0, vis)
    (mx, my), (A, B, C), op, bx = sel(means2d).unbind(-1), sel(conics).unbind(-1), sel(opacities), sel(boxes)
    tau = torch.log(255.0 * op.clamp_min(1e-30))  # alpha >= 1/255  <=>  sigma <= tau
    detc = (A * C - B * B).clamp_min(1e-30)
    ext_y = torch.sqrt((2.0 * tau * A / detc).clamp_min(0.0))  # vertical half-extent of that ellipse
    v0 = torch.maximum(bx[:, 2], _ceil_i(my - ext_y - 0.5 - margin))
    v1 = torch.minimum(bx[:, 3], _floor_i(my + ext_y - 0.5 + margin))
    nrow = (v1 - v0 + 1).clamp_min(0) * (tau > 0)
    # one item per (Gaussian, row): the span of u where sigma <= tau, clipped to the 3-sigma box
    k, kstart = _expand(nrow)
    g = lambda t: t.index_select(0, k)
    Ak, Bk, Ck, mxk = g(A), g(B), g(C), g(mx)
    row = g(v0) + torch.arange(len(k), device=dev) - g(kstart)
    dy = row.to(dt) + 0.5 - g(my)
    disc = (Bk * Bk - Ak * Ck) * dy * dy + 2.0 * Ak * g(tau)
    half = torch.sqrt(disc.clamp_min(0.0)) / Ak
    ctr = mxk - Bk * dy / Ak - 0.5
    u0 = torch.maximum(g(bx[:, 0]), _ceil_i(ctr - half - margin))
    u1 = torch.minimum(g(bx[:, 1]), _floor_i(ctr + half + margin))
    ncol = (u1 - u0 + 1).clamp_min(0) * (disc >= 0)
    # per-row constants: pixel id and dx of the span's first pixel; alpha = exp(-((a dx + b) dx + c))
    prow = (row * W + u0).int()
    x0 = u0.to(dt) + 0.5 - mxk
    ca, cb, cc = 0.5 * Ak, Bk * dy, 0.5 * Ck * dy * dy - torch.log(g(op))
    gid_r = g(vis).int()

    ends = torch.cumsum(ncol, 0)
    total = int(ends[-1]) if len(ends) else 0
    n_chunks = max(1, -(-total // chunk_pairs))
    cuts = torch.searchsorted(ends, torch.arange(1, n_chunks, device=dev) * (total // n_chunks)).tolist()
    bounds = [0] + cuts + [len(ncol)]
    log_tmin = math.log(T_MIN)
    # sum of log(1 - alpha) over the pairs generated so far, per pixel. Once it is below log(1e-4)
    # the pixel's cut-off lies among them, so later (deeper) chunks can skip the pixel. No sort is
    # needed for that; pairs past the cut-off inside a chunk are left for composite() to drop.
    logT = torch.zeros(H * W, dtype=torch.float64, device=dev)
    n_done = torch.zeros(H * W + 1, dtype=torch.int32, device=dev)  # prefix count of finished pixels
    parts = []
    for c in range(n_chunks):
        items = torch.arange(bounds[c], bounds[c + 1], device=dev)
        if c > 0:
            done = logT < log_tmin
            torch.cumsum(done, 0, dtype=torch.int32, out=n_done[1:])
            nc = ncol.index_select(0, items)
            # an empty span's start pixel can lie anywhere (the row missed the ellipse): use 0 there
            p0 = prow.index_select(0, items).long() * (nc > 0)
            items = items[(n_done.index_select(0, p0 + nc) - n_done.index_select(0, p0)) < nc]  # whole span done
        if len(items) == 0:
            continue
        j, jstart = _expand(ncol.index_select(0, items))  # one element per (Gaussian, pixel), depth order
        local = torch.arange(len(j), dtype=torch.int32, device=dev) - jstart.int().index_select(0, j)
        item = items.int().index_select(0, j)
        pix = prow.index_select(0, item) + local
        dx = x0.index_select(0, item) + local.to(dt)
        alpha = torch.exp(-((ca.index_select(0, item) * dx + cb.index_select(0, item)) * dx + cc.index_select(0, item)))
        ok = alpha >= ALPHA_MIN
        if c > 0:
            ok &= ~done.index_select(0, pix)
        if n_chunks > 1:
            logT.index_add_(0, pix, torch.log1p(-alpha.clamp_max(ALPHA_MAX) * ok).double())
        idx = torch.nonzero(ok).squeeze(1)
        parts.append((pix.index_select(0, idx), item.index_select(0, idx)))
    if not parts:
        z = torch.zeros(0, dtype=torch.int32, device=dev)
        return z, z, means2d.new_zeros(0), means2d.new_zeros(0), means2d.new_zeros(0)
    pix, item = (torch.cat(t) for t in zip(*parts))
    # depth order -> pixel-major; the stable sort keeps the depth order inside every pixel
    # (int32 keys sort ~2x faster than int64 on CPU)
    pix, perm = torch.sort(pix, stable=True)
    item = item.index_select(0, perm)
    # per-pair values again from the row items: cheaper than carrying them through the sort
    dx = x0.index_select(0, item) + (pix - prow.index_select(0, item)).to(dt)
    alpha = torch.exp(-((ca.index_select(0, item) * dx + cb.index_select(0, item)) * dx + cc.index_select(0, item)))
    return pix, gid_r.index_select(0, item), dx, dy.index_select(0, item), alpha


class _Composite(torch.autograd.Function):
    """Front-to-back compositing of the sorted pair list, with a hand-written backward (measured
    73 ms vs 176 ms for autograd through the same torch ops, 50k Gaussians, 1 thread).

    Per pixel: w_k = a_k T_k, T_k = prod_{j<k} (1 - a_j); out = sum_k w_k f_k + T_final bg_f for the
    channels f = (colour (any number Cc >= 3: rgb then extra features), 1, z); the background
    applies to the first three. T_k comes from an exclusive cumsum of log(1 - a) in float64
    (the running sum over all pixels must not swallow per-pixel differences)."""

    @staticmethod
    def forward(ctx, means2d, conics, opacities, colors, depths, background, pix, gid, dx, dy, alpha_raw, n_pix):
        dt = means2d.dtype
        ok = alpha_raw >= ALPHA_MIN
        alpha = torch.where(ok, alpha_raw.clamp_max(ALPHA_MAX), torch.zeros_like(alpha_raw))
        logm = torch.log1p(-alpha).double()  # float64 only where it matters: the running sum
        cs = torch.cumsum(logm, 0)
        cnt = torch.bincount(pix, minlength=n_pix)
        seg_start = torch.cumsum(cnt, 0) - cnt
        base = torch.nn.functional.pad(cs, (1, 0)).index_select(0, seg_start)  # sum before the pixel's segment
        logT_incl = cs - base.index_select(0, pix)
        # INRIA: the step that would take T below 1e-4 is not taken, nor any after it. Pairs past
        # the cut-off and those under 1/255 are dropped here: past ~50k Gaussians that is most of them.
        keep = torch.nonzero((logT_incl >= math.log(T_MIN)) & ok).squeeze(1)
        pix, gid, dx, dy, alpha_raw, alpha = (t.index_select(0, keep) for t in (pix, gid, dx, dy, alpha_raw, alpha))
        T = torch.exp(logT_incl.index_select(0, keep) - logm.index_select(0, keep)).to(dt)
        w = alpha * T
        cc = colors.shape[1]
        table = torch.cat([colors, torch.ones_like(depths)[:, None], depths[:, None]], 1)  # (N, cc + 2)
        F = table.index_select(0, gid)
        cnt = torch.bincount(pix, minlength=n_pix)
        out = torch.segment_reduce(F * w[:, None], "sum", lengths=cnt) if len(pix) else \
            means2d.new_zeros(n_pix, cc + 2)
        T_final = 1.0 - out[:, cc]
        if background is not None:
            out[:, :3] += T_final[:, None] * background
        ctx.save_for_backward(conics, opacities, background, pix, gid, dx, dy, alpha_raw, T, w, F, cnt, T_final)
        return out

    @staticmethod
    def backward(ctx, g_out):
        conics, opacities, background, pix, gid, dx, dy, alpha_raw, T, w, F, cnt, T_final = ctx.saved_tensors
        n = len(conics)
        g_out = g_out.contiguous()
        cc = g_out.shape[1] - 2
        g_pair = g_out.index_select(0, pix)  # (P, cc + 2): dL/d(colour, alpha, depth) at the pair's pixel
        v = (g_pair * F).sum(1)  # dL/dw_k
        # S_k = sum_{j>k} v_j w_j + T_final (g_rgb . bg): what lies behind k in its pixel
        cs = torch.cumsum((v * w).double(), 0)
        seg_total = torch.nn.functional.pad(cs, (1, 0)).index_select(0, torch.cumsum(cnt, 0))
        if background is not None:
            seg_total = seg_total + (T_final * (g_out[:, :3] * background).sum(1)).double()
            g_bg = (g_out[:, :3] * T_final[:, None]).sum(0)
        else:
            g_bg = None
        S = (seg_total.index_select(0, pix) - cs).to(w.dtype)
        alpha = alpha_raw.clamp_max(ALPHA_MAX)
        g_alpha = (T * v - S / (1.0 - alpha)) * (alpha_raw < ALPHA_MAX)
        q = g_alpha * alpha_raw  # = -dL/dsigma, since alpha_raw = o exp(-sigma)
        qdx, qdy = q * dx, q * dy
        acc = lambda x: x.new_zeros(n).index_add_(0, gid, x)
        s_q, s_x, s_y, s_xx, s_xy, s_yy = acc(q), acc(qdx), acc(qdy), acc(qdx * dx), acc(qdx * dy), acc(qdy * dy)
        A, B, C = conics.unbind(-1)
        g_means2d = torch.stack([A * s_x + B * s_y, B * s_x + C * s_y], 1)
        g_conics = torch.stack([-0.5 * s_xx, -s_xy, -0.5 * s_yy], 1)
        g_opac = s_q / opacities.clamp_min(1e-30)
        # 1-D index_add per channel: the 2-D one takes a slow path with int32 indices
        g_colors = torch.stack([acc(g_pair[:, c] * w) for c in range(cc)], 1)
        return (g_means2d, g_conics, g_opac, g_colors, acc(g_pair[:, cc + 1] * w), g_bg,
                None, None, None, None, None, None)


def composite(means2d, conics, opacities, colors, depths, background, pairs, H, W):
    """Returns colour (H,W,Cc) (Cc = colors.shape[1], usually 3), alpha (H,W), depth (H,W) for the
    pairs from intersect(). background, when given, is added under the first 3 channels."""
    pix, gid, dx, dy, alpha_raw = pairs
    if background is not None:
        background = background.to(means2d)
    cc = colors.shape[1]
    out = _Composite.apply(means2d, conics, opacities, colors, depths, background, pix, gid, dx, dy, alpha_raw, H * W)
    return out[:, :cc].reshape(H, W, cc), out[:, cc].reshape(H, W), out[:, cc + 1].reshape(H, W)


def rasterize(means, quats, scales, opacities, sh, camera, background=None, sh_degree=None,
              near=0.01, eps2d=EPS2D, features=None, antialiased=False, backend=None, groups=None, depth=True,
              shade=None):
    """Render N Gaussians into camera. See the module docstring for shapes.

    features: optional (N, F) extra channels composited like the colour (instance ids, albedo,
    normals...; background 0), returned as out["features"] (H, W, F); or a list of (N, F_i)
    parts, composited as their concatenation (the tiled back end reads the parts as they are:
    no (N, F) table is built per render).
    depth: False leaves the depth channel out (out has no "depth"): one channel less for the
    compositor to blend, for renders that do not use it (relit shading, splatting/relight/render.py).
    antialiased: mip-splatting's 2D filter with opacity compensation (gsplat's "antialiased"
    mode): opacity x sqrt(det S / det(S + eps2d I)), S the projected covariance before the eps2d
    low-pass, so a Gaussian smaller than a pixel keeps its true footprint instead of growing
    to a 0.3 px^2 blob at full opacity (thin spokes, far-away cyclists).  A (N,) bool tensor
    applies it to those Gaussians only (a scene mixing assets trained with and without it: each
    is drawn as it was trained).
    groups: optional (ids (N,) int in [-1, G), G): also out["group_alpha"] (G, H, W), the alpha of
    each group's Gaussians rendered alone (no occlusion by the other Gaussians: amodal masks), not
    differentiable; "tiles" computes them in the image's own pass, "torch" renders each group.
    shade: a splatting.raster.cpu_tiles.TileShade (tiled back end, float32, no grad, depth=False,
    no background; splatting/relight/render.py builds it): each tile is shaded as the compositor
    finishes it, out["rgb"] is the display colour shaded from the composited colour (the
    reflectance) and features, and out["features"] is there only when shade.features.
    backend: "tiles" (the fused OpenMP C++ compositor, splatting/raster/cpu_tiles.py; CPU tensors),
    "torch" (the pure-torch pair list below: the reference, and the path for CUDA tensors), or
    None: "tiles" for CPU tensors, "torch" otherwise. out["backend"] says which one ran."""
    H, W = camera.height, camera.width
    backend = resolve_backend(backend, means)
    eps2d = check_eps2d(eps2d, means.shape[0])
    if shade is not None and (backend != "tiles" or depth):
        raise ValueError("rasterize: shade needs the tiled back end and depth=False")
    if backend == "tiles":  # projection + SH fused in C++ (splatting/raster/cpu_project.py)
        from splatting.raster.cpu_project import preprocess

        means2d, conics, depths, colors, radii, boxes, visible = preprocess(means, quats, scales, sh, camera,
                                                                            sh_degree, near, eps2d)
    else:
        means2d, conics, depths, radii, boxes = project(means, quats, scales, camera, near, eps2d)
        centre = camera.centre.to(means.device, means.dtype)
        dirs = means - centre
        dirs = dirs / dirs.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        colors = eval_sh(sh, dirs, sh_degree)
        visible = radii > 0
    if means2d.requires_grad:
        means2d.retain_grad()
    opacities = antialias_opacities(opacities, conics, eps2d, antialiased, "rasterize")
    if features is not None and not torch.is_tensor(features):  # parts
        features = list(features)
        nf = sum(f.shape[1] for f in features)
        if backend == "torch" and features:
            features = torch.cat(features, 1)
    else:
        nf = 0 if features is None else features.shape[1]
    group_alpha = None
    want_depth = depth
    if backend == "tiles":
        rgb, alpha, depth, feats, group_alpha = _composite_tiles(means2d, conics, opacities, colors, features, depths,
                                                                 radii, boxes, background, H, W, groups, want_depth,
                                                                 shade)
    else:
        if nf:
            colors = torch.cat([colors, features.to(colors)], 1)
        pairs = intersect(means2d.detach(), conics.detach(), opacities.detach(), depths.detach(), boxes, radii, W, H)
        col, alpha, depth = composite(means2d, conics, opacities, colors, depths, background, pairs, H, W)
        rgb, feats = col[..., :3], col[..., 3:]
        if groups is not None:
            group_alpha = _group_alpha_torch(means2d, conics, opacities, depths, radii, boxes, groups, H, W)
    out = {"rgb": rgb, "alpha": alpha, "depth": depth, "means2d": means2d, "radii": radii,
           "visible": visible, "backend": backend}
    if not want_depth:
        del out["depth"]
    if nf and feats is not None:
        out["features"] = feats
    if groups is not None:
        out["group_alpha"] = group_alpha
    return out


@torch.no_grad()
def _group_alpha_torch(means2d, conics, opacities, depths, radii, boxes, groups, H, W):
    """(G, H, W): each group's Gaussians intersected and composited alone (the reference for the
    tiled back end's one-pass group alphas)."""
    ids, n = groups
    out = means2d.new_zeros(n, H, W)
    for q in range(n):
        i = torch.nonzero(ids == q).squeeze(1)
        if len(i):
            sel = [t.detach().index_select(0, i) for t in (means2d, conics, opacities, depths, boxes, radii)]
            pairs = intersect(*sel, W, H)
            _, out[q], _ = composite(sel[0], sel[1], sel[2], sel[0].new_zeros(len(i), 1), sel[3], None, pairs, H, W)
    return out


def antialias_opacities(opacities, conics, eps2d, antialiased, who="rasterize"):
    """opacities (N,) x the mip filter's compensation (aa_compensation) where antialiased says: a
    bool for all Gaussians, or a (N,) bool mask (each asset drawn as it was trained).  Shared by
    rasterize and the relight fit's fixed pair list (splatting/relight/render.py prepare), so both
    composite the same alphas.  eps2d: the number or (N,) tensor the conics were projected with."""
    if torch.is_tensor(eps2d):
        eps2d = eps2d.to(conics)
    if torch.is_tensor(antialiased):
        if antialiased.shape != opacities.shape:
            raise ValueError(f"{who}: antialiased mask {tuple(antialiased.shape)} for {tuple(opacities.shape)} "
                             "Gaussians")
        if not bool(antialiased.any()):
            return opacities
        comp = aa_compensation(conics, eps2d)
        return opacities * torch.where(antialiased.to(comp.device), comp, torch.ones_like(comp))
    return opacities * aa_compensation(conics, eps2d) if antialiased else opacities


def aa_compensation(conics, eps2d):
    """sqrt(det S / det(S + eps2d I)) from the conic (S + eps2d I)^-1 = [[A, B], [B, C]]:
    S + eps2d I = [[C, -B], [-B, A]] / d with d = AC - B^2, so det(S + eps2d I) = 1 / d and
    det S = (C/d - eps2d)(A/d - eps2d) - B^2/d^2. 0 where S is degenerate (culled anyway).
    eps2d: a number or a (N,) tensor (per Gaussian, as the conics were projected)."""
    A, B, C = conics.unbind(-1)
    d = A * C - B * B
    d = torch.where(d > 0, d, torch.ones_like(d))
    det_s = (C / d - eps2d) * (A / d - eps2d) - B * B / (d * d)
    return torch.sqrt(torch.clamp_min(det_s * d, 0.0))


# ---------------------------------------------------------------- back-end choice (tiled C++ / torch)

BACKENDS = ("tiles", "torch")


def resolve_backend(backend, means):
    """None -> "tiles" for CPU tensors, "torch" for others; anything else must be in BACKENDS."""
    if backend is None:
        return "tiles" if means.device.type == "cpu" else "torch"
    if backend not in BACKENDS:
        raise ValueError(f"rasterize: backend must be one of {BACKENDS} or None, got {backend!r}")
    return backend


def _composite_tiles(means2d, conics, opacities, colors, features, depths, radii, boxes, background, H, W,
                     groups=None, depth=True, shade=None):
    """The tiled C++ compositor with the torch path's outputs: rgb (H,W,3) over the background,
    alpha, depth (camera z composited as the last channel; None when not depth), features (H,W,F)
    or None, features a tensor or a list of parts (one plane). Colour,
    features and depth are handed over as separate planes; the compositor reads them in place,
    writes each as its own contiguous image (colour already over the background, alpha, the
    group alphas), and takes their gradients back the same way (no concatenation, no slicing, no
    torch op on a full image)."""
    from splatting.raster.cpu_tiles import composite_tiles

    fparts = [] if features is None else [features] if torch.is_tensor(features) else list(features)
    fparts = [f.to(colors) for f in fparts if f.shape[1] > 0]
    planes = [colors] + ([fparts[0] if len(fparts) == 1 else fparts] if fparts else []) + ([depths] if depth else [])
    res = composite_tiles(means2d, conics, opacities, planes, depths.detach(), radii, boxes, H, W,
                          *(() if groups is None else groups), background=background, shade=shade)
    rgb, alpha = res[0], res[len(planes)]
    feats = res[1] if fparts else None
    return rgb, alpha, res[len(planes) - 1] if depth else None, feats, None if groups is None else res[-1]


def render_gaussians(g, camera, **kw):
    """rasterize() for a splatting.gaussians.Gaussians (log scales, logit opacities)."""
    return rasterize(g.means, g.quats, g.scales, g.opacities, g.sh, camera, **kw)
