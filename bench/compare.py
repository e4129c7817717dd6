"""Image comparisons shared by the ground-truth benchmarks (bike_gt, rider): float images in [0, 1]."""
import numpy as np

from splatting.training.metrics import mask_iou, psnr, union_box  # noqa: F401  (one metrics module for bench and trainer)


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
