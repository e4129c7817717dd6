"""A humanoid skeleton's bones -> the 24 SMPL joints (docs/contract.md "Names"); numpy only, no bpy.

`rider import` needs a bone (or a point riding on one) for each SMPL joint.  People publish rigs under
many naming families, so names are not matched against fixed tables but normalised, then read as a
body part and a side:

1. Normalise: drop a namespace (`mixamorig:`, `mixamorig1:`, `Armature|`), split camelCase, separators
   (`_ . - space`) and digits into tokens, drop family prefixes (`mixamorig`, `DEF`, `J_Bip_C`,
   `CC_Base`, `Bip01`, `Skeleton ... joint`, and any unknown leading word such as HumanIK's
   `Character1_`), read a side token (`L/R/Left/Right`, as prefix or
   suffix: `thigh_l`, `DEF-thigh.L`, `Bip01 L Thigh`, `LeftUpLeg`, `Left arm_07`).  The rest is the
   part key, tried with and without a trailing number (Sketchfab's `_07` renumbering, UE's `spine_01`).
2. Never a joint: helper, IK, control, pole, target, twist, roll, leaf, end, socket bones (name
   tokens), and bones that deform nothing when the file says so (Rigify ORG-/MCH-, a .blend's controls).
3. Part words: pelvis/hips; spine/chest/upperchest/abdomen/torso/waist; neck; head; clavicle/collar/
   shoulder; upperarm/arm; forearm/lowerarm/elbow; hand/wrist; thigh/upleg/upperleg; calf/shin/leg/
   lowerleg/knee; foot/ankle; toe/toebase/toes/ball; middle/index finger bases (incl. Biped Finger2/1,
   VRM MiddleProximal, CC Mid1).  Ambiguous words are settled per side by what else is there
   (`shoulder` is the collar when an upper-arm bone follows it, else the upper arm; `hand` is the
   SMPL hand when a `wrist` bone exists; `foot` is the toe when an `ankle` exists; `leg` is the shin
   when a thigh exists).  Rigify's `DEF-spine[.00N]` chain is read by its numbers.
4. The torso from the tree: the spine chain is the path from the pelvis to the head; its bones below
   the neck fill spine1..3 by their place along it (SMPL's fractions); a rig with fewer spine bones
   (two, one, none) gets the missing spine joints interpolated along the chain, riding on the bone
   below them.  A missing neck, collar, hand or toe is likewise placed from its neighbours
   (`Mapping.virtual`).
5. No names at all (or too few): the topology and geometry of the skeleton.  The two lowest leaf
   chains that split left/right are the legs; their common ancestor is the pelvis; the two chains
   reaching furthest sideways from above it are the arms; the path up from the pelvis that continues
   past the arms ends in the head; long bones along a limb are its segments; left/right from the side
   of the body (forward = the feet's heel->toe direction).

`map_bones` (names only, at the end) keeps the strict Mixamo / Rigify table for callers that have bone
names but no skeleton.  `map_skeleton` returns a Mapping: the bone of each joint (None for placed joints), the placed joints
with the bone they ride on and their rest position, and for each joint how it was found
("names:<family>", "topology", "interpolated", "derived").
"""
import itertools
import re
from dataclasses import dataclass, field

import numpy as np

from .errors import UserError

SMPL_JOINTS = ("pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle",
               "right_ankle", "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head",
               "left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist",
               "left_hand", "right_hand")
# where SMPL's spine joints sit along pelvis -> neck (fraction of that path; the roster bodies' template)
SPINE_FRACTIONS = {"spine1": 0.265, "spine2": 0.44, "spine3": 0.705}

_EXCLUDE = re.compile(r"(ik|fk|ctrl|ctl|control|controller|pole|target|tgt|twist|roll|leaf|end|nub|helper|hlp|"
                      r"aux|socket|slot|prop|weapon|attach|attachment|mch|org|wgt|corrective|dummy|null|"
                      r"ref|marker|locator|adjust|offset|pv|effector|goal|share|pad|jiggle|physics|"
                      r"dyn|spring|cloth|hair|skirt|cape|tail|ear|eye|jaw|tongue|teeth|lip|brow|cheek|"
                      r"nose|mouth|breast|bust|pec|butt|glute)\d*$")
