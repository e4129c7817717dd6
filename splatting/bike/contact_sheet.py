"""`contact-sheet` (the command: bike/command.py): one rendered view of every bike in a library, labelled, on one PNG."""
import glob
import json
import math
import os

from PIL import Image, ImageDraw, ImageFont

from cyclist_formats.atomic import atomic_path
from cyclist_formats.errors import UserError


def contact_sheet(bikes_dir, out, view=3, cols=6, tile=256):
    pattern = os.path.join(bikes_dir, "*", "views", "whole", "rgba", f"camera{view:04d}", "0000.png")
    files = sorted(glob.glob(pattern))
    if not files:
        raise UserError(f"no rendered views match {pattern}")
    rows = math.ceil(len(files) / cols)
    cols = min(cols, len(files))
    label_h = 22
    font = ImageFont.load_default(size=15)
    sheet = Image.new("RGB", (cols * tile, rows * (tile + label_h)), (236, 238, 240))
    draw = ImageDraw.Draw(sheet)
    for i, f in enumerate(files):
        bike_dir = f.split(os.sep + "views" + os.sep)[0]
        label = os.path.basename(bike_dir)
        meta = os.path.join(bike_dir, "meta.json")
        if os.path.isfile(meta):
            with open(meta) as fh:
                m = json.load(fh)
            label = f"{label} ({m.get('style', m.get('rideable', ''))})"
        img = Image.open(f).convert("RGBA")
        bbox = img.getbbox() or (0, 0, img.width, img.height)
        crop = img.crop(_square(bbox, img.size, pad=8))
        crop = crop.resize((tile, tile), Image.LANCZOS)
        x, y = (i % cols) * tile, (i // cols) * (tile + label_h)
        sheet.paste(crop, (x, y), crop)
        draw.text((x + 6, y + tile + 2), label, fill=(30, 30, 30), font=font)
    with atomic_path(out) as tmp:
        sheet.save(tmp, format="PNG")
    return len(files)


def _square(bbox, size, pad):
    x0, y0, x1, y1 = bbox
    cx, cy, half = (x0 + x1) / 2, (y0 + y1) / 2, max(x1 - x0, y1 - y0) / 2 + pad
    return (int(cx - half), int(cy - half), int(cx + half), int(cy + half))
