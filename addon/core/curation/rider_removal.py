"""A rider (a person or a robot sitting on the bike) found by geometry and dropped before the
keypoints (numpy, no bpy).  Works per mesh component in the canonical frame (metres, wheel
diameter D); object names are never looked at.

1. Seeds: a person reaches 2.1-3.5 D high (a bike alone stays below ~2 D; a kick scooter's stem
   is far taller and thin).  The pieces wholly above 1.75 D (head, torso; not a handlebar: wide
   across and thin) are the rider, and so is one piece reaching that high whose top is a solid
   body (a one-mesh person: the part above 1.75 D is deep, wide and thick, unlike a windscreen
   or high bars).
2. Body: grown through touching thick pieces (arms, thighs, hips: thicker than a tenth of a
   wheel, which no tube, saddle or bar is) whose middle is above the wheel tops and which hang to
   one side or are short (a torso or hip; a motorcycle's tank, seat and body are as thick but
   centred and long), and which are not wholly in the steering column ahead of the rider (a
   stem, a basket or a headlamp the hands touch).
3. Limbs: grown on from the body through pieces that touch it (surface within ~2 cm) and lie
   wholly to one side of the bike's plane (shins, knees, feet, hands): not a piece fastened to
   the bike's centre (a crank arm on its axle, a grip or lever on the bar, a footpeg, a stand),
   not a wheel, and not a pedal (a small flat plate under the foot).
"""
import numpy as np

from .contacts import Touch
from .shape_keypoints import steering_axis

HIGH = 1.75          # wheel diameters: wholly above this is head or torso
PERSON_D = 0.6       # metres: the least "wheel diameter" the person's proportions are measured in


def _solid_top(q, D):
    """A one-piece person (q: its surface samples): the part of the piece above HIGH*D is a
    body (deep along the bike, wide across it and thick in every direction), not a windscreen,
    a bar or a stem."""
    top = q[q[:, 1] > HIGH * D]
    if len(top) < 8:
        return False
    ext = top.max(0) - top.min(0)
    if ext[0] < 0.2 * D or ext[2] < 0.2 * D:
        return False
    c = top - top.mean(0)
    thin = np.ptp(c @ np.linalg.svd(c, full_matrices=False)[2][2])
    return thin > 0.15 * D


class _Pieces:
    """The kept components in the canonical frame: bounding boxes, the surface contacts and the
    bike's landmarks the steps share."""

    def __init__(self, soup, pose, idx, P, D, wheel_D=None):
        self.idx, self.D = idx, D
        self.local = {i: j for j, i in enumerate(idx)}
        pts = [P[soup.comps[i].verts] for i in idx]
        self.lo = np.array([q.min(0) for q in pts])
        self.hi = np.array([q.max(0) for q in pts])
        self.fa, self.ra = pose.apply(pose.front.centre), pose.apply(pose.rear.centre)
        self.touch = Touch(P, soup.TW, {i: soup.comps[i] for i in idx}, max(0.02, 0.025 * D))
        lo, hi, R = self.lo, self.hi, 0.5 * (wheel_D or D)
        self.lateral = (lo[:, 2] > 0.04 * D) | (hi[:, 2] < -0.04 * D)
        self.wheel = np.zeros(len(idx), bool)
        for c in (self.fa, self.ra):   # tyres, rims, spokes, hubs: within the wheel disc, near its plane
            far = np.maximum(np.abs(lo[:, :2] - c[:2]), np.abs(hi[:, :2] - c[:2]))
            self.wheel |= (np.hypot(far[:, 0], far[:, 1]) < 1.1 * R) & (np.maximum(-lo[:, 2], hi[:, 2]) < 0.4 * R)
        # the steering column: a stem, basket or lamp wholly ahead of where a rider's body can
        # be, and what is fastened to it (a toy bike's thick bar halves)
        self.column = lo[:, 0] > self.fa[0] - 0.4 * D
        # on small wheels (D raised to the person's measure), also ahead of the steering axis'
        # line less 0.3 D where the shape shows one: a motor scooter's stem leans its bar 30 cm
        # behind the front axle, where a seated rider's hands are (on a bicycle's or a
        # motorcycle's wheels the rider's head and arms come as close to that line)
        axis = None
        if wheel_D is not None and wheel_D < D:
            X = np.concatenate([self.touch.samples[i] for i in idx])
            axis = steering_axis(X, self.fa, R)
        if axis is not None:
            sb, st = axis
            ymid = 0.5 * (lo[:, 1] + hi[:, 1])
            x_at = sb[0] + (ymid - sb[1]) * (st[0] - sb[0]) / max(st[1] - sb[1], 1e-9)
            along = (lo[:, 0] > x_at - 0.3 * D) & (ymid > self.fa[1])
            self.column |= along
            # the bar itself, up to the stem's top: never a head or torso (a scooter's bar halves
            # sit 1.3 m up, above 1.75 of a small-wheeled vehicle's D)
            self.bar_top = along & (hi[:, 1] < st[1] + 0.1 * D)
        else:
            self.bar_top = np.zeros(len(idx), bool)
        self.on_column = self.mask(self.touch.touching(self.global_(self.column)))
        # the frame's stays, the fork legs, axle nuts: lateral pieces reaching a wheel's hub
        self.at_hub = np.zeros(len(idx), bool)
        for c in (self.fa, self.ra):
            near = np.maximum(lo[:, :2] - c[:2], np.maximum(c[:2] - hi[:, :2], 0.0))
            self.at_hub |= self.lateral & (np.hypot(near[:, 0], near[:, 1]) < 0.3 * R)

    def global_(self, mask):
        return [self.idx[j] for j in np.nonzero(mask)[0]]

    def mask(self, comps):
        m = np.zeros(len(self.idx), bool)
        m[[self.local[i] for i in comps]] = True
        return m

    def neighbours(self, j):
        return [self.local[t] for t in self.touch.touching([self.idx[j]])]


