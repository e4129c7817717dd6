"""The rasterizer's constants and the eps2d (screen-space low-pass) rules every back end shares."""
import math

import torch

ALPHA_MIN = 1.0 / 255.0
# the screen-space low-pass (px^2) rasterize adds by default, and the filter of every trained model
# that records none (parts, fine-tuned bikes and avatars made before the filter was recorded)
EPS2D = 0.3
ALPHA_MAX = 0.99
T_MIN = 1e-4
CHUNK_PAIRS = 1 << 16  # candidate pairs per front-to-back chunk in intersect() (2^15..2^16 measured best)


def check_eps2d(eps2d, n, who="rasterize"):
    """eps2d as the rasterizer takes it: a finite number >= 0 for every Gaussian (returned as a
    float), or a (n,) floating tensor of them, one per Gaussian (returned detached: a model's filter
    is a constant, not a parameter).  Anything else is a ValueError naming who asked."""
    if torch.is_tensor(eps2d):
        if tuple(eps2d.shape) != (n,) or not eps2d.is_floating_point():
            raise ValueError(f"{who}: eps2d must be a number or a ({n},) floating tensor (one per Gaussian), "
                             f"got a {tuple(eps2d.shape)} {eps2d.dtype} tensor")
        e = eps2d.detach()
        if not bool(torch.isfinite(e).all()) or bool((e < 0).any()):
            bad = e[~(torch.isfinite(e) & (e >= 0))][0]
            raise ValueError(f"{who}: eps2d must be finite and >= 0 for every Gaussian, got {float(bad)}")
        return e
    if isinstance(eps2d, bool) or not isinstance(eps2d, (int, float)):
        raise ValueError(f"{who}: eps2d must be a number or a ({n},) floating tensor, got {type(eps2d).__name__}")
    if not math.isfinite(eps2d) or eps2d < 0:
        raise ValueError(f"{who}: eps2d must be finite and >= 0, got {eps2d}")
    return float(eps2d)


def eps2d_where(mask, a, b):
    """The eps2d of a scene of two kinds of Gaussians: a where mask (N,) bool, b elsewhere (a bike's
    filter and its rider's).  One number when they agree or one kind is absent: rasterize's scalar
    path, the renders of before bit for bit."""
    a, b = float(a), float(b)
    if a == b or not bool(mask.any()):
        return b
    if bool(mask.all()):
        return a
    return torch.where(mask, torch.tensor(a, dtype=torch.float64), torch.tensor(b, dtype=torch.float64))


def eps2d_cat(parts):
    """[(count, eps2d number or (count,) tensor), ...] in the scene's order -> the eps2d of their
    concatenation: one number when all are the same number (the scalar path), else a (N,) tensor."""
    nums = {float(e) for _, e in parts if not torch.is_tensor(e)}
    if all(not torch.is_tensor(e) for _, e in parts) and len(nums) <= 1:
        return nums.pop() if nums else EPS2D
    return torch.cat([e.detach().to(torch.float64) if torch.is_tensor(e) else torch.full((n,), float(e), dtype=torch.float64)
                      for n, e in parts])
