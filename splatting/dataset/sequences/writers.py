"""Tracking label formats of a sequence: the text of KITTI tracking, MOTChallenge and COCO-video.

Pure functions of per-frame rows (known-answer tests in tests/test_sequences.py), called when a
sequence's frames are all done; output.py writes them atomically.

- KITTI tracking (devkit readme_tracking.txt): `label_02/SEQ.txt`, one object per line,
  17 columns: frame track_id type truncated occluded alpha x1 y1 x2 y2 h w l x y z rotation_y.
  Frames are 0-based, truncated is an INTEGER level there (0 not, 1 partly, 2 largely truncated;
  the object benchmark's float share is mapped with TRUNCATION_LEVELS), occluded 0..2 as in
  kitti.py.  `calib/SEQ.txt` is one calib for the sequence (the ego moves without turning, so P2
  and the rectification stay: the kitti.py calib of frame 0).
- MOTChallenge (MOT16/17 ground truth): `SEQ/gt/gt.txt` lines
  frame,id,bb_left,bb_top,bb_width,bb_height,conf,class,visibility with frames 1-based, conf 1
  (the entry counts), class 1 for the tracked target (a cyclist: rider + vehicle; MOT's
  evaluators score class 1 only) and 4 (MOT's bicycle) for a riderless bike, the amodal box
  (MOT boxes cover occluded parts) clipped to the image, visibility = visible / amodal pixels;
  `SEQ/seqinfo.ini` and the images as `SEQ/img1/%06d.png` (imExt .png).
- COCO-video (TAO / OVIS / mmtracking CocoVID): `videos` [{id, name, width, height, length}],
  each image `video_id` and `frame_id` (0-based; `frame_index` too, TAO's name), each annotation
  `video_id`, `frame_id`, `track_id` (stable across the sequence, unique in the set, shared by an
  instance's bicycle, person and cyclist annotations) and `instance_id` (one per track and category:
  track_id * 10 + category_id, mmtracking's name), and `tracks` [{id: instance_id, track_id, video_id, category_id}].
"""
TRUNCATION_LEVELS = (0.05, 0.5)  # share outside the image below the first: 0, below the second: 1, else 2
MOT_CLASS = {"cyclist": 1, "parked": 4}
# a KITTI frame's own objects in MOT (sequences in KITTI frames): their MOT17 classes as TrackEval names
# them (1 pedestrian = the target class, here cyclists; 3 car; 7 static person and 8 distractor are
# distractors: a tracker's box on them is not counted against it); any other type 8
KITTI_TYPES_MOT = {"Cyclist": 1, "Car": 3, "Van": 3, "Truck": 3, "Tram": 3, "Pedestrian": 7, "Person_sitting": 7,
                   "Misc": 8}


def truncation_level(share):
    """The integer level of a truncated share; a negative share (KITTI's DontCare rows: -1) stays -1."""
    if share < 0:
        return -1
    return 0 if share < TRUNCATION_LEVELS[0] else 1 if share < TRUNCATION_LEVELS[1] else 2


def kitti_tracking_line(frame, track_id, o):
    """One label_02 line of an object dict (kitti.py's fields)."""
    return (f"{frame} {track_id} {o['type']} {truncation_level(o['truncated'])} {int(o['occluded'])} {o['alpha']:.2f} "
            f"{o['x1']:.2f} {o['y1']:.2f} {o['x2']:.2f} {o['y2']:.2f} "
            f"{o['h']:.2f} {o['w']:.2f} {o['l']:.2f} {o['x']:.2f} {o['y']:.2f} {o['z']:.2f} {o['rotation_y']:.2f}\n")


def kitti_tracking_text(frames):
    """frames: [(frame index, [(track_id, object dict)])] in frame order -> label_02/SEQ.txt."""
    return "".join(kitti_tracking_line(f, tid, o) for f, objs in frames for tid, o in objs)


def mot_line(frame, track_id, row):
    """row: {"box": [x, y, w, h], "kind": cyclist|parked, "visibility"} (or with its own "class": a
    KITTI frame's objects, visibility -1 = unknown); frame 0-based here."""
    x, y, w, h = row["box"]
    cls = row["class"] if "class" in row else MOT_CLASS[row["kind"]]
    return f"{frame + 1},{track_id},{x:.2f},{y:.2f},{w:.2f},{h:.2f},1,{cls},{row['visibility']:.4f}\n"


def mot_gt_text(frames):
    """frames: [(frame index, [(track_id, row)])] -> gt.txt, sorted by frame then id (as MOT's files)."""
    return "".join(mot_line(f, tid, r) for f, rows in frames for tid, r in sorted(rows, key=lambda x: x[0]))


def signal_text(frames, sep, first_frame):
    """The arm-signal side file of a sequence: one line `frame<sep>track_id<sep>signal` per cyclist
    and frame (riderless bikes have none), frames numbered from first_frame (KITTI 0, MOT 1) as the
    format's labels are, so a reader joins them on (frame, track_id).  frames: [(frame, [[track, signal]])]."""
    return "".join(f"{f + first_frame}{sep}{tid}{sep}{sig}\n" for f, rows in frames for tid, sig in sorted(rows))


def seqinfo_text(name, fps, length, width, height, ext=".png"):
    return (f"[Sequence]\nname={name}\nimDir=img1\nframeRate={fps:g}\nseqLength={length}\n"
            f"imWidth={width}\nimHeight={height}\nimExt={ext}\n")


def coco_video(images, annotations, videos):
    """Add the COCO-video fields: images [(image dict, video_id, frame_id)], annotations already
    carrying video_id and track_id -> (images, tracks) with the tracks listed once each."""
    out = []
    for im, vid, fid in images:
        out.append(dict(im, video_id=vid, frame_id=fid, frame_index=fid))
    tracks = {}  # one per (instance, category): a cyclist's bike, person and cyclist annotations share its track_id
    for a in annotations:
        tracks.setdefault(a["instance_id"], {"id": a["instance_id"], "track_id": a["track_id"], "video_id": a["video_id"],
                                             "category_id": a["category_id"]})
    return out, [tracks[k] for k in sorted(tracks)]