_EXCLUDE_SUFFIX = re.compile(r"(ik|ctrl|ctl|twist|roll|end|leaf|slot|socket|target|pole|nub|helper)\d*$")
_PREFIX_TOKENS = {"mixamorig", "def", "j", "bip", "cc", "base", "skeleton", "joint", "jnt", "bone", "bn", "b",
                  "rig", "armature", "character", "char", "c", "m", "sk", "bind", "deform", "valvebiped",
                  "npc", "ue", "rootbone", "x", "g"}
_PREFIX_RE = re.compile(r"^(mixamorig\d*|bip\d+|biped\d*)$")
_SIDE = {"l": "left", "left": "left", "lft": "left", "r": "right", "right": "right", "rgt": "right"}

# part key (side removed, tokens joined) -> part; first match wins
_PARTS = [
    ("pelvis", r"(hips?|pelvis|hipbone|hipsbone|cog)"),
    ("neck", r"(neck\d*|necktwist0?1|neckbase|necklower|neckupper)"),
    ("head", r"(head)"),
    ("spine", r"(spine\d*|chest\d*|upperchest|chestlower|chestupper|abdomen\d*|abdomenupper|abdomenlower|torso|waist|belly|"
              r"stomach|back|lowerback|upperback|midback|spine(lower|upper|mid|low|up)|ribs|ribcage|thorax)"),
    ("collar", r"(clavicle|collar|collarbone|scapula)"),
    ("shoulder", r"(shoulder)"),
    ("upperarm", r"(upperarm|uparm|upperarms|humerus|armupper|bicep|arm|shldr)"),
    ("forearm", r"(forearm|lowerarm|lowarm|loarm|elbow|armlower|ulna|radius)"),
    ("wrist", r"(wrist)"),
    ("hand", r"(hand|fist|palm)"),
    ("thigh", r"(thigh|upleg|upperleg|uplegs|legupper|femur)"),
    ("hip", r"(hip)"),
    ("shin", r"(calf|shin|lowerleg|knee|leglower|crus|tibia)"),
    ("leg", r"(leg)"),
    ("ankle", r"(ankle)"),
    ("foot", r"(foot)"),
    ("toe", r"(toe|toes|toebase|ball|toe0|toes0|toe01|toesbase|football)"),
    ("middle1", r"(hand)?(f)?(middle|mid)(finger)?(0?1|proximal|a)|finger2|fingermiddle0?1"),
    ("index1", r"(hand)?(f)?(index|pointer)(finger)?(0?1|proximal|a)|finger1|fingerindex0?1"),
]
_PARTS = [(p, re.compile(f"^(?:{rx})$")) for p, rx in _PARTS]
_RIGIFY_SPINE = re.compile(r"^(?:def|org)?[-_.]?spine(?:\.(\d{3}))?$", re.IGNORECASE)


@dataclass
class Mapping:
    bone_of: dict                 # joint -> bone name (None for a placed joint)
    virtual: dict = field(default_factory=dict)  # joint -> (carrier bone, rest position (3,)), or ("toe", ankle
    #                                              bone) / ("hand", wrist bone): placed from the mesh by the caller
    how: dict = field(default_factory=dict)      # joint -> "names:<family>" | "topology" | "interpolated" | "derived"
    scheme: str = "names"


def tokens(name):
    """A bone name -> its lower-case tokens (namespace dropped, camelCase and digits split off)."""
    n = re.sub(r"^.*[:|]", "", name)
    n = re.sub(r"([a-z])([A-Z])", r"\1_\2", n)
    n = re.sub(r"([A-Z])([A-Z][a-z])", r"\1_\2", n)
    return [t.lower() for t in re.split(r"[\s_.\-]+", n) if t]


def family(name):
    """The naming family a bone name belongs to (for the meta)."""
    low = name.lower()
    for fam, rx in (("mixamo", r"mixamorig"), ("rigify", r"^(def|org)-"), ("biped", r"^bip\d+[ _]"),
                    ("vroid", r"^j_(bip|sec)_"), ("character_creator", r"^cc_base_"),
                    ("unreal", r"^(pelvis|spine_0\d|thigh_[lr]|calf_[lr]|upperarm_[lr]|clavicle_[lr]|neck_0\d)$"),
                    ("mixamo", r"^(hips|spine\d?|left(upleg|arm|forearm|hand|foot|shoulder)|neck|head)$"),
                    ("sketchfab", r"_\d+$")):
        if re.search(rx, low):
            return fam
    return "generic"


