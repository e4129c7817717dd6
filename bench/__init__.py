"""Benchmarks for `make bench`: each module exposes run(results: dict)."""
import argparse
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def bench_parser(name, doc):
    """`python -m bench.<name>`'s command line: the module docstring's first line as its
    description and --out, the bench output folder (default out/bench)."""
    ap = argparse.ArgumentParser(prog=f"python -m bench.{name}", description=doc.splitlines()[0])
    ap.add_argument("--out", default=os.path.join(ROOT, "out", "bench"))
    return ap


def worker_or_standalone(ap, worker):
    """A Blender comparison bench's command line, parsed: with --worker JOB this is the bpy side, which
    runs `worker(JOB)` and gets None back; a standalone run needs --out and gets the arguments."""
    a = ap.parse_args()
    if a.worker:
        worker(a.worker)
        return None
    if not a.out:
        ap.error("--out is required")
    return a


def save_png(image, path):
    """Write a PIL image (or an (H, W, 3) uint8 array) to path as PNG, atomically, its folder made."""
    import numpy as np
    from PIL import Image

    from cyclist_formats.atomic import atomic_path
    if isinstance(image, np.ndarray):
        image = Image.fromarray(image)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_path(path) as tmp:
        image.save(tmp, format="PNG")


def labelled_sheet(tiles, labels, cols, background):
    """Tiles (PIL images of one size) in rows of `cols`, each with its label lines (a string or a
    list) drawn at its top left: a contact sheet."""
    import math

    from PIL import Image, ImageDraw
    tw, th = tiles[0].size
    sheet = Image.new("RGB", (cols * tw, math.ceil(len(tiles) / cols) * th), background)
    draw = ImageDraw.Draw(sheet)
    for k, (t, lab) in enumerate(zip(tiles, labels)):
        x, y = (k % cols) * tw, (k // cols) * th
        sheet.paste(t, (x, y))
        for n, ln in enumerate([lab] if isinstance(lab, str) else lab):
            draw.text((x + 5, y + 4 + 11 * n), ln, fill=(0, 0, 0))
    return sheet


def main_with_errors(main, name):
    """Run a bench script's main(): a UserError ends it with one line on stderr and exit 2."""
    import sys

    from cyclist_formats.errors import UserError
    try:
        sys.exit(main())
    except UserError as e:
        print(f"{name}: error: {e}", file=sys.stderr)
        sys.exit(2)
