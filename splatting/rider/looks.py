"""How a roster rider looks: clothing patterns, hems, face, hair, helmet, shoes and a backpack, as
geometry and vertex colours on the T-posed body (so Blender renders them into the avatar's training
views, and the posed mesh carries them: the one path every rider takes, docs/rider.md).

A look is a small dict (LOOK_FIELDS) drawn per rider by `draw_look` from a Generator seeded with the
rider id (crc32), so every process builds the same rider; a roster entry's optional `look:` block
overrides any field (roster.py validates it).  `dress` turns a look into:
- vertex colours on the body: a jersey pattern (plain, stripes, checks, side panels, a chest band, a
  chest print), shorts or long trousers with an optional side stripe, short or long sleeves, darker
  hems where a garment meets another region, shoe soles, and a face (brows, eyes, lips);
- extra surfaces, each skinned so it moves with the body:
  * helmet: an ellipsoid shell around the skull above the brow, its rim lower at the back, vents as
    darker meridians; every vertex weighted 1 on the head joint (rigid on the head in any pose);
  * hair: the scalp's own faces copied and pushed out along their normals (a 6-14 mm volume) in the
    hair colour, plus a bun or a ponytail for those styles; weighted 1 on the head; under a helmet
    only what the helmet leaves showing is kept;
  * backpack: a box on the upper back, each vertex taking the skinning weights of its nearest
    torso vertex (it bends with the back like the jersey under it), straps painted on the jersey.
Accessory vertices come after the body's, so body vertex indices (keypoint regressors) stay valid.
"""
import zlib

import numpy as np

from splatting.rider.kinematics import JOINT_INDEX
from splatting.rider.look_names import HAIR_STYLES

TOP_PATTERNS = ("plain", "stripes", "checks", "side_panels", "chest_band", "print")
BOTTOM_PATTERNS = ("plain", "side_stripe")
LOOK_FIELDS = {"top_pattern": TOP_PATTERNS, "bottom_pattern": BOTTOM_PATTERNS, "sleeves": ("short", "long"),
               "legs": ("shorts", "long"), "hair": HAIR_STYLES, "helmet": (True, False), "bag": ("none", "backpack")}
COLOUR_FIELDS = ("accent", "hair_colour", "bag_colour")
# the accessory-free look of a rider's bare base avatar (`rider-avatar --bare`): no helmet, no bag, bald,
# so every accessory can be added to it as a set (splatting/cyclist/accessories.py)
BARE = {"helmet": False, "hair": "bald", "bag": "none"}
HAIR_COLOURS = ("#1b1410", "#3b2a1e", "#5a3a22", "#8a5a2b", "#b98c4f", "#d8c27a", "#7a2e17")
GREY_HAIR = ("#9a9690", "#c9c6c0", "#6e6a66")
BAG_COLOURS = ("#222222", "#3a4a2f", "#1f3a5f", "#7a1f1f", "#555a60", "#c2571a")
ACCENTS = ("#ffffff", "#111111", "#f4d35e", "#ee964b", "#0d3b66", "#f95738", "#2ec4b6", "#e71d36", "#c0c0c0")


def hex_rgb(h):
    """'#rrggbb' -> (3,) float rgb in [0, 1] (the roster's and the looks' colours)."""
    h = h.lstrip("#")
    return np.array([int(h[i:i + 2], 16) for i in (0, 2, 4)], float) / 255.0


def draw_look(rider_id, age_years=None):
    """The look of a rider, a function of its id (and age: grey hair from 55 on)."""
    rng = np.random.default_rng([zlib.crc32(str(rider_id).encode()), 28])
    pick = lambda xs, p=None: xs[int(rng.choice(len(xs), p=p))]
    look = {"top_pattern": pick(TOP_PATTERNS), "bottom_pattern": pick(BOTTOM_PATTERNS, [0.6, 0.4]),
            "sleeves": pick(("short", "long"), [0.65, 0.35]), "legs": pick(("shorts", "long"), [0.6, 0.4]),
            "hair": pick(HAIR_STYLES, [0.08, 0.17, 0.35, 0.2, 0.2]), "helmet": bool(rng.uniform() < 0.6),
            "bag": pick(("none", "backpack"), [0.65, 0.35])}
    greys = age_years is not None and age_years >= 55
    look["hair_colour"] = pick(GREY_HAIR if greys else HAIR_COLOURS)
    look["accent"] = pick(ACCENTS)
    look["bag_colour"] = pick(BAG_COLOURS)
    return look