def classify(name):
    """(part, side) for a bone name, side in 'left', 'right', None; (None, None) for helpers and unknowns."""
    m = _RIGIFY_SPINE.match(name)
    if m and re.match(r"^(def|org)", name, re.IGNORECASE) or (m and m.group(1)):
        n = m.group(1)
        k = 0 if n is None else int(n)
        return ({0: "pelvis", 1: "spine", 2: "spine", 3: "spine", 4: "neck", 5: "neck2", 6: "head"}.get(k), None)
    toks = tokens(name)
    joined = "".join(t for t in toks if t not in _SIDE)
    if re.search(r"necktwist0?1$", joined):  # Character Creator's neck
        return "neck", None
    if _excluded(toks):
        return None, None
    side = None
    rest = []
    for i, t in enumerate(toks):
        s = _SIDE.get(t)
        if s is not None and side is None:
            side = s
            continue
        for word, sd in (("left", "left"), ("right", "right")):
            if side is None and t.startswith(word) and len(t) > len(word):
                side, t = sd, t[len(word):]
        rest.append(t)
    while rest and (rest[0] in _PREFIX_TOKENS or _PREFIX_RE.match(rest[0])) and len(rest) > 1:
        rest = rest[1:]
    rest = [t for t in rest if t not in ("joint", "jnt", "bone", "bn", "deform", "bend")] or rest
    keys = []
    for start in range(len(rest)):  # an unknown leading word (HumanIK's Character1_) is a prefix too
        tail = rest[start:]
        keys.append("".join(tail))
        if len(tail) > 1 and tail[-1].isdigit():
            keys.append("".join(tail[:-1]))
    for key in keys:
        for part, rx in _PARTS:
            if rx.match(key):
                if part == "pelvis" and side is not None:  # L_Hip (SMPL's own names) is a hip joint
                    return ("hip", side) if key in ("hip", "hips") else (None, None)
                return part, side
    return None, None


def _excluded(toks):
    return any(t != "bend" and (_EXCLUDE.match(t) or _EXCLUDE_SUFFIX.search(t)) for t in toks)  # Daz's *Bend bones


# ---------------------------------------------------------------- the tree

class _Tree:
    def __init__(self, bones):
        self.bones = {b["name"]: b for b in bones}
        self.parent = {b["name"]: b["parent"] if b["parent"] in self.bones else None for b in bones}
        self.children = {n: [] for n in self.bones}
        for n, p in self.parent.items():
            if p is not None:
                self.children[p].append(n)
        self.head = {n: np.asarray(b["head"], float) for n, b in self.bones.items()}
        self.tail = {n: np.asarray(b["tail"], float) for n, b in self.bones.items()}

    def ancestors(self, n):
        out = []
        while self.parent[n] is not None:
            n = self.parent[n]
            out.append(n)
        return out

    def depth(self, n):
        return len(self.ancestors(n))

    def is_below(self, n, anc):
        return anc in self.ancestors(n)

    def path(self, top, bottom):
        """Bones from top (exclusive) down to bottom (inclusive); None when bottom is not below top."""
        chain = [bottom]
        for a in self.ancestors(bottom):
            if a == top:
                return list(reversed(chain))
            chain.append(a)
        return None

    def lca(self, a, b):
        anc = [a] + self.ancestors(a)
        for x in [b] + self.ancestors(b):
            if x in anc:
                return x
        return None

    def descendants(self, n):
        out, stack = [], list(self.children[n])
        while stack:
            c = stack.pop()
            out.append(c)
            stack.extend(self.children[c])
        return out

    def length(self, n):
        return float(np.linalg.norm(self.tail[n] - self.head[n]))


# ---------------------------------------------------------------- by names

