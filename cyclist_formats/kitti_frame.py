"""KITTI object folders (numpy only): frame ids, calib, label_2 rows, road planes and Velodyne scans.

Layout (KITTI object devkit readme; AVOD's planes): a folder with
- image_2/ID.png: the left colour camera, rectified;
- calib/ID.txt: `KEY: numbers` lines: P0..P3 (3x4 projections of the rectified cameras, 12 values),
  R0_rect (3x3 rectifying rotation, 9), Tr_velo_to_cam (3x4 Velodyne -> unrectified camera 0, 12),
  Tr_imu_to_velo (3x4, 12; optional here: nothing uses it).  The tracking benchmark's spellings
  R_rect, Tr_velo_cam and Tr_imu_velo are read as the same keys.
- label_2/ID.txt: one object per line, 15 fields `type truncated occluded alpha x1 y1 x2 y2 h w l x y z
  rotation_y` (16 with a detector's score); 3D boxes in the rectified camera-0 frame (x right, y down,
  z forward), location = the box's bottom centre;
- planes/ID.txt (optional): a header (`# Matrix` or `# Plane`, `WIDTH 4`, `HEIGHT 1`, any case) and
  the road plane a b c d with a x + b y + c z + d = 0 in rectified camera-0 coordinates;
- velodyne/ID.bin (optional): float32 (x, y, z, reflectance) per point, Velodyne frame.

Everything is checked when read, and every error is one line naming file:line (UserError).  A point
p_velo of the scan is in rectified camera-0 coordinates at velo_to_rect(calib) @ [p_velo, 1]
(R0_rect @ Tr_velo_to_cam, both as 4x4); image_2 pixels are P2 @ [p_rect, 1] (P2 holds camera 2's
baseline in its last column, so P2 is not K [I | 0]).
"""
import math
import os

import numpy as np

from .errors import UserError

FIELDS = ("type", "truncated", "occluded", "alpha", "x1", "y1", "x2", "y2", "h", "w", "l", "x", "y", "z",
          "rotation_y")
CALIB_SHAPES = {"P0": (3, 4), "P1": (3, 4), "P2": (3, 4), "P3": (3, 4), "R0_rect": (3, 3),
                "Tr_velo_to_cam": (3, 4), "Tr_imu_to_velo": (3, 4)}
CALIB_REQUIRED = ("P0", "P1", "P2", "P3", "R0_rect", "Tr_velo_to_cam")
CALIB_ALIASES = {"R_rect": "R0_rect", "Tr_velo_cam": "Tr_velo_to_cam", "Tr_imu_velo": "Tr_imu_to_velo"}
IGNORED_TYPE = "DontCare"


