"""A strip of a generated sequence's frames with its tracks drawn: each cyclist's (amodal) box in
its track's colour, its track id, manoeuvre and intention, and the trail of its box's bottom
centre over the frames so far (where it was on screen; the camera moves, so a trail shows the
image motion a tracker sees).

    python -m splatting.dataset.sequences.strip --dataset DIR --out strip.png [--video 1] [--frames 4]

DIR is a dataset written with a `sequence` block (its annotations.json, COCO-video).
"""
import argparse
import json
import os
import sys

import numpy as np

from cyclist_formats.errors import UserError

COLOURS = [(230, 25, 75), (60, 180, 75), (255, 225, 25), (0, 130, 200), (245, 130, 48), (145, 30, 180),
           (70, 240, 240), (240, 50, 230)]


def load(dataset):
    path = os.path.join(dataset, "annotations.json")
    try:
        with open(path) as f:
            doc = json.load(f)
    except (OSError, ValueError) as e:
        raise UserError(f"cannot read {path}: {e}") from None
    if "videos" not in doc:
        raise UserError(f"{path} is not a sequence dataset (no 'videos'; set sequence.enabled)")
    return doc


def main_boxes(doc, video):
    """{frame_id: {track: (bbox_amodal, intention, manoeuvre)}} of the video's cyclists and parked bikes."""
    ims = {im["id"]: im for im in doc["images"] if im["video_id"] == video}
    out = {im["frame_id"]: {} for im in ims.values()}
    for a in doc["annotations"]:
        im = ims.get(a["image_id"])
        if im is None:
            continue
        if (a["parked"] and a["category_id"] in (1, 5, 6)) or (not a["parked"] and a["category_id"] in (3, 4)):
            out[im["frame_id"]][a["track_id"]] = (a["bbox_amodal"], a["intention"], a["manoeuvre"])
    return out, {im["frame_id"]: im for im in ims.values()}


def render_strip(dataset, video=1, n_frames=4, cols=2):
    from PIL import Image, ImageDraw, ImageFont
    doc = load(dataset)
    boxes, images = main_boxes(doc, video)
    if not images:
        raise UserError(f"{dataset}: no video {video}")
    order = sorted(images)
    picks = [order[int(round(i))] for i in np.linspace(0, len(order) - 1, min(n_frames, len(order)))]
    font = ImageFont.load_default(size=14)
    tiles = []
    for f in picks:
        im = Image.open(os.path.join(dataset, "images", images[f]["file_name"])).convert("RGB")
        d = ImageDraw.Draw(im)
        for tid in sorted(boxes[f]):
            col = COLOURS[tid % len(COLOURS)]
            trail = [boxes[g][tid][0] for g in order if g <= f and tid in boxes[g]]
            pts = [(x + w / 2, y + h) for x, y, w, h in trail]
            if len(pts) > 1:
                d.line(pts, fill=col, width=2)
            x, y, w, h = boxes[f][tid][0]
            d.rectangle([x, y, x + w, y + h], outline=col, width=2)
            _, inten, man = boxes[f][tid]
            d.text((x, max(0, y - 32)), f"#{tid % 1000} {man}\n{inten}", fill=col, font=font)
        t = images[f]["sequence"]["time_s"]
        d.text((8, 6), f"frame {f}  t = {t:.1f} s", fill=(255, 255, 255), font=font)
        tiles.append(np.asarray(im))
    h, w = tiles[0].shape[:2]
    rows = (len(tiles) + cols - 1) // cols
    sheet = np.zeros((rows * h, cols * w, 3), np.uint8)
    for i, t in enumerate(tiles):
        sheet[(i // cols) * h:(i // cols + 1) * h, (i % cols) * w:(i % cols + 1) * w] = t
    return sheet


def main(argv=None):
    ap = argparse.ArgumentParser(prog="python -m splatting.dataset.sequences.strip", description=__doc__.splitlines()[0])
    ap.add_argument("--dataset", required=True, help="a sequence dataset folder (annotations.json with videos)")
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--video", type=int, default=1)
    ap.add_argument("--frames", type=int, default=4)
    args = ap.parse_args(argv)
    try:
        if args.frames < 1:
            raise UserError("--frames must be >= 1")
        sheet = render_strip(args.dataset, args.video, args.frames)
        from PIL import Image
        from cyclist_formats.atomic import atomic_path
        os.makedirs(os.path.dirname(os.path.abspath(args.out)), exist_ok=True)
        with atomic_path(args.out) as tmp:
            Image.fromarray(sheet).save(tmp, format="PNG", optimize=True)
    except UserError as e:
        sys.stderr.write(f"strip: error: {e}\n")
        return 2
    print(f"strip: {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
