"""The whole automatic curation on arrays (numpy, no bpy): model triangles in, canonical
transform, keypoints, problems and per-triangle part labels out."""
from dataclasses import dataclass, field

import numpy as np

from ..contract import UserError
from . import keypoints as kpmod
from . import keypoint_check, mesh, orientation, scale, silhouette, split, wheels
from .rider_removal import drop_rider
from .shape_fit import check_two_wheels, choose_keypoints, shape_samples
from .shape_keypoints import bulky as _bulky
from .pose import canonical_pose
from .validate import validate

DEFAULT_WHEEL_DIAMETER = 0.7


@dataclass
class Result:
    M: np.ndarray                    # 4x4 model -> canonical (metres)
    scale: float
    keypoints: dict                  # name -> (3,) canonical
    labels: np.ndarray               # per input triangle: split.FRAME/STEERING/CRANK/JUNK
    cut: np.ndarray                  # per input triangle: labelled face by face (fused mesh)
    problems: list
    notes: list = field(default_factory=list)
    wheel_diameter: float = DEFAULT_WHEEL_DIAMETER
    record: dict = field(default_factory=dict)
    cues: list = field(default_factory=list)         # orientation.Cue: which way the bike faces
    split_args: dict = field(default_factory=dict)   # regions() parameters: where fused faces are cut


def curate_arrays(V, T, wheel_diameter=DEFAULT_WHEEL_DIAMETER, keypoints=None, hints=None, wheel_centres=None):
    """V (n, 3) model vertices (world), T (m, 3) triangles.

    wheel_diameter: the tyres' outer diameter in metres, or None: sized from every cue
    (scale.py: the vehicle class its shape shows, the file's own units, the wheelbase, bar and
    seat heights), refused with the measured figures when they disagree.
    keypoints: optional {name: canonical xyz} that replace the automatic ones (an annotator's
    JSON); wheel_centres: optional (front, rear) model points an annotator placed, used instead
    of the wheel search; hints: optional per-triangle labels (split.FRAME.. or -1 for none) from vertex
    groups or object names, used instead of the automatic split where given.
    Raises UserError when no wheels are found.
    """
    res, err = _sized(V, T, wheel_diameter, keypoints, hints, wheel_centres, {})
    if wheel_centres is not None:   # the annotator placed the front wheel: their front
        if err:
            raise UserError(err)
        return res
    v = res.record["forward_check"]["verdict"]
    bar_guess = res.record.get("forward_cue", "").startswith("handlebar")
    if v in ("backwards", "conflict") or ((err or res.problems) and bar_guess):
        # the other way round: the cues say this way is backwards (a mirrored bike: pedal_left on
        # the right), or disagree, or front and back came from the bar's average place, a guess
        # (a motor scooter's broad rear body is as wide and high as its bar), and this way has problems
        rear = np.linalg.inv(res.M) @ np.r_[res.keypoints["rear_axle"], 1.0]
        try:
            res2, err2 = _sized(V, T, wheel_diameter, keypoints, hints, wheel_centres, {"front": rear[:3]})
        except UserError as e:
            res2, err2 = None, str(e)
        if v == "conflict":
            # the crank and the bar point opposite ways (a toy bike's crank nearer its front wheel,
            # something wider than the bar high over the rear wheel): only a way that validates
            # where the other does not is taken; a backwards bike can validate too
            good = [(r, e) for r, e in ((res, err), (res2, err2)) if r is not None and e is None and not r.problems]
            if len(good) != 1:
                raise UserError(orientation.conflict_line(res.cues))
            if good[0][0] is res2:
                res, err = res2, err2
                res.record["forward_cue"] = "the other way round (the only way that validates; the cues disagree)"
            _note(res, None, "front and back: the crank and the bar disagree, only this way validates")
            return res
        if res2 is not None and _rank(res2, err2) < _rank(res, err):
            res, err = res2, err2
            if v == "backwards":
                _note(res, "the other way round (the crank and bar cues say so)", "front and back: the other way "
                      "round, the crank and bar cues say so")
            else:
                _note(res, "the other way validates (bar cue reversed)",
                      "front and back: the bar cue reversed, the other way validates")
            v = res.record["forward_check"]["verdict"]
    if v == "backwards":
        raise UserError("the bike faces backwards whichever way it is curated (" +
                        "; ".join(c.text for c in res.cues if c.sign) + "); place the wheel centres in the "
                        "annotator panel (Curate from wheel centres)")
    if err:
        raise UserError(err)
    return res