def _by_names(tree, usable):
    """{(part, side): bone} from the names of the usable bones (the shallowest bone of each)."""
    found = {}
    for n in usable:
        part, side = classify(n)
        if part is None:
            continue
        if part in ("pelvis", "spine", "neck", "neck2", "head"):
            side = None
        elif side is None:
            continue
        key = (part, side)
        found.setdefault(key, []).append(n)
    pick = {}
    for key, names in found.items():
        if key[0] in ("spine", "neck", "neck2"):
            pick[key] = sorted(names, key=tree.depth)
        else:
            pick[key] = min(names, key=lambda x: (tree.depth(x), x))
    out = {"spine": pick.get(("spine", None), []), "neck": pick.get(("neck", None), []) +
           pick.get(("neck2", None), [])}
    for k in ("pelvis", "head"):
        if (k, None) in pick:
            out[k] = pick[(k, None)]
    for side in ("left", "right"):
        g = lambda p: pick.get((p, side))  # noqa: E731
        s = {}
        if g("thigh") or g("hip"):  # Mixamo: UpLeg + Leg
            s["thigh"], s["shin"] = g("thigh") or g("hip"), g("shin") or g("leg")
        else:  # "Left leg" + "Left shin"
            s["thigh"], s["shin"] = g("leg"), g("shin")
        if g("ankle"):
            s["ankle"], s["toe"] = g("ankle"), g("toe") or g("foot")
        else:
            s["ankle"], s["toe"] = g("foot"), g("toe")
        s["upperarm"] = g("upperarm")
        s["collar"] = g("collar")
        if g("shoulder"):
            if s["upperarm"] and tree.is_below(s["upperarm"], g("shoulder")) and not s["collar"]:
                s["collar"] = g("shoulder")
            elif not s["upperarm"]:
                s["upperarm"] = g("shoulder")
        s["forearm"] = g("forearm")
        if g("wrist"):
            s["wrist"], s["hand"] = g("wrist"), g("middle1") or g("index1") or g("hand")
        else:
            s["wrist"], s["hand"] = g("hand"), g("middle1") or g("index1")
        out[side] = s
    return out


# ---------------------------------------------------------------- by topology

def _long_bones(tree, chain, min_len):
    return [b for b in chain if tree.length(b) >= min_len or
            (tree.children[b] and np.linalg.norm(tree.head[tree.children[b][0]] - tree.head[b]) >= min_len)]


def _seg_len(tree, b):
    """A bone's extent: head to its first child's head, else its own length."""
    kids = tree.children[b]
    return max([tree.length(b)] + [float(np.linalg.norm(tree.head[c] - tree.head[b])) for c in kids])