def drop_rider(soup, pose):
    """Bool per soup component: the rider's pieces (all False when there is none)."""
    P = soup.transformed_points(pose.M)
    wheel_D = 2 * 0.5 * (pose.front.radius + pose.rear.radius) * pose.scale
    # the person's measure: a bicycle's wheel, or 0.6 m on small-wheeled vehicles (a motor
    # scooter's 0.46 m wheels put a seated person 4 wheel diameters up, a bicycle's rider 3)
    D = max(wheel_D, PERSON_D)
    out = np.zeros(len(soup.comps), bool)
    idx = [i for i, k in enumerate(pose.keep) if k]
    if not idx:
        return out
    hi_all = np.array([P[soup.comps[i].verts][:, 1].max() for i in idx])
    if not (2.1 * D < hi_all.max() < 3.5 * D):
        return out
    pc = _Pieces(soup, pose, idx, P, D, wheel_D)
    lo, hi = pc.lo, pc.hi
    # a handlebar may sit that high (a motorcycle's): wide across and thin, unlike a person
    bar_like = (hi[:, 2] - lo[:, 2] > 0.5 * D) & ((hi - lo).min(1) <= 0.1 * D)
    # plates and rods up there (a triple clamp, bar risers, a windscreen) are not a head or torso
    solid = (hi - lo).min(1) >= 0.06 * D
    high = ((lo[:, 1] > HIGH * D) & ~bar_like & solid & ~pc.bar_top) \
        | np.array([h > HIGH * D and lw < HIGH * D and not b and _solid_top(pc.touch.samples[i], D)
                    for i, lw, h, b in zip(idx, lo[:, 1], hi[:, 1], bar_like)])
    # a person shows a head and shoulders above HIGH*D: as wide as 0.2 D and reaching 0.25 D up
    if not high.any() or (hi[high, 2] - lo[high, 2]).max() < 0.2 * D or hi[high, 1].max() < (HIGH + 0.25) * D:
        return out
    rider = _body(pc, high)
    rider |= _limbs(pc, rider)
    rider |= _straddling(pc, rider)
    rider |= _surrounded(pc, rider)
    rider |= _hanging(pc, rider)
    out[np.array(idx)[rider]] = True
    return out