def _note(res, cue, note):
    if cue:
        res.record["forward_cue"] = cue
    res.notes.append(note)
    res.record["notes"] = res.record["notes"] + [note]


_VERDICT_RANK = {"forward": 0, "unknown": 1, "backwards": 2, "conflict": 2}


def _rank(res, err):
    """Order of two curations of one model the two ways round: not the one the cues say is
    backwards (or whose cues disagree), then one that validates (no refusal, no problem) over
    one that does not, then the one the cues say faces forward, then fewer problems (a refusal
    counts as one).  A clean way whose bar cue falls just inside the margin (undecided) beats a
    failing way the cues call forward: which surface samples reach the bar's ends, and so
    whether the cue decides, changes with the file's triangle order (the motor scooter's bar
    sits 0.09-0.14 m from the middle, the margin 0.13 m, before and after a glTF round trip).
    A front guessed from the bar (the high wide parts' average place) that only the bar cue
    confirms is no evidence (the cue measures what the guess did): it ranks as undecided."""
    v = res.record["forward_check"]["verdict"]
    if v == "forward" and res.record.get("forward_cue", "").startswith("handlebar") \
            and all(c.sign == 0 for c in res.cues if c.name != "bar"):
        v = "unknown"
    failures = (0 if err is None else 1) + len(res.problems)
    return _VERDICT_RANK[v] == 2, failures > 0, _VERDICT_RANK[v], failures


def _sized(V, T, wheel_diameter, keypoints, hints, wheel_centres, extra):
    """(Result, refusal text or None): curated at the given wheel size, or, with None, at the
    size every cue gives (scale.py; the text says why the cues disagree)."""
    res = _curate(V, T, wheel_diameter, keypoints, hints, wheel_centres, dict(extra))
    if wheel_diameter is not None:
        return res, None
    # the first pass at a bicycle's 0.7 m wheels shows what the vehicle is; curate again at the
    # size its cues give (every length threshold is relative to the wheels or metric)
    size = scale.choose(res)
    if abs(size["diameter"] / res.wheel_diameter - 1) > 0.02:
        res = _curate(V, T, None, keypoints, hints, wheel_centres, {**size, **extra})
    return res, scale.check(res, size)