def _by_topology(tree, usable, body_z=None):
    """The same structure as _by_names, found from the tree's shape; None when it has no person's shape."""
    use = set(usable)
    leaves = [n for n in use if not any(c in use for c in tree.descendants(n))]
    if len(leaves) < 5:
        return None
    pts = np.array([tree.head[n] for n in use] + [tree.tail[n] for n in use])
    height = float(pts[:, 2].max() - pts[:, 2].min())
    if height <= 0:
        return None
    # the side-to-side axis: the widest horizontal direction of the skeleton (arms out or down, feet apart)
    heads = np.array([tree.head[n] for n in use])
    centre = np.median(heads, axis=0)
    xy = heads[:, :2] - centre[:2]
    _, _, vt = np.linalg.svd(xy, full_matrices=False)
    lateral = np.array([vt[0, 0], vt[0, 1], 0.0])
    x_of = lambda p: float((np.asarray(p) - centre) @ lateral)  # noqa: E731
    low = lambda n: min(tree.head[n][2], tree.tail[n][2])  # noqa: E731
    leaves_low = sorted(leaves, key=low)
    feet = None
    for a, b in itertools.combinations(leaves_low[:6], 2):
        if x_of(tree.head[a]) * x_of(tree.head[b]) < 0 and tree.lca(a, b) is not None:
            feet = (a, b)
            break
    if feet is None:
        return None
    pelvis = tree.lca(*feet)
    if pelvis in feet:
        return None
    legs = [tree.path(pelvis, f) for f in feet]
    if any(len(_long_bones(tree, lg, 0.12 * height)) < 2 for lg in legs):
        return None
    # the thighs may hang from the first spine bone (3ds Max Biped): the pelvis is then its parent,
    # whose head is nearer the hip joints
    hips_z = np.mean([tree.head[_long_bones(tree, lg, 0.12 * height)[0]][2] for lg in legs])
    par = tree.parent[pelvis]
    if par is not None and par in use and abs(tree.head[par][2] - hips_z) < abs(tree.head[pelvis][2] - hips_z):
        legs = [tree.path(par, f) for f in feet]
        legs = [[b for b in lg if b != pelvis] for lg in legs]
        pelvis = par
    # the head: the highest point reached through a child of the pelvis that is not on a leg
    first_leg = {lg[0] for lg in legs}
    up_roots = [c for c in tree.children[pelvis] if c in use and c not in first_leg] or \
        ([pelvis] if tree.parent[pelvis] is None else [])
    upper = [d for r in up_roots for d in [r] + tree.descendants(r) if d in use]
    if not upper:
        return None
    top = max(upper, key=lambda n: max(tree.head[n][2], tree.tail[n][2]))
    spine_path = tree.path(pelvis, top) or []
    # arms: the two usable leaves above the pelvis reaching furthest sideways, on opposite sides
    up_leaves = [n for n in upper if n in leaves]
    wide = sorted(up_leaves, key=lambda n: -max(abs(x_of(tree.head[n])), abs(x_of(tree.tail[n]))))
    hands = None
    for a, b in itertools.combinations(wide[:8], 2):
        if x_of(tree.tail[a]) * x_of(tree.tail[b]) < 0:
            hands = (a, b)
            break
    if hands is None:
        return None
    branch = tree.lca(*hands)
    if branch is None or branch not in [pelvis] + spine_path:
        return None
    out = {"pelvis": pelvis}
    on_spine = set(spine_path)
    arms = []
    for h in hands:
        path = tree.path(branch, h)
        arm = []
        for b in path:
            if b not in on_spine:
                arm.append(b)
        arms.append(arm)
    # forward: heel -> toe of the feet (the leg chain's last long bone onward)
    fwd = np.zeros(3)
    for lg in legs:
        shin = _long_bones(tree, lg, 0.12 * height)[1]
        after = lg[lg.index(shin) + 1:]
        fwd += (tree.head[after[-1]] - tree.head[after[0]]) if len(after) > 1 else \
            (tree.tail[lg[-1]] - tree.head[lg[-1]])
    fwd[2] = 0
    if np.linalg.norm(fwd) < 1e-9:
        return None
    right = np.cross(fwd / np.linalg.norm(fwd), [0.0, 0.0, 1.0])
    sides = {}
    for lg in legs:
        side = "right" if (tree.head[lg[0]] - tree.head[pelvis]) @ right > 0 else "left"
        long = _long_bones(tree, lg, 0.12 * height)
        thigh, shin = long[0], long[1]
        after = lg[lg.index(shin) + 1:]
        s = sides.setdefault(side, {})
        s.update(thigh=thigh, shin=shin, ankle=after[0] if after else None, toe=after[1] if len(after) > 1 else None)
    for arm in arms:
        if not arm:
            return None
        side = "right" if (tree.tail[arm[-1]] - tree.head[branch]) @ right > 0 else "left"
        segs = [b for b in arm if _seg_len(tree, b) >= 0.08 * height]
        if len(segs) < 2:
            return None
        # upper arm and forearm: the two longest consecutive segments
        best = max(range(len(segs) - 1), key=lambda i: _seg_len(tree, segs[i]) + _seg_len(tree, segs[i + 1]))
        ua, fa = segs[best], segs[best + 1]
        i_fa = arm.index(fa)
        rest = arm[i_fa + 1:]
        i_ua = arm.index(ua)
        hand = rest[1] if len(rest) > 1 else None
        kids = [c for c in tree.children[rest[0]] if c in use] if rest else []
        if len(kids) >= 3:  # fingers: the middle one, nearest the fingers' mean base
            mean = np.mean([tree.head[c] for c in kids], axis=0)
            hand = min(kids, key=lambda c: float(np.linalg.norm(tree.head[c] - mean)))
        s = sides.setdefault(side, {})
        s.update(upperarm=ua, forearm=fa, collar=arm[i_ua - 1] if i_ua > 0 else None,
                 wrist=rest[0] if rest else None, hand=hand)
    if set(sides) != {"left", "right"}:
        return None
    out.update(sides)
    above = [b for b in spine_path if tree.depth(b) > tree.depth(branch)]
    out["spine"] = [b for b in spine_path if b not in above]
    soles, crown = body_z if body_z is not None else (float(pts[:, 2].min()), float(pts[:, 2].max()))
    # the head joint sits at the skull's base: at least 8 % of the body's height below its crown
    cands = [b for b in [branch] + above if tree.head[b][2] <= crown - 0.08 * (crown - soles)]
    head = max(cands, key=lambda b: tree.head[b][2]) if cands else None
    if head is None or head == branch:
        return None
    out["head"] = head
    out["neck"] = [tree.parent[head]] if tree.parent[head] in above else []
    return out


# ---------------------------------------------------------------- the 24 joints

