"""Which way the curated bike faces, checked by cues independent of the pose's guess (numpy, no bpy).

The canonical frame is right-handed (docs/contract.md: X forward, Y up, Z to the rider's right),
so a bike curated backwards is also mirrored: its pedal_left and handle_left land on the
bike's right.  Left and right themselves come from the side of the mid-plane (Z = 0) each pedal
body and grip lies on; what can go wrong is forward.  The pose (pose.py) guesses forward from the
chainring, else from where the wide parts high up sit on average (a densely modelled wide saddle
outweighs a bar of few vertices), and the pipeline's retry takes the other way round when that
one validates better (a backwards bike can validate: its seat stays read as a fork).  So after
the keypoints, on the kept bike in the canonical frame (a rider removed), two cues measured on
the geometry, each +1 (agrees with X forward), -1 (says the bike is backwards) or 0 (no cue):

- crank: a bicycle's crank sits nearer its rear wheel (chainstays ~0.42 m, front centre ~0.6 m);
  the pedal bodies' midpoint, else the chainring's centre, more than a tenth of the wheelbase
  nearer one axle than the other;
- bar: the handlebar, the widest thing high up (above 2.25 wheel radii: not a pannier or a
  kickstand), sits at the top of the steering over the front half: its ends' (the points within
  15 % of the greatest width) mean X more than a tenth of the wheelbase from the middle.

They decide only when they are sure; when the two point opposite ways the model is refused with
the figures (curating it either way would mirror one of them)."""
from dataclasses import dataclass

import numpy as np

MARGIN = 0.1          # of the wheelbase: a cue nearer that to even says nothing
BAR_HEIGHT = 2.25     # wheel radii above the ground: where a handlebar is (pose.py's high parts)
BAR_ENDS = 0.85       # of the greatest half width: the bar's ends
MIN_HALF_WIDTH = 0.3  # wheel radii: narrower than that up high is a saddle or a stem, not a bar


@dataclass
class Cue:
    name: str
    sign: int        # +1 agrees with X forward, -1 says backwards, 0 undecided
    text: str        # the measured figures, frame-independent (a refusal quotes it)


def crank_cue(kp, has_crank, chainring_found):
    fa, ra = np.asarray(kp["front_axle"], float), np.asarray(kp["rear_axle"], float)
    if has_crank and "pedal_left" in kp and "pedal_right" in kp:
        c, what = 0.5 * (np.asarray(kp["pedal_left"], float) + np.asarray(kp["pedal_right"], float)), "pedals' midpoint"
    elif chainring_found and "crank_axle" in kp:
        c, what = np.asarray(kp["crank_axle"], float), "chainring"
    else:
        return Cue("crank", 0, "no crank")
    wb = fa[0] - ra[0]
    dr, df = c[0] - ra[0], fa[0] - c[0]
    near, far = sorted((dr, df))
    text = f"the crank ({what}) is {near:.2f} m from one axle and {far:.2f} m from the other"
    if abs(dr - df) <= MARGIN * abs(wb):
        return Cue("crank", 0, text + " (too even to tell)")
    return Cue("crank", 1 if dr < df else -1, text)


def bar_cue(X, kp, R):
    fa, ra = np.asarray(kp["front_axle"], float), np.asarray(kp["rear_axle"], float)
    wb = fa[0] - ra[0]
    m = (X[:, 1] > BAR_HEIGHT * R) & (X[:, 0] > ra[0] - R) & (X[:, 0] < fa[0] + R)
    B = X[m]
    if len(B) < 4:
        return Cue("bar", 0, "nothing high up")
    z = np.abs(B[:, 2])
    zmax = float(z.max())
    if zmax < MIN_HALF_WIDTH * R:
        return Cue("bar", 0, f"nothing wide high up ({2 * zmax:.2f} m across)")
    xm = float(B[z > BAR_ENDS * zmax, 0].mean()) - 0.5 * (fa[0] + ra[0])
    text = f"the widest part high up, {2 * zmax:.2f} m across (a handlebar's place), is {abs(xm):.2f} m from the wheelbase middle"
    if abs(xm) <= MARGIN * abs(wb):
        return Cue("bar", 0, text + " (too near it to tell)")
    return Cue("bar", 1 if xm > 0 else -1, text)


def cues(X, kp, R, has_crank, chainring_found):
    """[crank cue, bar cue] of a curated bike: X its kept surface samples and kp its keypoints,
    canonical metres; R the wheel radius."""
    if "front_axle" not in kp or "rear_axle" not in kp:
        return []
    return [crank_cue(kp, has_crank, chainring_found), bar_cue(X, kp, R)]


def verdict(cs):
    """'forward', 'backwards', 'conflict' (cues point opposite ways) or 'unknown' (no cue)."""
    signs = {c.sign for c in cs} - {0}
    if signs == {1}:
        return "forward"
    if signs == {-1}:
        return "backwards"
    return "conflict" if signs else "unknown"


def conflict_line(cs):
    """The one-line refusal of a bike whose cues point opposite ways."""
    crank = next(c for c in cs if c.name == "crank")
    bar = next(c for c in cs if c.name == "bar")
    return (f"cannot tell the front from the back: {crank.text}, so the far one is the front (a crank sits "
            f"nearer the rear wheel), but {bar.text} towards the axle the crank is nearer; "
            f"place the wheel centres in the annotator panel (Curate from wheel centres)")