def _curate(V, T, wheel_diameter, keypoints, hints, wheel_centres, _size):
    if wheel_diameter is not None and not (wheel_diameter > 0 and np.isfinite(wheel_diameter)):
        raise UserError(f"--wheel-diameter must be a positive number of metres, got {wheel_diameter}")
    V = np.asarray(V, float)
    T = np.asarray(T, np.int64).reshape(-1, 3)
    if len(T) == 0:
        raise UserError("the model has no faces")
    if not np.all(np.isfinite(V)):
        raise UserError("the model has non-finite vertex coordinates")
    soup = mesh.Soup(V, T)
    if not soup.area.sum() > 0:
        raise UserError("the model's faces have no area (all degenerate): nothing to curate")
    check_not_noisy(soup)
    rings = wheels.find_rings(soup)
    pair = wheels.wheel_pair(rings) if wheel_centres is None else None
    seeds, wheel_method, front = None, "rings", _size.get("front")
    if wheel_centres is not None:
        pair, bands = silhouette.rings_from_centres(soup, *wheel_centres)
        comp_pos = {c.index: i for i, c in enumerate(soup.comps)}
        seeds = sorted({comp_pos[c] for b in bands for c in soup.comp_of_vert[b] if c in comp_pos})
        wheel_method, front = "given", np.asarray(wheel_centres[0], float)
    elif pair is None:
        # no clean tyre pieces: the wheels are the two circles of the side-view outline
        pair, _, bands = silhouette.wheel_rings(soup, skip=backdrops(soup))
        comp_pos = {c.index: i for i, c in enumerate(soup.comps)}
        seeds = sorted({comp_pos[c] for b in bands for c in soup.comp_of_vert[b] if c in comp_pos})
        wheel_method = "silhouette"
    if seeds is not None and not seeds:  # no vertex on the tyre outline: grow from everything
        seeds = list(range(len(soup.comps)))
    auto_size = wheel_diameter is None
    wheel_diameter = _size.get("diameter", DEFAULT_WHEEL_DIAMETER) if auto_size else wheel_diameter
    pose = canonical_pose(soup, rings, pair, wheel_diameter, seeds, front)
    if "note" in _size:
        pose.notes.append(_size["note"])
    keep_tri = soup.tri_mask(pose.keep)
    rider = drop_rider(soup, pose)
    if rider.any():
        pose.keep &= ~rider
        keep_tri = soup.tri_mask(pose.keep)
        pose.notes.append(f"removed a rider: {int(rider.sum())} component(s) of a person-sized shape above the saddle")
    view = kpmod.View(soup, pose)
    X = shape_samples(view, keep_tri)
    check_two_wheels(X, pose)
    auto, notes, info, has_crank_shape = choose_keypoints(view, pose, X, clean=wheel_method == "rings")
    kp = dict(auto)
    source = {k: "auto" for k in auto}
    if keypoints:
        for k, v in keypoints.items():
            kp[k] = np.asarray(v, float)
            source[k] = "file"
    has_crank = has_crank_shape if has_crank_shape is not None else \
        (pose.crank is not None or ("pedal_left" in kp and "pedal_right" in kp))
    problems = validate(kp, has_crank)
    needed = ("crank_axle", "front_axle", "steer_top", "steer_bottom", "pedal_left", "pedal_right")
    if all(k in kp for k in needed):
        labels, cut = split.label_triangles(view, keep_tri, kp, info.get("head_tube_radius"),
                                            pose.front.radius * pose.scale, has_crank, info.get("head_span"))
    else:  # no split without the keypoints that define it: everything is frame until fixed
        labels, cut = np.where(keep_tri, split.FRAME, split.JUNK), np.zeros(len(T), bool)
    if hints is not None:
        h = np.asarray(hints)
        use = (h >= 0) & keep_tri
        labels[use] = h[use]
    kp_probs, kp_dist = {}, {}
    if all(k in kp for k in needed) and not problems:
        # the keypoints on their own parts (keypoint_check.py): only once they validate, a
        # refused geometry says more than a distance
        if has_crank and keypoint_check.pedal_pieces(soup, view.P, labels, kp, keep_tri):
            notes.append("pedal bodies modelled as their own pieces put on the crank")
        given = {k: kp[k] for k in (keypoints or {})}   # an annotator's points are measured, never moved
        moved = [k for k in keypoint_check.snap(view.P, soup.TW, labels, kp, has_crank) if k not in given]
        kp.update(given)
        if moved:
            problems = validate(kp, has_crank)
            notes.append(f"moved onto their part: {', '.join(moved)}")
        kp_probs, kp_dist = keypoint_check.check(view.P, soup.TW, labels, kp, has_crank)
        problems = problems + kp_probs
    if pose.crank is not None and pose.apply(pose.crank.centre)[2] < -0.01:
        notes.append("the chainring is on the bike's left (a mirrored model?): curated as modelled, "
                     "pedal_left on the left")
    cues = orientation.cues(X, kp, 0.5 * (pose.front.radius + pose.rear.radius) * pose.scale, has_crank,
                            pose.crank is not None)
    split_args = {"head_radius": info.get("head_tube_radius"), "wheel_radius": pose.front.radius * pose.scale,
                  "head_span": info.get("head_span"), "has_crank": bool(has_crank)}
    record = {
        "method": "auto" if not keypoints else "auto+file",
        "wheel_diameter_m": float(wheel_diameter),
        "scale_m_per_unit": float(pose.scale),
        "model_to_canonical": pose.M.tolist(),
        "forward_cue": pose.forward_cue,
        "forward_check": {"verdict": orientation.verdict(cues), **{c.name: c.text for c in cues}},
        "wheel_radii_model_units": [float(pose.rear.radius), float(pose.front.radius)],
        "chainring_found": pose.crank is not None,
        "wheels_from": wheel_method,
        "has_crank": bool(has_crank),
        "height_m": float(X[:, 1].max()) if len(X) else 0.0,
        "bulky": float(sk_bulky(X, pose)),
        "components": len(soup.comps),
        "components_kept": int(pose.keep.sum()),
        "keypoint_source": source,
        "notes": pose.notes + notes,
        "faces_cut": int(cut.sum()),
        "keypoint_distance_cm": {k: round(v * 100, 2) for k, v in kp_dist.items()},
        "split_args": {k: (v if v is None or isinstance(v, bool) else np.asarray(v, float).tolist())
                       for k, v in split_args.items()},
    }
    return Result(pose.M, pose.scale, kp, labels, cut, problems, pose.notes + notes, wheel_diameter, record, cues,
                  split_args)