def _assemble(tree, parts, how_found, what, usable):
    """{joint: bone}, virtual joints and provenance from the parts found (by names or topology)."""
    bone_of = {j: None for j in SMPL_JOINTS}
    virtual, how = {}, {}
    missing = []

    def put(joint, bone):
        bone_of[joint] = bone
        how[joint] = how_found

    pelvis = parts.get("pelvis")
    sides = {s: parts.get(s) or {} for s in ("left", "right")}
    if pelvis is None and sides["left"].get("thigh") and sides["right"].get("thigh"):
        pelvis = tree.lca(sides["left"]["thigh"], sides["right"]["thigh"])
        if pelvis in (sides["left"]["thigh"], sides["right"]["thigh"]):
            pelvis = None
    for side, s in sides.items():
        for part, joint in (("thigh", "hip"), ("shin", "knee"), ("ankle", "ankle"), ("upperarm", "shoulder"),
                            ("forearm", "elbow"), ("wrist", "wrist")):
            if not s.get(part):
                missing.append(f"{side}_{joint}")
    if pelvis is None:
        missing.insert(0, "pelvis")
    head = parts.get("head")
    if head is None:
        missing.append("head")
    if missing:
        return None, missing
    for side, s in sides.items():  # each limb must hang down its own chain
        for a, b in (("thigh", "shin"), ("shin", "ankle"), ("upperarm", "forearm"), ("forearm", "wrist")):
            if not tree.is_below(s[b], s[a]):
                raise UserError(f"{what}: bone '{s[b]}' ({side} {b}) is not below '{s[a]}' ({side} {a}) "
                                f"in the hierarchy: not a humanoid rig")
    put("pelvis", pelvis)
    for side, s in sides.items():
        put(f"{side}_hip", s["thigh"])
        put(f"{side}_knee", s["shin"])
        put(f"{side}_ankle", s["ankle"])
        put(f"{side}_shoulder", s["upperarm"])
        put(f"{side}_elbow", s["forearm"])
        put(f"{side}_wrist", s["wrist"])
        toe = s.get("toe")
        if toe and tree.is_below(toe, s["ankle"]):
            put(f"{side}_foot", toe)
        else:
            virtual[f"{side}_foot"] = ("toe", s["ankle"])
            how[f"{side}_foot"] = "derived"
        hand = s.get("hand")
        if hand and tree.is_below(hand, s["wrist"]):
            put(f"{side}_hand", hand)
        else:  # placed from the hand's mesh by the caller (rider_rig), like a toe
            virtual[f"{side}_hand"] = ("hand", s["wrist"])
            how[f"{side}_hand"] = "derived"
    # the torso: the path pelvis -> head
    path = tree.path(pelvis, head)
    if path is None:
        raise UserError(f"{what}: the head bone '{head}' is not below the pelvis bone '{pelvis}': not a humanoid rig")
    use = set(usable)
    chain = [b for b in path[:-1] if b in use]
    named_neck = [b for b in chain if b in set(parts.get("neck") or [])]
    arm_roots = [sides[s].get("collar") or sides[s]["upperarm"] for s in sides]
    branch = tree.lca(*arm_roots)
    if named_neck:
        neck = named_neck[0]
    else:
        above = [b for b in chain if branch is not None and tree.depth(b) > tree.depth(branch)]
        neck = above[0] if above else None
        if neck is None and len(chain) >= 2 and chain[-1] == branch:
            # the arms hang from the neck itself (Biped's clavicles): a branch 80 % of the way up is the neck
            span = tree.head[head] - tree.head[pelvis]
            if span @ span > 0 and (tree.head[branch] - tree.head[pelvis]) @ span / (span @ span) >= 0.8:
                neck = branch
    spine = chain[:chain.index(neck)] if neck else list(chain)
    if neck:
        put("neck", neck)
    put("head", head)
    # spine1..3 by their place along pelvis -> neck
    P0 = tree.head[pelvis]
    top = tree.head[neck] if neck else tree.head[head]
    pts = [P0] + [tree.head[b] for b in spine] + [top]
    seg = [float(np.linalg.norm(b - a)) for a, b in zip(pts, pts[1:])]
    total = sum(seg) or 1.0
    frac = np.cumsum([0.0] + seg) / total  # of pelvis, spine bones..., neck
    slots = list(SPINE_FRACTIONS)
    k = len(spine)
    if k >= 3:
        best = min(itertools.combinations(range(k), 3),
                   key=lambda c: sum(abs(frac[1 + i] - SPINE_FRACTIONS[s]) for i, s in zip(c, slots)))
        for i, s in zip(best, slots):
            put(s, spine[i])
    else:
        best = min(itertools.combinations(range(3), k),
                   key=lambda c: sum(abs(frac[1 + i] - SPINE_FRACTIONS[slots[c_i]]) for i, c_i in enumerate(c)))
        real = {slots[c]: spine[i] for i, c in enumerate(best)}
        for s in slots:
            if s in real:
                put(s, real[s])
                continue
            f = SPINE_FRACTIONS[s]
            i = int(np.searchsorted(frac, f, side="right") - 1)
            i = min(max(i, 0), len(pts) - 2)
            t = (f - frac[i]) / max(frac[i + 1] - frac[i], 1e-9)
            p = pts[i] + t * (pts[i + 1] - pts[i])
            carrier = ([pelvis] + spine)[min(i, len(spine))]
            virtual[s] = (carrier, p)
            how[s] = "interpolated"
    # spine3's position (real or placed) for the neck and collars
    s3 = tree.head[bone_of["spine3"]] if bone_of["spine3"] else virtual["spine3"][1]
    if not neck:
        p = s3 + 0.6 * (tree.head[head] - s3)
        virtual["neck"] = (bone_of["spine3"] or virtual["spine3"][0], p)
        how["neck"] = "interpolated"
    neck_p = tree.head[neck] if neck else virtual["neck"][1]
    for side, s in sides.items():
        collar = s.get("collar")
        if collar and tree.is_below(s["upperarm"], collar) and collar not in path:
            put(f"{side}_collar", collar)
        else:
            par = tree.parent[s["upperarm"]]
            if par is not None and par not in path and par != pelvis and tree.is_below(par, pelvis):
                put(f"{side}_collar", par)
                how[f"{side}_collar"] = "topology"
            else:
                p = 0.5 * (s3 + neck_p)
                p = p + 0.15 * (tree.head[s["upperarm"]] - p)
                virtual[f"{side}_collar"] = (par or bone_of["spine3"] or virtual["spine3"][0], p)
                how[f"{side}_collar"] = "interpolated"
    return (bone_of, virtual, how), []


