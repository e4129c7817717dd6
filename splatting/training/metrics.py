"""Image metrics shared by the trainer, the benchmarks and the ground-truth checks: PSNR (torch or
numpy images in [0, 1]), SSIM (pytorch-msssim), mask IoU."""
import math

from pytorch_msssim import ssim as _ssim
import numpy as np


def psnr(a, b, mask=None, peak=1.0):
    """10 log10(peak^2 / MSE) of two images (torch tensors or numpy arrays), over `mask` if given.
    Identical images give 120 dB (MSE floored at 1e-12), not infinity."""
    if hasattr(a, "detach"):
        d = (a.detach().double() - b.detach().double()) ** 2
        d = d[mask] if mask is not None else d
        mse = float(d.mean())
    else:
        d = (np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2
        d = d[mask] if mask is not None else d
        mse = float(d.mean())
    return 10 * math.log10(peak * peak / max(mse, 1e-12 * peak * peak))


def ssim(a, b):
    """SSIM of two (H, W, C) torch images in [0, 1] (differentiable)."""
    return _ssim(a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None], data_range=1.0, size_average=True)


def mask_iou(a, b):
    """Intersection over union of two boolean masks (numpy); 0 when both are empty."""
    return float((a & b).sum() / max(1, (a | b).sum()))


def union_box(m1, m2, pad=0):
    """(x0, y0, x1, y1), end-exclusive: the bounding box of m1 | m2 ((H, W) bool numpy) grown by pad
    pixels and clipped to the image; the whole image when both masks are empty."""
    h, w = m1.shape
    ys, xs = np.nonzero(m1 | m2)
    if len(xs) == 0:
        return 0, 0, w, h
    return (max(0, int(xs.min()) - pad), max(0, int(ys.min()) - pad),
            min(w, int(xs.max()) + pad + 1), min(h, int(ys.max()) + pad + 1))


def box_psnr(a, b, m1, m2, pad=0):
    """PSNR of images a, b (H, W, C) inside union_box(m1, m2, pad), where the object is (a whole-image
    PSNR is dominated by the empty background); NaN when both masks are empty."""
    if not (m1 | m2).any():
        return float("nan")
    x0, y0, x1, y1 = union_box(m1, m2, pad)
    return psnr(a[y0:y1, x0:x1], b[y0:y1, x0:x1])