def _body(pc, high):
    """Step 2: the seeds grown through touching (bounding boxes) thick pieces, not those on the
    steering column."""
    lo, hi, D = pc.lo, pc.hi, pc.D
    mid = 0.5 * (lo[:, 1] + hi[:, 1])
    thick = (hi - lo).min(1) > 0.1 * D
    side = np.abs(0.5 * (lo[:, 2] + hi[:, 2])) > 0.25 * (hi[:, 2] - lo[:, 2])
    # short, or a chunky blob up to 0.7 D long (hips: as high and wide as half their length;
    # a tank, a motorcycle seat or a frame tube is longer for its height or width)
    ext = hi - lo
    short = (ext[:, 0] < 0.6 * D) | ((ext[:, 0] < 0.7 * D) & (ext.min(1) >= 0.55 * ext.max(1)))
    # a handlebar assembly (bar, headset, lamp in one piece) at the top of a stem leaning far
    # back, behind the column test's line: wider than 0.8 D, centred, in the front half
    bars = (hi[:, 2] - lo[:, 2] > 0.8 * D) & (np.abs(hi[:, 2] + lo[:, 2]) < 0.2 * (hi[:, 2] - lo[:, 2])) \
        & (0.5 * (lo[:, 0] + hi[:, 0]) > 0.5 * (pc.fa[0] + pc.ra[0]))
    ok = (mid > 1.1 * D) & thick & (side | short) & ~pc.column & ~(pc.on_column & ~high) & ~(bars & ~high)
    grow = high.copy()
    gap = 0.08 * D
    frontier = list(np.nonzero(high)[0])
    while frontier:
        f = np.array(frontier)
        ov = np.all((lo[None] <= hi[f][:, None] + gap) & (hi[None] >= lo[f][:, None] - gap), axis=2).any(0)
        new = np.nonzero(ov & ~grow & ok)[0]
        grow[new] = True
        frontier = list(new)
    return grow


def _limbs(pc, body):
    """Step 3: pieces wholly to one side of the bike's plane, touching the rider, not fastened
    to the bike's centre, not a wheel, not a pedal."""
    lo, hi, D, R = pc.lo, pc.hi, pc.D, 0.5 * pc.D
    core = ~pc.lateral & ~pc.wheel & ~body
    ext = hi - lo
    # a pedal or a grip: small and thin against its size; a foot or a shoe is longer, a
    # robot's foot piece thicker
    pedal = (ext.max(1) < 0.2 * D) & (ext.min(1) < 0.3 * ext.max(1))
    cand = pc.lateral & ~pc.wheel & ~body & ~pedal
    grown = np.zeros(len(pc.idx), bool)
    if not cand.any():
        return grown
    # fastened to the bike: touching its centre pieces, or a thin plate low down (a crank arm,
    # a chainring) reached from them through other such plates; a foot on a crank arm is not
    axle_y = max(pc.fa[1], pc.ra[1])
    plate = pc.lateral & ~body & (ext[:, 2] < 0.08 * D) & (hi[:, 1] < axle_y + 0.6 * R)
    fastened = np.zeros(len(pc.idx), bool)
    frontier, first = pc.global_(core), True
    while frontier:
        new = [pc.local[t] for t in pc.touch.touching(frontier)]
        new = [j for j in new if pc.lateral[j] and not fastened[j] and not body[j] and (first or plate[j])]
        fastened[new] = True
        frontier = [pc.idx[j] for j in new if plate[j]]
        first = False
    # a thigh on the body is the rider's even where it touches the saddle or the top tube (a
    # crank arm under a one-piece person's shoe is not)
    frontier, first = pc.global_(body), True
    while frontier:
        new = [pc.local[t] for t in pc.touch.touching(frontier)]
        new = [j for j in new if cand[j] and not grown[j] and not pc.at_hub[j]
               and not (fastened[j] and (plate[j] or not first))]
        first = False
        grown[new] = True
        frontier = [pc.idx[j] for j in new]
    return grown