def usable_bones(bones):
    """Names of the bones that may be joints: deforming (when any bone is marked non-deforming) and not
    helpers by name."""
    deform = [b for b in bones if b.get("deform", True)]
    pool = deform if len(deform) >= 10 else bones
    out = []
    for b in pool:
        if _excluded(tokens(b["name"])) and classify(b["name"])[0] is None:
            continue
        out.append(b["name"])
    return out


def map_skeleton(bones, what="armature", body_z=None):
    """bones: [{"name", "parent", "head" (3,), "tail" (3,), "deform"}] in world coordinates with +Z up
    (Blender's importers) -> Mapping.  body_z: (lowest, highest) Z of the skinned mesh, when known (the
    shape fallback finds the head below the crown with it).  UserError (one line) when neither the names nor the shape make
    a humanoid."""
    tree = _Tree(bones)
    usable = usable_bones(bones)
    names = _by_names(tree, usable)
    fams = {}
    for n in usable:
        if classify(n)[0] is not None:
            f = family(n)
            fams[f] = fams.get(f, 0) + 1
    fams.pop("generic", None)
    fam = max(fams, key=fams.get) if fams else "generic"
    names_error = None
    try:
        res, missing = _assemble(tree, names, f"names:{fam}", what, usable)
    except UserError as e:  # names that contradict the hierarchy: the shape may still make sense of it
        res, missing, names_error = None, [], e
    if res is None:
        topo = _by_topology(tree, usable, body_z)
        if topo is not None:
            # names that were found still win over the shape for their joints
            for side in ("left", "right"):
                for k, v in (names.get(side) or {}).items():
                    if v and not topo[side].get(k):
                        topo[side][k] = v
            try:
                res, missing2 = _assemble(tree, topo, "topology", what, usable)
            except UserError:
                res, missing2 = None, missing
            fam = "topology"
    if res is None and names_error is not None:
        raise names_error
    if res is None:
        found = 24 - len(missing)
        sample = ", ".join(sorted(b["name"] for b in bones)[:8]) or "none"
        if len(missing) > 8:
            raise UserError(f"{what}: not a humanoid rig of a known naming scheme (Mixamo, Rigify, Unreal/MPFB, "
                            f"Biped, VRoid, CC, Blender .L/.R) nor of a person's shape (two legs, two arms, a "
                            f"head): {found} of 24 SMPL joints found by name; its bones include {sample}")
        raise UserError(f"{what}: humanoid rig without bones for SMPL joints {', '.join(missing)} "
                        f"(its bones include {sample})")
    bone_of, virtual, how = res
    return Mapping(bone_of=bone_of, virtual=virtual, how=how, scheme=fam)