def _read_lines(path):
    try:
        with open(path, "rb") as f:
            data = f.read()
    except FileNotFoundError:
        raise UserError(f"{path}: no such file") from None
    except OSError as e:
        raise UserError(f"{path}: cannot read ({e.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise UserError(f"{path}: not UTF-8 text (byte {e.start})") from None
    return text.splitlines()


def _floats(tokens, where):
    try:
        v = [float(t) for t in tokens]
    except ValueError:
        bad = next(t for t in tokens if not _is_float(t))
        raise UserError(f"{where}: {bad!r} is not a number") from None
    if not all(math.isfinite(x) for x in v):
        raise UserError(f"{where}: values must be finite, got {' '.join(tokens)}")
    return v


def _is_float(t):
    try:
        float(t)
        return True
    except ValueError:
        return False


# ------------------------------------------------------------------ calib

def parse_calib(path):
    """calib/ID.txt -> {key: ndarray} (P0..P3 (3, 4), R0_rect (3, 3), Tr_velo_to_cam (3, 4), and
    Tr_imu_to_velo (3, 4) when present).  UserError (file:line) on anything else."""
    out = {}
    for n, line in enumerate(_read_lines(path), 1):
        if not line.strip():
            continue
        key, sep, rest = line.partition(":")
        key = CALIB_ALIASES.get(key.strip(), key.strip())
        where = f"{path}:{n}"
        if not sep or key not in CALIB_SHAPES:
            raise UserError(f"{where}: expected 'KEY: numbers' with KEY one of {', '.join(CALIB_SHAPES)}, "
                            f"got {line.strip()[:40]!r}")
        shape = CALIB_SHAPES[key]
        v = _floats(rest.split(), where)
        if len(v) != shape[0] * shape[1]:
            raise UserError(f"{where}: {key} has {shape[0] * shape[1]} values, got {len(v)}")
        if key in out:
            raise UserError(f"{where}: {key} given twice")
        out[key] = np.array(v, dtype=np.float64).reshape(shape)
    missing = [k for k in CALIB_REQUIRED if k not in out]
    if missing:
        raise UserError(f"{path}: calib lacks {', '.join(missing)}")
    P2 = out["P2"]
    if not (P2[0, 0] > 0 and P2[1, 1] > 0 and np.allclose(P2[2, :3], [0, 0, 1], atol=1e-6)):
        raise UserError(f"{path}: P2 is not a rectified projection (fx, fy > 0, last row [0 0 1 t])")
    if not np.allclose(out["R0_rect"] @ out["R0_rect"].T, np.eye(3), atol=1e-3):
        raise UserError(f"{path}: R0_rect is not a rotation")
    return out


def homogeneous(m):
    """(3, 3) or (3, 4) -> (4, 4)."""
    h = np.eye(4)
    h[:3, :m.shape[1]] = m
    return h


def velo_to_rect(calib):
    """(4, 4): Velodyne -> rectified camera-0 coordinates (R0_rect @ Tr_velo_to_cam)."""
    return homogeneous(calib["R0_rect"]) @ homogeneous(calib["Tr_velo_to_cam"])


def camera_of_P(P):
    """A rectified projection P = K [I | t] -> (K (3, 3), t (3,)), t = K^-1 P[:, 3]: a rectified
    point p is at p + t in the camera's own axes, and the camera sits at -t.  Camera 2: t_x ~
    P2[0, 3] / fx ~ +0.06 m, so it stands about 6 cm left of camera 0 (t_y, t_z are millimetres)."""
    K = np.asarray(P, float)[:, :3].copy()
    t = np.linalg.solve(K, np.asarray(P, float)[:, 3])
    return K, t


def calib_text(c):
    """{name: array} -> calib file text (KITTI's layout, 12 significant digits)."""
    return "".join(f"{k}: " + " ".join(f"{v:.12e}" for v in np.asarray(m).ravel()) + "\n" for k, m in c.items())


# ------------------------------------------------------------------ labels

def parse_label_line(line, where="label"):
    """A label_2 line -> {field: value} (15 fields; a 16th, the score, is allowed and kept as 'score')."""
    p = line.split()
    if len(p) not in (15, 16):
        raise UserError(f"{where}: KITTI label lines have 15 fields (16 with a score), got {len(p)}")
    if _is_float(p[0]):
        raise UserError(f"{where}: the first field is the object type, got the number {p[0]!r}")
    v = _floats(p[1:], where)
    out = {"type": p[0], "truncated": v[0]}
    occ = v[1]
    if occ != int(occ) or int(occ) not in (-1, 0, 1, 2, 3):
        raise UserError(f"{where}: occluded is one of -1, 0, 1, 2, 3, got {p[2]!r}")
    out["occluded"] = int(occ)
    out.update(zip(FIELDS[3:], v[2:14]))
    if len(p) == 16:
        out["score"] = v[14]
    if p[0] != IGNORED_TYPE:
        if out["x2"] < out["x1"] or out["y2"] < out["y1"]:
            raise UserError(f"{where}: 2D box x1 y1 x2 y2 must have x2 >= x1 and y2 >= y1")
        if min(out["h"], out["w"], out["l"]) < 0:
            raise UserError(f"{where}: 3D size h w l must not be negative")
    return out


def label_line(obj):
    """{field: value} -> a label_2 line (two decimals, as KITTI's files)."""
    return (f"{obj['type']} {obj['truncated']:.2f} {int(obj['occluded'])} {obj['alpha']:.2f} "
            f"{obj['x1']:.2f} {obj['y1']:.2f} {obj['x2']:.2f} {obj['y2']:.2f} "
            f"{obj['h']:.2f} {obj['w']:.2f} {obj['l']:.2f} {obj['x']:.2f} {obj['y']:.2f} {obj['z']:.2f} "
            f"{obj['rotation_y']:.2f}\n")


def parse_labels(path):
    """label_2/ID.txt -> [(row dict, the line's text)] (blank lines skipped)."""
    rows = []
    for n, line in enumerate(_read_lines(path), 1):
        if line.strip():
            rows.append((parse_label_line(line, f"{path}:{n}"), line.strip()))
    return rows


def with_occluded(text, occluded):
    """A label line's text with its occluded field (the third) replaced, every other byte kept."""
    p = text.split(" ")
    toks = [i for i, t in enumerate(p) if t]
    p[toks[2]] = str(int(occluded))
    return " ".join(p)


# ------------------------------------------------------------------ planes

def parse_plane(path):
    """planes/ID.txt -> (a, b, c, d), unit normal pointing up (b < 0 in the rectified frame, whose y
    points down): KITTI/AVOD's files are so; one written the other way round is turned."""
    nums, where = None, path
    for n, line in enumerate(_read_lines(path), 1):
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        head = s.split()
        if head[0].lower() in ("width", "height") and len(head) == 2:
            want = "4" if head[0].lower() == "width" else "1"
            if head[1] != want:
                raise UserError(f"{path}:{n}: a plane file is {head[0]} {want}, got {head[1]}")
            continue
        if nums is not None:
            raise UserError(f"{path}:{n}: more than one plane row")
        where = f"{path}:{n}"
        nums = _floats(head, where)
        if len(nums) != 4:
            raise UserError(f"{where}: a plane row has 4 values a b c d, got {len(nums)}")
    if nums is None:
        raise UserError(f"{path}: no plane row (a b c d)")
    v = np.array(nums, dtype=np.float64)
    norm = np.linalg.norm(v[:3])
    if norm < 1e-9:
        raise UserError(f"{where}: the plane normal (a, b, c) is zero")
    v /= norm
    if v[1] > 0:
        v = -v
    if abs(v[1]) < 0.5:
        raise UserError(f"{where}: the road plane's normal ({v[0]:.3f}, {v[1]:.3f}, {v[2]:.3f}) is not "
                        f"near the vertical (rectified -y)")
    return tuple(float(x) for x in v)


def plane_text(plane):
    a, b, c, d = plane
    return f"# Matrix\nWIDTH 4\nHEIGHT 1\n{a:.6e} {b:.6e} {c:.6e} {d:.6e} \n"


# ------------------------------------------------------------------ velodyne

def check_velodyne(path):
    """Size check without reading: KITTI scans are float32 x 4 per point."""
    try:
        size = os.path.getsize(path)
    except OSError as e:
        raise UserError(f"{path}: cannot read ({e.strerror})") from None
    if size % 16:
        raise UserError(f"{path}: {size} bytes is not a whole number of points (16 bytes: float32 x y z r)")
    return size // 16


def read_velodyne(path):
    """velodyne/ID.bin -> (N, 4) float32 (x, y, z, reflectance), Velodyne frame."""
    check_velodyne(path)
    pts = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    bad = ~np.isfinite(pts).all(1)
    if bad.any():
        raise UserError(f"{path}: point {int(np.flatnonzero(bad)[0])} is not finite")
    return pts


# ------------------------------------------------------------------ folders

def frame_ids(folder):
    """The frame ids of a KITTI object folder: the names of image_2/*.png, sorted."""
    d = os.path.join(folder, "image_2")
    if not os.path.isdir(folder):
        raise UserError(f"{folder}: no such frames folder")
    if not os.path.isdir(d):
        raise UserError(f"{folder}: not a KITTI object folder (no image_2/)")
    ids = sorted(f[:-4] for f in os.listdir(d) if f.endswith(".png") and not f.startswith("."))
    if not ids:
        raise UserError(f"{d}: no .png frames")
    return ids


def frame_paths(folder, fid):
    return {"image": os.path.join(folder, "image_2", fid + ".png"),
            "calib": os.path.join(folder, "calib", fid + ".txt"),
            "label": os.path.join(folder, "label_2", fid + ".txt"),
            "plane": os.path.join(folder, "planes", fid + ".txt"),
            "velodyne": os.path.join(folder, "velodyne", fid + ".bin")}


def check_folder(folder):
    """Read and check every frame's calib, labels and plane, and the size of every scan, before
    any work: -> {id: {"calib", "labels", "plane" (or None), "velodyne" (path or None), "image"}}."""
    out = {}
    for fid in frame_ids(folder):
        p = frame_paths(folder, fid)
        for k in ("calib", "label"):
            if not os.path.isfile(p[k]):
                raise UserError(f"{p[k]}: no such file (frame {fid} needs its {k})")
        rec = {"image": p["image"], "calib": parse_calib(p["calib"]), "labels": parse_labels(p["label"]),
               "plane": parse_plane(p["plane"]) if os.path.isfile(p["plane"]) else None, "velodyne": None}
        if os.path.isfile(p["velodyne"]):
            check_velodyne(p["velodyne"])
            rec["velodyne"] = p["velodyne"]
        out[fid] = rec
    return out
