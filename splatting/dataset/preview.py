"""A strip of COCO samples with their annotations drawn on (masks, boxes, keypoints): a check by eye."""
import json
import os

from PIL import Image, ImageDraw
from pycocotools import mask as mask_utils
import numpy as np

from cyclist_formats.atomic import atomic_path

COLOURS = {"bicycle": (40, 120, 255), "person": (255, 60, 60), "cyclist": (40, 200, 90),
           "motorcyclist": (200, 200, 40), "motorcycle": (40, 200, 200), "scooter": (200, 40, 200)}
KEY_NAMES = {"rider": "person"}  # category key -> colour name (names are configurable, keys are not)
COMBINED = ("cyclist", "motorcyclist")


def _name(c):
    return KEY_NAMES.get(c.get("key"), c.get("key")) if c.get("key") else c["name"]


def coco_preview(coco_dir, out_png, n=4, tile=256):
    with open(os.path.join(coco_dir, "annotations.json")) as f:
        ann = json.load(f)
    cats = {c["id"]: _name(c) for c in ann["categories"]}
    images = ann["images"][:n]
    widths = [max(1, round(tile * im["width"] / im["height"])) for im in images]  # keep the aspect
    strip = Image.new("RGB", (max(1, sum(widths)), tile), (255, 255, 255))
    x_at = 0
    for i, im in enumerate(images):
        img = Image.open(os.path.join(coco_dir, "images", im["file_name"])).convert("RGB")
        arr = np.asarray(img).astype(np.float32)
        anns = [a for a in ann["annotations"] if a["image_id"] == im["id"]]
        for a in anns:  # tint the instance masks (the cyclist union is drawn as its box only)
            name = cats[a["category_id"]]
            if name in COMBINED:
                continue
            m = mask_utils.decode(a["segmentation"]).astype(bool)
            arr[m] = 0.6 * arr[m] + 0.4 * np.array(COLOURS.get(name, (255, 255, 255)))
        img = Image.fromarray(arr.clip(0, 255).astype(np.uint8))
        d = ImageDraw.Draw(img)
        for a in anns:
            name = cats[a["category_id"]]
            x, y, w, h = a["bbox"]
            lw = max(1, round(2 * im["height"] / tile))  # about 2 px after the resize
            d.rectangle([x, y, x + w, y + h], outline=COLOURS.get(name, (255, 255, 255)), width=lw)
            kp = np.array(a.get("keypoints", []), dtype=float).reshape(-1, 3)
            for u, v, vis in kp:
                if vis > 0:
                    r = (3 if vis == 2 else 2) * max(1, round(im["height"] / tile))
                    d.ellipse([u - r, v - r, u + r, v + r], fill=(255, 255, 0) if vis == 2 else (120, 120, 120))
        strip.paste(img.resize((widths[i], tile)), (x_at, 0))
        x_at += widths[i]
    with atomic_path(out_png) as tmp:
        strip.save(tmp, format="PNG")
    return len(images)


def keypoint_figure(coco_dir, out_png, image_id=1, scale=2, names=("person", "bicycle")):
    """One image with the keypoints and skeletons of the given categories drawn and numbered (the
    label reference's picture of the 17 person points and the 11 bike points)."""
    with open(os.path.join(coco_dir, "annotations.json")) as f:
        ann = json.load(f)
    cats = {c["id"]: c for c in ann["categories"]}
    im = next(i for i in ann["images"] if i["id"] == image_id)
    img = Image.open(os.path.join(coco_dir, "images", im["file_name"])).convert("RGB")
    img = img.resize((img.width * scale, img.height * scale), Image.LANCZOS)
    d = ImageDraw.Draw(img)
    for a in ann["annotations"]:
        c = cats[a["category_id"]]
        if a["image_id"] != image_id or c["name"] not in names or not c["keypoints"]:
            continue
        kp = np.array(a["keypoints"], dtype=float).reshape(-1, 3)
        colour = COLOURS.get(_name(c), (255, 255, 255))
        for i, j in c["skeleton"]:
            if kp[i - 1, 2] > 0 and kp[j - 1, 2] > 0:
                d.line([tuple(kp[i - 1, :2] * scale), tuple(kp[j - 1, :2] * scale)], fill=colour, width=2)
        for k, (u, v, vis) in enumerate(kp):
            if vis > 0:
                u, v = u * scale, v * scale
                d.ellipse([u - 4, v - 4, u + 4, v + 4], fill=(255, 255, 0) if vis == 2 else (150, 150, 150),
                          outline=(0, 0, 0))
                d.text((u + 5, v - 6), str(k + 1), fill=colour)
    with atomic_path(out_png) as tmp:
        img.save(tmp, format="PNG")
    return out_png


def relit_preview(baked_dir, relit_dir, out_png, n=4, tile=192, margin=12):
    """The same samples of a baked and a relit set (same config and seed; the light has its own
    random stream, so poses and cameras agree), cropped to the instances: baked on top, relit
    below, each relit tile captioned with its sun (elevation / azimuth, degrees)."""
    docs = []
    for d in (baked_dir, relit_dir):
        with open(os.path.join(d, "annotations.json")) as f:
            docs.append(json.load(f))
    images = docs[1]["images"][:n]
    sheet = Image.new("RGB", (max(1, tile * len(images)), 2 * tile + 16), (255, 255, 255))
    draw = ImageDraw.Draw(sheet)
    for i, im in enumerate(images):
        boxes = [a["bbox"] for a in docs[1]["annotations"] if a["image_id"] == im["id"]] or [[0, 0, im["width"], im["height"]]]
        x0, y0 = min(b[0] for b in boxes), min(b[1] for b in boxes)
        x1, y1 = max(b[0] + b[2] for b in boxes), max(b[1] + b[3] for b in boxes)
        s = max(x1 - x0, y1 - y0) / 2 + margin  # a square around the instances
        cx, cy = (x0 + x1) / 2, (y0 + y1) / 2
        crop = tuple(round(v) for v in (cx - s, cy - s, cx + s, cy + s))
        for row, d in enumerate((baked_dir, relit_dir)):
            img = Image.open(os.path.join(d, "images", im["file_name"])).convert("RGB")
            sheet.paste(img.crop(crop).resize((tile, tile), Image.LANCZOS), (i * tile, row * tile))
        sun = im.get("lighting") or {}
        if sun:
            draw.text((i * tile + 4, 2 * tile + 2), f"sun {sun['elevation_deg']:.0f} / {sun['azimuth_deg']:.0f} deg",
                      fill=(0, 0, 0))
    with atomic_path(out_png) as tmp:
        sheet.save(tmp, format="PNG")
    return len(images)