def look_of(spec):
    """A roster entry's look: drawn from its id, then its `look:` block's fields."""
    look = draw_look(spec["id"], spec.get("age_years"))
    look.update(spec.get("look") or {})
    return look


def validate_look(look):
    """The first problem of a `look:` block (a string) or None."""
    if not isinstance(look, dict):
        return "look must be a mapping"
    for k, v in look.items():
        if k in LOOK_FIELDS:
            if v not in LOOK_FIELDS[k] or (k == "helmet" and not isinstance(v, bool)):
                return f"look.{k} must be one of {', '.join(map(str, LOOK_FIELDS[k]))}"
        elif k in COLOUR_FIELDS:
            if not isinstance(v, str) or len(v) != 7 or v[0] != "#" or any(c not in "0123456789abcdefABCDEF" for c in v[1:]):
                return f"look.{k} must be '#rrggbb'"
        else:
            return f"unknown look field {k!r} (known: {', '.join(list(LOOK_FIELDS) + list(COLOUR_FIELDS))})"
    return None


# ------------------------------------------------------------------ geometry helpers

def vertex_normals(verts, faces):
    """(V, 3) area-weighted unit normals."""
    fn = np.cross(verts[faces[:, 1]] - verts[faces[:, 0]], verts[faces[:, 2]] - verts[faces[:, 0]])
    n = np.zeros_like(verts)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def boundary(faces, mask):
    """(V,) bool: vertices of mask that share a face with a vertex outside it."""
    fm = mask[faces]
    mixed = fm.any(1) & ~fm.all(1)
    out = np.zeros(len(mask), bool)
    out[np.unique(faces[mixed])] = True
    return out & mask


def _grow(faces, mask, rings):
    for _ in range(rings):
        touched = np.zeros(len(mask), bool)
        touched[np.unique(faces[mask[faces].any(1)])] = True
        mask = touched
    return mask


def helmet_shell(centre, radii, rim_front_y, rim_back_y, n_az=64, n_rings=14):
    """(verts, faces, vent mask) of an ellipsoid cap (X forward), rim at rim_front_y in front and
    rim_back_y behind (cosine blend over the azimuth)."""
    a, b, c = radii
    verts, vent = [np.array([centre[0], centre[1] + b, centre[2]])], [False]
    phis = np.linspace(0, 2 * np.pi, n_az, endpoint=False)
    for phi in phis:
        w = 0.5 * (1 + np.cos(phi))  # 1 in front, 0 behind
        rim_y = w * rim_front_y + (1 - w) * rim_back_y
        theta_rim = np.arccos(np.clip((rim_y - centre[1]) / b, -1, 1))
        for t in np.linspace(1.0 / n_rings, 1.0, n_rings):
            th = t * theta_rim
            verts.append(centre + np.array([a * np.sin(th) * np.cos(phi), b * np.cos(th), c * np.sin(th) * np.sin(phi)]))
            vent.append(bool(t < 0.75 and np.cos(phi) > -0.3 and (np.round(phi / (2 * np.pi) * n_az) % 8 == 0)))
    faces = []
    idx = lambda i, r: 1 + (i % n_az) * n_rings + r
    for i in range(n_az):
        faces.append([0, idx(i + 1, 0), idx(i, 0)])
        for r in range(n_rings - 1):
            faces += [[idx(i, r), idx(i + 1, r), idx(i + 1, r + 1)], [idx(i, r), idx(i + 1, r + 1), idx(i, r + 1)]]
    return np.array(verts), np.array(faces, np.int64), np.array(vent)


def ellipsoid(centre, radii, n_az=16, n_el=10):
    """(verts, faces) of a closed UV ellipsoid."""
    verts = [centre + [0, radii[1], 0]]
    for k in range(1, n_el):
        th = np.pi * k / n_el
        for i in range(n_az):
            phi = 2 * np.pi * i / n_az
            verts.append(centre + radii * np.array([np.sin(th) * np.cos(phi), np.cos(th), np.sin(th) * np.sin(phi)]))
    verts.append(centre - [0, radii[1], 0])
    idx = lambda k, i: 1 + (k - 1) * n_az + i % n_az
    faces = [[0, idx(1, i + 1), idx(1, i)] for i in range(n_az)]
    for k in range(1, n_el - 1):
        for i in range(n_az):
            faces += [[idx(k, i), idx(k, i + 1), idx(k + 1, i + 1)], [idx(k, i), idx(k + 1, i + 1), idx(k + 1, i)]]
    last = len(verts) - 1
    faces += [[last, idx(n_el - 1, i), idx(n_el - 1, i + 1)] for i in range(n_az)]
    return np.array(verts, float), np.array(faces, np.int64)


