"""The 8-DoF bike pose (docs/contract.md "Pose"): field names, parsing and validation, numpy only.

A pose is (theta_p, theta_s, theta_x, theta_y, theta_z) in degrees and (t_x, t_y, t_z) in metres,
in this order everywhere: command lines ("p,s,X,Y,Z,tx,ty,tz"), JSON files (a list of 8 numbers
or a dict of the named fields), the Blender oracle and the Gaussian bike.
"""
import math

import numpy as np

from .errors import UserError

POSE_FIELDS = ("theta_p_deg", "theta_s_deg", "theta_x_deg", "theta_y_deg", "theta_z_deg",
               "t_x_m", "t_y_m", "t_z_m")
N_ANGLES = 5  # the first five pose values are angles
FIELDS_HELP = ", ".join(POSE_FIELDS)


def check_poses(poses):
    """Any (8,) or (B, 8) array-like of degrees/metres -> float64 array (B, 8); UserError if bad."""
    try:
        t = np.asarray(poses, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise UserError(f"pose is not a list of numbers: {e}") from None
    if t.ndim == 1:
        t = t[None]
    if t.ndim != 2 or t.shape[1] != 8:
        raise UserError(f"a pose has 8 values ({FIELDS_HELP}); got shape {tuple(t.shape)}")
    if t.shape[0] == 0:
        raise UserError("no poses given")
    bad = ~np.isfinite(t)
    if bad.any():
        i, j = (int(x) for x in np.argwhere(bad)[0])
        raise UserError(f"pose {i}: {POSE_FIELDS[j]} is {t[i, j]} (must be finite)")
    return t


def parse_pose_string(text):
    """'p,s,X,Y,Z,tx,ty,tz' (degrees, metres) -> float64 array (8,)."""
    items = [s.strip() for s in str(text).replace(";", ",").split(",")]
    if len(items) != 8:
        raise UserError(f"--pose needs 8 comma-separated values (p,s,X,Y,Z,tx,ty,tz); got {len(items)}: {text!r}")
    vals = []
    for name, s in zip(POSE_FIELDS, items):
        try:
            v = float(s)
        except ValueError:
            raise UserError(f"--pose {name} is not a number: {s!r}") from None
        if not math.isfinite(v):
            raise UserError(f"--pose {name} is {s} (must be finite)")
        vals.append(v)
    return check_poses(vals)[0]


def poses_from_json(obj):
    """A list of 8-lists or of dicts with the named POSE_FIELDS (or {"poses": [...]}) -> (B, 8)."""
    if isinstance(obj, dict) and "poses" in obj:
        obj = obj["poses"]
    if isinstance(obj, dict):
        obj = [obj]
    if not isinstance(obj, list) or not obj:
        raise UserError("poses file must hold a non-empty list of poses")
    rows = []
    for i, p in enumerate(obj):
        if isinstance(p, dict):
            missing = [k for k in POSE_FIELDS if k not in p]
            extra = [k for k in p if k not in POSE_FIELDS]
            if missing or extra:
                raise UserError(f"pose {i}: missing fields {missing}, unknown fields {extra}")
            p = [p[k] for k in POSE_FIELDS]
        if not isinstance(p, (list, tuple)) or len(p) != 8:
            raise UserError(f"pose {i}: expected 8 numbers or a dict of {FIELDS_HELP}")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in p):
            raise UserError(f"pose {i}: values must be numbers, got {p}")
        rows.append([float(v) for v in p])
    return check_poses(rows)


def pose_dict(pose):
    """(8,) degrees/metres -> {field: value} for JSON output."""
    return {k: float(v) for k, v in zip(POSE_FIELDS, np.asarray(pose, dtype=np.float64).reshape(8).tolist())}