NOISY_MEDIAN_DEG = 28.0   # median angle between neighbouring faces above which a dense mesh is noise
NOISY_MIN_FACES = 5000


def check_not_noisy(soup):
    """UserError for a dense mesh whose neighbouring faces meet at random angles (a noisy
    photogrammetry scan): modelled surfaces are flat or smoothly curved between their edges
    (median angle <= 22 deg on the shared real models and the synthetic ones), a scan with noise
    of a few mm on 1-3 cm faces is 32-44 deg."""
    if len(soup.TW) < NOISY_MIN_FACES:
        return
    ang = mesh.dihedral_angles(soup)
    if len(ang) and np.median(ang) > NOISY_MEDIAN_DEG and (ang > 30).mean() > 0.5:
        raise UserError(f"not a clean model: the surface is noisy (median angle between neighbouring faces "
                        f"{np.median(ang):.0f} deg > {NOISY_MEDIAN_DEG:.0f}; a photogrammetry scan?)")


def sk_bulky(X, pose):
    """Share of the side view between the wheels filled by a wide body (a motorcycle's engine
    and tank, a scooter's deck or covered body; shape_keypoints.bulky)."""
    fa, ra = pose.apply(pose.front.centre), pose.apply(pose.rear.centre)
    return _bulky(X, fa, ra, 0.5 * (pose.front.radius + pose.rear.radius) * pose.scale) if len(X) else 0.0


def backdrops(soup):
    """Components that are flat sheets at least as large as everything else together: a ground
    plane or backdrop the model was published on (found before the wheels, whose size sizes the
    later ground_like check).  A bike's own plates (a number plate, a fairing) are far smaller
    than the bike."""
    out = np.zeros(len(soup.comps), bool)
    if len(soup.comps) < 2:
        return out
    lo = np.array([c.bbox[0] for c in soup.comps])
    hi = np.array([c.bbox[1] for c in soup.comps])
    for i, c in enumerate(soup.comps):
        if not (c.spread[0] > 0 and c.spread[2] < 0.01 * c.spread[0]):
            continue
        rest = np.ones(len(soup.comps), bool)
        rest[i] = False
        rest_ext = float((hi[rest].max(0) - lo[rest].min(0)).max())
        if float((c.bbox[1] - c.bbox[0]).max()) >= 0.9 * rest_ext:
            out[i] = True
    return out


class _Identity:
    """A Pose stand-in for a mesh that is already canonical (re-split after edits)."""

    def __init__(self, n_comps):
        self.M = np.eye(4)
        self.scale = 1.0
        self.keep = np.ones(n_comps, bool)


def relabel(V, T, kp):
    """Part label per triangle of an already canonical mesh from (edited) keypoints."""
    needed = ("crank_axle", "front_axle", "steer_top", "steer_bottom", "pedal_left", "pedal_right")
    missing = [k for k in needed if k not in kp]
    if missing:
        raise UserError(f"keypoint '{missing[0]}' is missing: place it before splitting")
    kp = {k: np.asarray(v, float) for k, v in kp.items()}
    soup = mesh.Soup(V, T)
    view = kpmod.View(soup, _Identity(len(soup.comps)))
    ht = kpmod.head_tube(view, kp["front_axle"], kp["crank_axle"])
    labels, _ = split.label_triangles(view, np.ones(len(soup.TW), bool), kp, ht[0] if ht else None,
                                      float(kp["front_axle"][1]))
    return labels