def box(lo, hi, n=8):
    """(verts, faces) of a closed box subdivided n x n per side (for a dense enough vertex colouring)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    verts, faces = [], []
    g = np.linspace(0, 1, n + 1)
    for axis in range(3):
        u, v = [k for k in range(3) if k != axis]
        for side in (0, 1):
            base = len(verts)
            for a in g:
                for bb in g:
                    p = np.empty(3)
                    p[axis] = hi[axis] if side else lo[axis]
                    p[u], p[v] = lo[u] + a * (hi[u] - lo[u]), lo[v] + bb * (hi[v] - lo[v])
                    verts.append(p)
            for i in range(n):
                for j in range(n):
                    q = [base + i * (n + 1) + j, base + (i + 1) * (n + 1) + j, base + (i + 1) * (n + 1) + j + 1,
                         base + i * (n + 1) + j + 1]
                    tri = [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
                    faces += tri if side else [t[::-1] for t in tri]
    return np.array(verts), np.array(faces, np.int64)


# ------------------------------------------------------------------ dressing

def _one_hot(n, joint):
    w = np.zeros((n, 24))
    w[:, JOINT_INDEX[joint]] = 1.0
    return w


def dress(verts, faces, weights, joints, eye_y, eyes, colors, regions, look, region_names):
    """(verts, faces, weights, colours, regions, parts) with the look applied: body colours repainted
    in place, accessories appended.  eyes (2, 3): the eye centres; colors: the roster's
    {region: '#rrggbb'}; regions: (V,) ids into region_names; parts: {name: (first, last+1)} of the
    appended vertices."""
    J = JOINT_INDEX
    verts, faces = np.asarray(verts, float), np.asarray(faces, np.int64)
    reg = np.asarray(regions).copy()
    R = {n: i for i, n in enumerate(region_names)}
    base = {n: hex_rgb(colors[n]) for n in ("skin", "top", "bottom", "shoes", "helmet")}
    accent = hex_rgb(look["accent"])
    if np.abs(accent - base["top"]).sum() < 0.3:  # an accent the colour of the jersey shows nothing
        accent = 1.0 - base["top"]
    col = np.stack([base.get(n, base["skin"]) for n in region_names])[reg]
    x, y, z = verts.T
    dom = weights.argmax(1)
    pelvis, neck = joints[J["pelvis"]], joints[J["neck"]]
    sh_z, el_z, wr_z = abs(joints[J["left_shoulder"], 2]), abs(joints[J["left_elbow"], 2]), abs(joints[J["left_wrist"], 2])

    # sleeves and legs: long ones take the arm to the wrist, the leg to the ankle
    arm = np.isin(dom, [J[f"{s}_{p}"] for s in ("left", "right") for p in ("shoulder", "elbow")])
    if look["sleeves"] == "long":
        m = arm & (np.abs(z) < wr_z - 0.03) & (reg == R["skin"])
        reg[m], col[m] = R["top"], base["top"]
    leg = np.isin(dom, [J[f"{s}_{p}"] for s in ("left", "right") for p in ("hip", "knee")])
    if look["legs"] == "long":
        m = leg & (y > joints[J["left_ankle"], 1] + 0.04) & (reg == R["skin"])
        reg[m], col[m] = R["bottom"], base["bottom"]

    top = reg == R["top"]
    torso = top & (np.abs(z) < sh_z)
    chest_y = 0.5 * (joints[J["spine3"], 1] + neck[1])
    p = look["top_pattern"]
    if p == "stripes":
        m = top & (np.floor((y - pelvis[1]) / 0.035) % 2 == 1)
    elif p == "checks":
        m = top & ((np.floor((y - pelvis[1]) / 0.05) + np.floor((z + 1.0) / 0.05)) % 2 == 1)
    elif p == "side_panels":
        half = np.percentile(np.abs(z[torso]), 90) if torso.any() else 0.15
        m = top & ((np.abs(z) > 0.55 * half) & (np.abs(z) < sh_z) | (np.abs(z) > 0.5 * (sh_z + el_z)))
    elif p == "chest_band":
        m = top & (np.abs(y - chest_y) < 0.045) | top & (np.abs(z) > sh_z) & (np.abs(z) < sh_z + 0.05)
    elif p == "print":  # a block on the chest and the back with a contrasting frame
        front = x > pelvis[0] + 0.02
        blk = torso & (np.abs(y - (chest_y - 0.06)) < 0.07) & (np.abs(z) < 0.08)
        inner = torso & (np.abs(y - (chest_y - 0.06)) < 0.045) & (np.abs(z) < 0.055) & front
        m = blk & ~inner
    else:
        m = np.zeros(len(verts), bool)
    col[m] = accent
    if look["bottom_pattern"] == "side_stripe":
        # down the outer side of each leg: around the leg's axis (its dominant joint, T-pose legs
        # hang along Y), the direction pointing away from the body's mid-plane
        side = np.sign(joints[dom, 2])
        ang = np.arctan2(x - joints[dom, 0], (z - joints[dom, 2]) * side)
        m = (reg == R["bottom"]) & leg & (np.abs(ang) < 0.3)
        col[m] = accent

    # hems and seams: the rim of every garment a shade darker, sleeve and leg ends a band of accent
    for r in ("top", "bottom"):
        rim = boundary(faces, reg == R[r])
        col[rim] = col[rim] * 0.55
    shoes = reg == R["shoes"]
    col[shoes & (y < 0.022)] = np.array([0.92, 0.92, 0.9]) if base["shoes"].mean() < 0.5 else np.array([0.12, 0.12, 0.12])
    col[shoes & (x > np.percentile(x[shoes], 80)) & (y >= 0.022)] *= 0.7  # toe caps

    # the face: brows, eyes (white, dark iris), lips
    head = dom == J["head"]
    skin = base["skin"]
    fwd = x > eyes[:, 0].mean() - 0.01
    for e in eyes:
        white = head & fwd & (np.abs(y - e[1]) < 0.008) & (np.abs(z - e[2]) < 0.016)
        col[white] = [0.93, 0.92, 0.9]
        col[head & fwd & (np.abs(y - e[1]) < 0.008) & (np.abs(z - e[2]) < 0.007)] = [0.12, 0.08, 0.06]
        brow = head & fwd & (np.abs(y - (e[1] + 0.02)) < 0.005) & (np.abs(z - e[2]) < 0.022)
        col[brow] = hex_rgb(look["hair_colour"]) * 0.8
    nose_y = eyes[:, 1].mean() - 0.045
    lips = head & fwd & (np.abs(y - (nose_y - 0.025)) < 0.006) & (np.abs(z) < 0.022)
    col[lips] = skin * np.array([0.8, 0.5, 0.5])

    # hair or helmet over the scalp (the body's old "helmet" region becomes scalp: skin or hair)
    scalp_rest = reg == R["helmet"]
    reg[scalp_rest], col[scalp_rest] = R["skin"], skin
    hv = np.flatnonzero(head)
    hc = np.array([np.median(x[hv]), 0.0, np.median(z[hv])])
    back = x < hc[0] - 0.01
    scalp = head & ((y > eye_y + 0.045) | back & (y > eye_y - 0.035)) & ~(np.abs(z) > np.percentile(np.abs(z[hv]), 93))
    hair_rgb = hex_rgb(look["hair_colour"])
    out_v, out_f, out_w, out_c, out_r, parts = [verts], [faces], [weights], [col], [reg], {}

    def add(name, v, f, w, c, r):
        n0 = sum(len(a) for a in out_v)
        out_v.append(v)
        out_f.append(f + n0)
        out_w.append(w)
        out_c.append(np.broadcast_to(c, v.shape).copy() if np.ndim(c) == 1 else c)
        out_r.append(np.full(len(v), R[r], np.int64))
        parts[name] = (n0, n0 + len(v))

    helmet_y = eye_y + 0.035
    if look["hair"] != "bald":
        keep = scalp & ~(look["helmet"] & (y > helmet_y - 0.01))
        col[keep], reg[keep] = hair_rgb * (0.9 + 0.2 * ((np.floor(z / 0.006) % 2))[keep, None]), R["hair"]
        if look["hair"] in ("short", "long", "bun") and keep.any():
            thick = {"short": 0.007, "long": 0.012, "bun": 0.009}[look["hair"]]
            fsel = keep[faces].all(1)
            used = np.unique(faces[fsel])
            remap = -np.ones(len(verts), np.int64)
            remap[used] = np.arange(len(used))
            nrm = vertex_normals(verts, faces)[used]
            hv_ = verts[used] + thick * nrm
            strand = 0.85 + 0.3 * (np.floor((hv_[:, 2] + 1) / 0.005) % 2)[:, None]  # strands as fine streaks
            add("hair", hv_, remap[faces[fsel]], _one_hot(len(used), "head"), hair_rgb * strand, "hair")
        if look["hair"] == "bun" and not look["helmet"]:
            top_y = y[hv].max()
            c0 = np.array([x[hv].min() + 0.02, top_y - 0.03, hc[2]])
            v, f = ellipsoid(c0, np.array([0.04, 0.035, 0.04]))
            add("bun", v, f, _one_hot(len(v), "head"), hair_rgb * 0.9, "hair")
        if look["hair"] == "long":  # a ponytail hanging down the back of the head
            top = np.array([x[hv].min() + 0.005, eye_y - 0.02, hc[2]])
            segs = []
            for t in np.linspace(0, 1, 6):
                segs.append(top + [-0.025 * np.sin(np.pi * t / 2), -0.17 * t, 0.0])  # hangs close to the neck
            v, f = [], []
            n_az = 10
            for k, cen in enumerate(segs):
                r = 0.022 * (1 - 0.6 * k / (len(segs) - 1))
                for i in range(n_az):
                    ph = 2 * np.pi * i / n_az
                    v.append(cen + [r * np.cos(ph), 0.0, r * np.sin(ph)])
            for k in range(len(segs) - 1):
                for i in range(n_az):
                    a0, a1 = k * n_az + i, k * n_az + (i + 1) % n_az
                    f += [[a0, a1, a1 + n_az], [a0, a1 + n_az, a0 + n_az]]
            v = np.array(v)
            add("ponytail", v, np.array(f, np.int64), _one_hot(len(v), "head"), hair_rgb * 0.85, "hair")
    if look["helmet"]:
        cap = head & (y > eye_y + 0.0)
        pts = verts[cap]
        centre = np.array([(pts[:, 0].max() + pts[:, 0].min()) / 2, eye_y + 0.02, (pts[:, 2].max() + pts[:, 2].min()) / 2])
        radii = np.array([(pts[:, 0].max() - pts[:, 0].min()) / 2, pts[:, 1].max() - centre[1], (pts[:, 2].max() - pts[:, 2].min()) / 2])
        q = ((pts - centre) / radii) ** 2
        radii = radii * np.sqrt(q.sum(1).max()) + 0.015  # every skull vertex inside, 1.5 cm of padding
        v, f, vent = helmet_shell(centre, radii, helmet_y, eye_y - 0.02)
        c = np.broadcast_to(base["helmet"], v.shape).copy()
        c[vent] = base["helmet"] * 0.35
        add("helmet", v, f, _one_hot(len(v), "head"), c, "helmet")
    if look["bag"] == "backpack":
        upper = (np.isin(dom, [J["spine2"], J["spine3"]])) & (np.abs(z) < 0.12)
        back_x = np.percentile(x[upper], 3) if upper.any() else pelvis[0] - 0.12
        y0, y1 = joints[J["spine1"], 1] + 0.02, joints[J["neck"], 1] - 0.06
        v, f = box([back_x - 0.13, y0, -0.15], [back_x + 0.02, y1, 0.15], n=20)
        body = np.flatnonzero(np.isin(dom, [J["spine1"], J["spine2"], J["spine3"], J["pelvis"]]))
        nearest = body[np.argmin(((v[:, None, :] - verts[body][None]) ** 2).sum(-1), 1)]
        c = np.broadcast_to(hex_rgb(look["bag_colour"]), v.shape).copy()
        c[(np.abs(v[:, 1] - (y0 + 0.7 * (y1 - y0))) < 0.012) & (v[:, 0] < back_x - 0.12)] *= 0.5  # zip line
        add("backpack", v, f, weights[nearest], c, "bag")
        # straps over the shoulders, painted on the jersey
        strap = (reg == R["top"]) & (np.abs(np.abs(z) - 0.085) < 0.018) & (y > y0 + 0.1)
        col[strap] = hex_rgb(look["bag_colour"]) * 0.8
    return (np.concatenate(out_v), np.concatenate(out_f), np.concatenate(out_w), np.clip(np.concatenate(out_c), 0, 1),
            np.concatenate(out_r), parts)
