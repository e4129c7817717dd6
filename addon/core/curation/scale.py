"""The real size of a downloaded two-wheeler from every cue its shape and file give (numpy, no bpy).

A model's units say little (glTF is metres by the standard, yet people export bikes 0.12 or 200
units long), so the size comes from what the vehicle is:
- its class, from the shape at a bicycle's size: pedals on a crank, or a wheelbase under ~2
  wheel diameters, is a bicycle (0.7 m tyres); no crank and a wheelbase over 3.4 wheel
  diameters a kick scooter (sized so its top, the bar, is 1 m high); 2.75-3.4 diameters a motor
  scooter (small wheels: 0.46 m); below that a motorcycle (0.64 m);
- the file's own units: when the tyres measured in metres, centimetres, millimetres or inches
  fall in the class's range of wheel sizes, the author modelled it at real size and that wins;
- then the wheelbase, the bar and the seat heights at that size must be the class's; when they
  are not, the cues disagree (a lean, a ground plane or a wrong wheel pair made the wheels too
  small or too large) and the model is refused with the measured figures rather than curated
  at a wrong size.
"""
import numpy as np

# class: (typical tyre diameter, tyre range, wheelbase range, bar height range, seat height range), metres
CLASSES = {
    "bicycle": (0.70, (0.30, 0.80), (0.55, 1.50), (0.50, 1.50), (0.40, 1.25)),
    "motorcycle": (0.64, (0.45, 0.80), (1.10, 2.00), (0.65, 1.55), (0.50, 1.10)),
    "motor scooter": (0.46, (0.30, 0.62), (0.90, 1.80), (0.70, 1.45), (0.50, 1.05)),
    "kick scooter": (None, (0.06, 0.32), (0.30, 1.20), (0.55, 1.35), None),
}
# tyre sizes at which the file's own units are believed: the common adult sizes (a toy or a
# child's bike modelled "in metres" at 0.59 m is more likely an arbitrary unit)
FILE_UNITS_TRUSTED = {"bicycle": (0.62, 0.76), "motorcycle": (0.55, 0.74), "motor scooter": (0.35, 0.56),
                      "kick scooter": (0.08, 0.26)}
UNITS = ((1.0, "metres"), (0.01, "centimetres"), (0.001, "millimetres"), (0.0254, "inches"))


def classes(res):
    """(plausible classes, best first; why) from a curation at any size (ratios only)."""
    kp = res.keypoints
    D = res.wheel_diameter
    wb = float(np.linalg.norm(kp["front_axle"] - kp["rear_axle"])) / D if "front_axle" in kp else 0.0
    crank = bool(res.record.get("has_crank"))
    why = f"{'pedals on a crank' if crank else 'no crank'}, wheelbase {wb:.1f} wheel diameters"
    if crank or wb < 1.95:
        return ["bicycle"], why
    if wb >= 3.4:
        return ["kick scooter"], why
    # motorcycles (2.0-2.9) and small-wheeled motor scooters (2.6-3.3) overlap: the heights decide
    return (["motor scooter", "motorcycle"] if wb >= 2.75 else ["motorcycle", "motor scooter"]), why


def candidates(res):
    """[{'diameter', 'class', 'cue', 'note'}] in order of preference: the file's own units where
    they give a wheel size of a plausible class, then each class's typical size."""
    cls_list, why = classes(res)
    d_model = float(sum(res.record["wheel_radii_model_units"]))   # two radii: one mean diameter
    out = []
    for cls in cls_list:
        lo, hi = FILE_UNITS_TRUSTED[cls]
        for f, unit in UNITS:
            if lo <= d_model * f <= hi:
                d = round(d_model * f, 4)
                out.append({"diameter": d, "class": cls, "cue": f"the file's {unit}",
                            "note": f"size: a {cls} ({why}) modelled in {unit}: wheel diameter {d:.3f} m"})
                break
    for cls in cls_list:
        typical, (lo, hi) = CLASSES[cls][:2]
        if typical is None:   # kick scooter: its top (the bar) 1 m high
            top = res.record.get("height_m") or 0.0
            d = float(np.clip(round(res.wheel_diameter / top, 4) if top > 0 else 0.2, lo, hi))
            out.append({"diameter": d, "class": cls, "cue": "its top 1 m high",
                        "note": f"size: a {cls} ({why}): wheel diameter {d:.3f} m so its top is 1 m high"})
        else:
            out.append({"diameter": typical, "class": cls, "cue": f"a {cls}'s typical wheels",
                        "note": f"size: a {cls} ({why}): wheel diameter {typical:.2f} m (typical)"})
    return out


def choose(res):
    """The first candidate size at which the vehicle's wheelbase, bar and seat heights are its
    class's (measured on `res` scaled, no new curation), else the first candidate (check()
    will refuse it with the figures)."""
    cands = candidates(res)
    for c in cands:
        if not misfits(res, c["class"], c["diameter"] / res.wheel_diameter):
            return c
    return cands[0]


def misfits(res, cls, k=1.0):
    """The class's ranges that `res`'s measures (scaled by k) miss, as text."""
    _, _, wb_r, bar_r, seat_r = CLASSES[cls]
    bad = []
    for name, v, r in zip(("wheelbase", "bar height", "seat height"), measures(res), (wb_r, bar_r, seat_r)):
        if v is not None and r is not None and not r[0] <= v * k <= r[1]:
            bad.append(f"{name} {v * k:.2f} m (a {cls}'s: {r[0]:.2f}-{r[1]:.2f})")
    return bad


def measures(res):
    """(wheelbase, bar height, seat height) in metres of a Result; None where unknown."""
    kp = res.keypoints
    wb = float(np.linalg.norm(kp["front_axle"] - kp["rear_axle"])) if "front_axle" in kp and "rear_axle" in kp else None
    bar = kp.get("handle_right", kp.get("steer_top"))
    seat = kp.get("seat")
    return wb, (None if bar is None else float(bar[1])), (None if seat is None else float(seat[1]))


def check(res, size):
    """The refusal (one line naming the measured figures) when the sized vehicle is not its
    class's size, else None; the record keeps the size and its cue."""
    cls = size["class"]
    bad = misfits(res, cls)
    if bad:
        return (f"size: the cues disagree: a {cls} with {res.wheel_diameter:.2f} m wheels ({size['cue']}) "
                f"gives {', '.join(bad)}; give --wheel-diameter if the wheels are right")
    wb, bar, seat = measures(res)
    res.record["size"] = {"class": cls, "cue": size["cue"], "wheelbase_m": wb, "bar_height_m": bar,
                          "seat_height_m": seat}
    return None