def _straddling(pc, rider):
    """Step 3b: a rider's lower body as one piece (hips and both legs of a low-poly or skinned
    person, left on the saddle when the torso went): touching the rider, reaching from below the
    wheel tops to above 1.5 D, wider than 0.45 D across, its surface mostly beside the bike's
    plane on both sides (legs astride the frame, two apart at knee height) and little of it on
    the plane.  A motor scooter's leg shield is as wide but runs across the plane.  A motorcycle's
    tank, seat or body is narrower or centred; a handlebar is on the steering column; a rack's
    panniers stay low.  (It may touch the bar: hands and legs in one skinned piece.)"""
    lo, hi, D = pc.lo, pc.hi, pc.D
    near = pc.mask(pc.touch.touching(pc.global_(rider)))
    cand = near & ~rider & ~pc.wheel & ~pc.column & (hi[:, 1] > 1.5 * D) & (lo[:, 1] < 1.1 * D) \
        & (hi[:, 2] - lo[:, 2] > 0.45 * D)
    out = np.zeros(len(pc.idx), bool)
    for j in np.nonzero(cand)[0]:
        S = pc.touch.samples[pc.idx[j]]
        z = S[:, 2]
        if len(z) < 20:
            continue
        left, right, central = (z < -0.15 * D).mean(), (z > 0.15 * D).mean(), (np.abs(z) < 0.1 * D).mean()
        if left >= 0.2 and right >= 0.2 and left + right >= 0.5 and central <= 0.3 and _two_legs(S, D):
            out[j] = True
    return out


def _two_legs(S, D):
    """Between knee and thigh height, horizontal slices of legs astride a frame are two
    separate groups, left and right, with nothing on the bike's plane between them (the frame
    is another piece); a leg shield or a body panel runs across the plane at every height."""
    y0, y1 = S[:, 1].min(), S[:, 1].max()
    split_ = 0
    for a in np.linspace(0.1, 0.7, 12):
        z = S[(S[:, 1] >= y0 + a * (y1 - y0)) & (S[:, 1] < y0 + (a + 0.05) * (y1 - y0)), 2]
        if len(z) >= 10 and (z < -0.06 * D).any() and (z > 0.06 * D).any() and not (np.abs(z) < 0.06 * D).any():
            split_ += 1
    # a foot may hang lower than the other and the hips join them: two slices are enough
    return split_ >= 2


def _surrounded(pc, rider):
    """Step 4: a small piece above the wheel tops, away from the steering column, that touches three
    or more rider pieces and at least twice as many as bike pieces (those reached from the
    wheels without passing through such pieces) is the rider's: a robot's hip joint between its
    thighs and pelvis.  A saddle under a person touches one body or two thighs, and its post."""
    mid = 0.5 * (pc.lo[:, 1] + pc.hi[:, 1])
    # small: a saddle (25 cm and more), a tank or a motorcycle seat between the thighs is not
    small = (pc.hi - pc.lo).max(1) < 0.3 * pc.D
    cand = (mid > 1.1 * pc.D) & small & ~pc.column & ~pc.on_column & ~rider & ~pc.wheel
    reached = pc.wheel & ~rider
    frontier = pc.global_(reached)
    while frontier:
        new = [j for j in (pc.local[t] for t in pc.touch.touching(frontier)) if not reached[j] and not rider[j]]
        reached[new] = True
        frontier = [pc.idx[j] for j in new if not cand[j]]
    out = rider.copy()
    for j in np.nonzero(cand)[0]:
        nb = pc.neighbours(j)
        r = sum(bool(rider[k]) for k in nb)
        b = sum(bool(reached[k]) for k in nb)
        if r >= 3 and r >= 2 * b:
            out[j] = True
    return out


def _hanging(pc, rider):
    """Step 5: what the rider's removal left hanging.  Pieces reached from the wheels through
    touching bike pieces are the bike; a group reached from neither but touching the rider is
    the rider's (a robot's joints between its hips, something held in the hand)."""
    rider = rider.copy()
    bike = pc.wheel & ~rider
    if not bike.any():
        return rider
    for seed, grow in ((bike, bike), (rider, rider)):
        frontier = pc.global_(seed)
        while frontier:
            new = [j for j in (pc.local[t] for t in pc.touch.touching(frontier)) if not bike[j] and not rider[j]]
            grow[new] = True
            frontier = [pc.idx[j] for j in new]
    return rider
