"""Fused per-Gaussian preprocessing for the tiled back end (csrc/project.cpp): the EWA projection
of splatting/raster/sparse.py's project() and the SH colour of splatting/gaussians/sh.py's eval_sh() in one
OpenMP pass forward and one backward, instead of ~60 small torch autograd ops.

preprocess(means, quats, scales, sh, camera, sh_degree, near, eps2d) -> means2d (N,2),
conics (N,3), depths (N,), colors (N,3), radii (N,) long, boxes (N,4) long, visible (N,) bool
(radii > 0); differentiable in means, quats, scales and sh. eps2d: a number, or a (N,) tensor (one
low-pass per Gaussian, handed to the C++ as a pointer; a number goes with the camera, so the
scalar path is unchanged). Culled Gaussians (radius 0) get no
gradient (they are never drawn). Gradients of outputs nobody used reach the C++ as null pointers
(set_materialize_grads(False)), not as zero tensors: each torch op between the C calls is a
serial step, and at 2 threads under OMP_WAIT_POLICY=PASSIVE a parallel one also wakes the other
thread (docs/rasterizer.md).
"""
import torch

from . import build
from .constants import EPS2D, check_eps2d

_SUFFIX = {torch.float32: "f32", torch.float64: "f64"}


def _ptr(t):
    return t.data_ptr()


def _nptr(t):
    return None if t is None else t.data_ptr()


def _camera_args(camera, near, eps2d):  # eps2d: the number (0 when per Gaussian: unused)
    R = camera.R.detach().to("cpu", torch.float64).contiguous()
    T = camera.T.detach().to("cpu", torch.float64).contiguous()
    (fx, _, cx), (_, fy, cy) = camera.K.detach().to("cpu", torch.float64).tolist()[:2]
    intr = torch.tensor([fx, fy, cx, cy, near, eps2d], dtype=torch.float64)
    return R, T, intr


class _Preprocess(torch.autograd.Function):
    @staticmethod
    def forward(ctx, means, quats, scales, sh, camera, nb, near, eps2d, eps):
        lib = build.load()
        dt = means.dtype
        sfx = _SUFFIX[dt]
        nt = max(1, torch.get_num_threads())
        n = means.shape[0]
        m, q, s, f = (t.detach().to(dt).contiguous() for t in (means, quats, scales, sh))
        R, T, intr = _camera_args(camera, near, eps2d)
        eps = None if eps is None else eps.to(dt).contiguous()
        means2d, conics = torch.empty(n, 2, dtype=dt), torch.empty(n, 3, dtype=dt)
        depths, colors = torch.empty(n, dtype=dt), torch.empty(n, 3, dtype=dt)
        radii, boxes = torch.empty(n, dtype=torch.int64), torch.empty(n, 4, dtype=torch.int64)
        visible = torch.empty(n, dtype=torch.bool)
        getattr(lib, f"gs_preprocess_fwd_{sfx}")(n, _ptr(R), _ptr(T), _ptr(intr), camera.width, camera.height,
                                                 _ptr(m), _ptr(q), _ptr(s), _ptr(f), _nptr(eps), f.shape[1], nb,
                                                 nt, _ptr(means2d), _ptr(conics), _ptr(depths), _ptr(colors),
                                                 _ptr(radii), _ptr(boxes), _ptr(visible))
        ctx.mark_non_differentiable(radii, boxes, visible)
        ctx.set_materialize_grads(False)
        ctx.save_for_backward(m, q, s, f, radii)
        ctx.cam = (R, T, intr, camera.width, camera.height, nb, eps)
        ctx.dtypes = (means.dtype, quats.dtype, scales.dtype, sh.dtype)
        return means2d, conics, depths, colors, radii, boxes, visible

    @staticmethod
    def backward(ctx, g_m2, g_cn, g_z, g_col, _r, _b, _v):
        m, q, s, f, radii = ctx.saved_tensors
        R, T, intr, W, H, nb, eps = ctx.cam
        dt = m.dtype
        n = m.shape[0]
        g = [None if t is None else t.to(dt).contiguous() for t in (g_m2, g_cn, g_z, g_col)]
        gm, gq, gs, gf = torch.empty_like(m), torch.empty_like(q), torch.empty_like(s), torch.empty_like(f)
        getattr(build.load(), f"gs_preprocess_bwd_{_SUFFIX[dt]}")(
            n, _ptr(R), _ptr(T), _ptr(intr), W, H, _ptr(m), _ptr(q), _ptr(s), _ptr(f), _nptr(eps), f.shape[1], nb,
            max(1, torch.get_num_threads()), _ptr(radii), *map(_nptr, g), _ptr(gm), _ptr(gq), _ptr(gs), _ptr(gf))
        dm, dq, ds, df = ctx.dtypes
        return gm.to(dm), gq.to(dq), gs.to(ds), gf.to(df), None, None, None, None, None


