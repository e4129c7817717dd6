"""Files of a sequence dataset; every per-frame file atomic, every per-sequence file assembled from
the frames' shards once all are done (so a killed and resumed run gives the same bytes).

DIR/images/SEQ/FFFFFF.png, DIR/shards/SEQ/FFFFFF.json (the frame's image record, annotations and
tracking rows; written last: it marks the frame done), DIR/annotations.json (COCO-video);
`kitti`: DIR/kitti_tracking/training/{image_02/SEQ/FFFFFF.png, label_02/SEQ.txt, calib/SEQ.txt} (in a KITTI
frame: its calib file byte for byte, and velodyne/SEQ/FFFFFF.bin, its scan with the cyclists in it);
`mot`: DIR/mot/SEQ/{img1/%06d.png (1-based), gt/gt.txt, seqinfo.ini}.  SEQ = %04d.
The arm signal per cyclist and frame, which neither text format has a column for, goes beside
them: kitti_tracking/training/signal_02/SEQ.txt and mot/SEQ/gt/signals.txt (writers.signal_text).
Images in the kitti and mot trees are hard links to DIR/images (copies where links fail).
"""
import json
import os

from cyclist_formats.atomic import atomic_path, write_json
from splatting.dataset import png
from splatting.dataset.kitti import calib_text, link_or_copy
from splatting.dataset.sequences import writers
from splatting.dataset.sequences.render import make_frame, sequence_of


def paths(out_dir, index, cfg):
    s, f = sequence_of(cfg, index)
    return (os.path.join(out_dir, "images", f"{s:04d}", f"{f:06d}.png"),
            os.path.join(out_dir, "shards", f"{s:04d}", f"{f:06d}.json"))


def write_frame(cfg, index, out_dir, assets):
    rgb, image, anns, rows = make_frame(cfg, index, assets)
    img, shard = paths(out_dir, index, cfg)
    os.makedirs(os.path.dirname(img), exist_ok=True)
    with atomic_path(img) as tmp:
        png.write(tmp, rgb, cfg.png_compress_level)
    calib = {k: [float(x) for x in v.ravel()] for k, v in rows["calib"].items()}
    doc = {"image": image, "annotations": anns, "kitti": rows["kitti"], "mot": rows["mot"], "calib": calib,
           "signal": rows["signal"]}
    if "calib_text" in rows:  # a KITTI frame's own calib file, copied byte for byte at assembly
        doc["calib_text"] = rows["calib_text"]
    if rows.get("scan") is not None:  # its scan with the cyclists ray-cast in (KITTI tracking's velodyne/SEQ/)
        s, f = sequence_of(cfg, index)
        vel = os.path.join(out_dir, "kitti_tracking", "training", "velodyne", f"{s:04d}", f"{f:06d}.bin")
        os.makedirs(os.path.dirname(vel), exist_ok=True)
        with atomic_path(vel) as tmp:
            rows["scan"].astype("<f4").tofile(tmp)
    os.makedirs(os.path.dirname(shard), exist_ok=True)
    write_json(shard, doc, indent=None)
    return index


def frame_done(out_dir, index, cfg):
    return all(os.path.isfile(p) for p in paths(out_dir, index, cfg))


def total(cfg):
    return int(cfg.count) * int(cfg.sequence.length)


def _text(path, text):
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with atomic_path(path) as tmp:
        with open(tmp, "w") as f:
            f.write(text)


def assemble(out_dir, cfg, info, cats):
    """Every sequence's text files and the COCO-video annotations.json (atomic); returns its path."""
    n, fps = int(cfg.sequence.length), float(cfg.sequence.fps)
    fm = cfg.labels.formats
    images, anns, videos = [], [], []
    for s in range(int(cfg.count)):
        kit, mot, sig = [], [], []
        for f in range(n):
            img, shard = paths(out_dir, s * n + f, cfg)
            with open(shard) as fh:
                doc = json.load(fh)
            im = doc["image"]
            images.append((im, s + 1, f))
            for a in doc["annotations"]:
                anns.append(dict(a, id=len(anns) + 1, image_id=im["id"]))
            kit.append((f, doc["kitti"]))
            mot.append((f, doc["mot"]))
            sig.append((f, doc.get("signal", [])))
            if "kitti" in fm:
                link_or_copy(img, os.path.join(out_dir, "kitti_tracking", "training", "image_02", f"{s:04d}", f"{f:06d}.png"))
            if "mot" in fm:
                link_or_copy(img, os.path.join(out_dir, "mot", f"{s:04d}", "img1", f"{f + 1:06d}.png"))
            if f == 0:
                calib, W, H = doc.get("calib_text") or calib_text(doc["calib"]), im["width"], im["height"]
        videos.append({"id": s + 1, "name": f"{s:04d}", "width": W, "height": H, "length": n, "fps": fps})
        if "kitti" in fm:
            base = os.path.join(out_dir, "kitti_tracking", "training")
            _text(os.path.join(base, "label_02", f"{s:04d}.txt"), writers.kitti_tracking_text(kit))
            _text(os.path.join(base, "calib", f"{s:04d}.txt"), calib)
            _text(os.path.join(base, "signal_02", f"{s:04d}.txt"), writers.signal_text(sig, " ", 0))
        if "mot" in fm:
            d = os.path.join(out_dir, "mot", f"{s:04d}")
            _text(os.path.join(d, "gt", "gt.txt"), writers.mot_gt_text(mot))
            _text(os.path.join(d, "seqinfo.ini"), writers.seqinfo_text(f"{s:04d}", fps, n, W, H))
            _text(os.path.join(d, "gt", "signals.txt"), writers.signal_text(sig, ",", 1))
    imgs, tracks = writers.coco_video(images, anns, videos)
    doc = {"info": info, "licenses": [], "videos": videos, "images": imgs, "annotations": anns, "tracks": tracks,
           "categories": cats}
    path = os.path.join(out_dir, "annotations.json")
    with atomic_path(path) as tmp:
        with open(tmp, "w") as fh:
            json.dump(doc, fh, separators=(",", ":"))
    return path
