"""The box metrics every ground-truth check uses (splatting/training/metrics.py), against hand numbers."""
import math

import numpy as np

from splatting.training.metrics import box_psnr, union_box


def _masks():
    a = np.zeros((20, 30), bool)
    b = np.zeros((20, 30), bool)
    a[5:8, 10:12] = True   # rows 5-7, columns 10-11
    b[6:10, 4:7] = True    # rows 6-9, columns 4-6
    return a, b


def test_union_box_pads_and_clips():
    a, b = _masks()
    assert union_box(a, b) == (4, 5, 12, 10)
    assert union_box(a, b, pad=2) == (2, 3, 14, 12)
    assert union_box(a, b, pad=50) == (0, 0, 30, 20)  # clipped to the image
    empty = np.zeros_like(a)
    assert union_box(empty, empty, pad=3) == (0, 0, 30, 20)  # nothing there: the whole image


def test_box_psnr_counts_only_the_box():
    a, b = _masks()
    x = np.zeros((20, 30, 3))
    y = np.zeros((20, 30, 3))
    y[5:10, 4:12] = 0.1     # inside the box: MSE there 0.01 -> 20 dB
    y[15:, 20:] = 1.0       # outside the box: must not count
    assert math.isclose(box_psnr(x, y, a, b), 20.0, abs_tol=1e-9)
    # with a 1 px pad the box grows to rows 4-10, columns 3-12: 40 of 80+ pixels differ
    x0, y0, x1, y1 = union_box(a, b, pad=1)
    n_box, n_diff = (x1 - x0) * (y1 - y0), 5 * 8
    assert math.isclose(box_psnr(x, y, a, b, pad=1), -10 * math.log10(0.01 * n_diff / n_box), abs_tol=1e-9)
    empty = np.zeros_like(a)
    assert math.isnan(box_psnr(x, y, empty, empty))