def _checked(means, quats, scales, sh, sh_degree, eps2d):
    """The inputs' checks shared by preprocess and preprocess_cameras: returns the number of SH
    bases, eps2d (a float or a per-Gaussian tensor) and whether it is per-Gaussian."""
    if any(t.device.type != "cpu" for t in (means, quats, scales, sh)):
        raise ValueError("the tiled rasterizer runs on CPU tensors; use backend='torch' for "
                         f"{means.device.type} tensors")
    if means.dtype not in _SUFFIX:
        raise TypeError(f"tiled rasterizer: float32 or float64 tensors, got {means.dtype}")
    k = sh.shape[1]
    degree = int(round(k ** 0.5)) - 1 if sh_degree is None else int(sh_degree)
    nb = (degree + 1) ** 2
    if not 0 <= degree <= 3 or nb > k:
        raise ValueError(f"sh_degree {degree} needs {nb} SH coefficients (have {k}, degrees 0-3)")
    eps2d = check_eps2d(eps2d, means.shape[0], "preprocess")
    per = torch.is_tensor(eps2d)
    return nb, eps2d, per


def preprocess(means, quats, scales, sh, camera, sh_degree=None, near=0.01, eps2d=EPS2D):
    """See the module docstring. CPU tensors, float32 or float64 (means' dtype)."""
    nb, eps2d, per = _checked(means, quats, scales, sh, sh_degree, eps2d)
    return _Preprocess.apply(means, quats, scales, sh, camera, nb, float(near), 0.0 if per else eps2d,
                             eps2d if per else None)


def preprocess_cameras(means, quats, scales, sh, cameras, sh_degree=None, near=0.01, eps2d=EPS2D):
    """preprocess() for C cameras of one size in one C call (threads over blocks of 256 Gaussians;
    per block each Gaussian's camera-independent unit quaternion, rotation and covariance factor
    M = R_q S once, then its projection and SH colour for up to 8 cameras (4 in float64) at once,
    one a vector lane, each lane the one-camera code's operations in its order),
    forward only (no gradient: the several-camera render of rasterization()). Returns the same
    outputs with a leading camera axis: means2d (C,N,2), conics (C,N,3), depths (C,N), colors (C,N,3),
    radii (C,N), boxes (C,N,4), visible (C,N); camera c's are bit-identical to preprocess(..., cameras[c]).
    """
    if len({(c.width, c.height) for c in cameras}) != 1:
        raise ValueError("preprocess_cameras: cameras of one size")
    nb, eps2d, per = _checked(means, quats, scales, sh, sh_degree, eps2d)
    dt = means.dtype
    C, n = len(cameras), means.shape[0]
    args = [_camera_args(c, float(near), 0.0 if per else eps2d) for c in cameras]
    R, T, intr = (torch.stack([a[i] for a in args]).contiguous() for i in range(3))
    m, q, s, f = (t.detach().to(dt).contiguous() for t in (means, quats, scales, sh))
    eps = eps2d.to(dt).contiguous() if per else None
    means2d, conics = torch.empty(C, n, 2, dtype=dt), torch.empty(C, n, 3, dtype=dt)
    depths, colors = torch.empty(C, n, dtype=dt), torch.empty(C, n, 3, dtype=dt)
    radii, boxes = torch.empty(C, n, dtype=torch.int64), torch.empty(C, n, 4, dtype=torch.int64)
    visible = torch.empty(C, n, dtype=torch.bool)
    getattr(build.load(), f"gs_preprocess_fwd_cams_{_SUFFIX[dt]}")(
        C, n, _ptr(R), _ptr(T), _ptr(intr), cameras[0].width, cameras[0].height, _ptr(m), _ptr(q), _ptr(s), _ptr(f),
        _nptr(eps), f.shape[1], nb, max(1, torch.get_num_threads()), _ptr(means2d), _ptr(conics), _ptr(depths),
        _ptr(colors), _ptr(radii), _ptr(boxes), _ptr(visible))
    return means2d, conics, depths, colors, radii, boxes, visible