# ---------------------------------------------------------------- names only, two schemes (no skeleton at hand)
# The strict table of the two most common schemes, for callers that have bone names but no skeleton:
# every joint must have its Mixamo or Rigify bone (no placing, no shape fallback).

def _sided(table, left, right):
    """{joint: names} with 'left_x'/'right_x' entries made from one template per side."""
    out = {}
    for joint, names in table.items():
        if joint.startswith("side_"):
            base = joint[len("side_"):]
            out["left_" + base] = tuple(n.format(S=left[0], s=left[1]) for n in names)
            out["right_" + base] = tuple(n.format(S=right[0], s=right[1]) for n in names)
        else:
            out[joint] = names
    return out


SCHEMES = {
    "mixamo": _sided({
        "pelvis": ("Hips",), "spine1": ("Spine",), "spine2": ("Spine1",), "spine3": ("Spine2",),
        "neck": ("Neck",), "head": ("Head",),
        "side_hip": ("{S}UpLeg",), "side_knee": ("{S}Leg",), "side_ankle": ("{S}Foot",), "side_foot": ("{S}ToeBase",),
        "side_collar": ("{S}Shoulder",), "side_shoulder": ("{S}Arm",), "side_elbow": ("{S}ForeArm",),
        "side_wrist": ("{S}Hand",), "side_hand": ("{S}HandMiddle1", "{S}HandIndex1"),
    }, ("Left", "L"), ("Right", "R")),
    "rigify": _sided({
        "pelvis": ("DEF-spine",), "spine1": ("DEF-spine.001",), "spine2": ("DEF-spine.002",),
        "spine3": ("DEF-spine.003",), "neck": ("DEF-spine.004",), "head": ("DEF-spine.006",),
        "side_hip": ("DEF-thigh.{s}",), "side_knee": ("DEF-shin.{s}",), "side_ankle": ("DEF-foot.{s}",),
        "side_foot": ("DEF-toe.{s}",), "side_collar": ("DEF-shoulder.{s}",), "side_shoulder": ("DEF-upper_arm.{s}",),
        "side_elbow": ("DEF-forearm.{s}",), "side_wrist": ("DEF-hand.{s}",),
        "side_hand": ("DEF-f_middle.01.{s}", "DEF-f_index.01.{s}"),
    }, ("Left", "L"), ("Right", "R")),
}

_PREFIX = re.compile(r"^(?:[^:]*:|mixamorig\d*_)", re.IGNORECASE)


def _key(name):
    return _PREFIX.sub("", name).lower()


def map_bones(bone_names, what="armature"):
    """Bone names of one armature -> {SMPL joint: bone name}, with the scheme that matched most.

    UserError (one line) when fewer than half the joints match any scheme ("not a humanoid rig") or
    when some joints have no bone (they are named, with the names looked for)."""
    by_key = {}
    for n in bone_names:
        by_key.setdefault(_key(n), n)
    best = None
    for scheme, table in SCHEMES.items():
        found = {j: next((by_key[_key(c)] for c in table[j] if _key(c) in by_key), None) for j in SMPL_JOINTS}
        score = sum(v is not None for v in found.values())
        if best is None or score > best[2]:
            best = (scheme, found, score)
    scheme, found, score = best
    if score < len(SMPL_JOINTS) // 2:
        sample = ", ".join(sorted(bone_names)[:8]) or "none"
        raise UserError(f"{what}: not a humanoid rig of a known naming scheme ({', '.join(SCHEMES)}): "
                        f"{score} of 24 SMPL joints found; its bones include {sample}")
    missing = [j for j in SMPL_JOINTS if found[j] is None]
    if missing:
        looked = "; ".join(f"{j} ({'/'.join(SCHEMES[scheme][j])})" for j in missing)
        raise UserError(f"{what}: {scheme} rig without bones for SMPL joints {looked}")
    return dict(found), scheme
