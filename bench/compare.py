"""Image comparisons shared by the ground-truth benchmarks (bike_gt, rider): float images in [0, 1]."""
import numpy as np

from splatting.training.metrics import mask_iou, psnr, union_box  # noqa: F401  (one metrics module for bench and trainer)

# What a Gaussian render is scored against: Blender's Cycles run to convergence (512 samples,
# adaptive threshold 0.005, no denoising; issue 14's reference). A 16-sample denoised render is
# itself only 35.4 dB / IoU 0.979 from it on the city bike (bench/blender_compare, 2026-11-26):
# its noise and the denoiser's edges would be charged to the Gaussians.
REFERENCE_SAMPLES = 512
# Cycles' adaptive sampling stops a pixel once its noise estimate is below this: flat, converged
# pixels cost far fewer than 512 samples (0.005 ~ 46 dB of per-pixel noise, far below the 28-36 dB
# differences being measured); 0 turns it off (every pixel 512 samples)
REFERENCE_ADAPTIVE = 0.005
REFERENCE = {"samples": REFERENCE_SAMPLES, "adaptive_threshold": REFERENCE_ADAPTIVE, "denoise": "NONE"}


def renders_for(gt_dir, key, prefix="gt_"):
    """gt_dir holding only renders made for `key` (a JSON-able dict: poses, cameras, lights, render
    settings, the inputs' hashes and the code version: bench/provenance.py): when gt_dir/key.json records
    another key, its files starting with `prefix` (a string or a tuple of them) are deleted, so that a
    worker skipping existing files renders them again. Returns gt_dir."""
    import json
    import os

    from cyclist_formats.atomic import write_json

    os.makedirs(gt_dir, exist_ok=True)
    path = os.path.join(gt_dir, "key.json")
    try:
        with open(path) as f:
            same = json.load(f) == json.loads(json.dumps(key))
    except (OSError, ValueError):
        same = False
    if not same:
        for f in os.listdir(gt_dir):
            if f.startswith(prefix):
                os.remove(os.path.join(gt_dir, f))
        write_json(path, key)
    return gt_dir


def load_rgba(path):
    """A Blender RGBA render -> (premultiplied RGB (H, W, 3) float64 in [0, 1], mask alpha > 0.5)."""
    from PIL import Image

    im = np.asarray(Image.open(path).convert("RGBA")).astype(np.float64) / 255
    return im[..., :3] * im[..., 3:4], im[..., 3] > 0.5


def score_png(gt_png, rgb, alpha, pad=8):
    """Blender RGBA file vs a render (rgb premultiplied (H, W, 3), alpha (H, W), numpy) ->
    (IoU, box PSNR, gt premultiplied rgb, box); the box is union_box(pad), the whole image when
    both masks are empty."""
    gt_rgb, m_gt = load_rgba(gt_png)
    m = alpha > 0.5
    x0, y0, x1, y1 = box = union_box(m, m_gt, pad)
    return mask_iou(m, m_gt), psnr(rgb[y0:y1, x0:x1], gt_rgb[y0:y1, x0:x1]), gt_rgb, box


def side_by_side(gt, pred, path, box=None, zoom=1):
    """PNG strip: reference | prediction | 4x |difference|, optionally cropped to box and zoomed."""
    from PIL import Image

    if box is not None:
        x0, y0, x1, y1 = box
        gt, pred = gt[y0:y1, x0:x1], pred[y0:y1, x0:x1]
    diff = np.abs(gt - pred).mean(-1, keepdims=True).repeat(3, -1) * 4
    strip = np.concatenate([gt, pred, np.clip(diff, 0, 1)], 1)
    im = Image.fromarray((strip * 255).round().astype(np.uint8))
    if zoom != 1:
        im = im.resize((im.width * zoom, im.height * zoom), Image.NEAREST)
    im.save(path)


def write_table(out_dir, name, lines):
    """A markdown table (list of lines) to out_dir/name, echoed to stdout for the bench log."""
    import os
    with open(os.path.join(out_dir, name), "w") as f:
        f.write("\n".join(lines) + "\n")
    print("\n".join(lines))
