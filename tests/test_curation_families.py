"""How unseen real two-wheelers failed, as synthetic families (numpy, no bpy; tests/curation_synth.py
primitives, truth from the construction): a third round outline beside the wheels (a round
basket or lamp, a large chainring), wheels covered by a scooter's body, clean spoked wheels,
a ground plane under the model, the size from the model's own units and refused when the cues
disagree, and keypoints measured against their own parts."""
import numpy as np
import pytest

from addon.core.curation import keypoint_check, mesh, pipeline, silhouette
from addon.core.script import UserError

from curation_synth import STEER, FRAME, Builder, synth_bike, transform

CASES = [(41, 1.0, 0.0), (42, 100.0, np.array([300.0, -50.0, 20.0])), (43, 0.001, 0.0)]


def _wheels(V, T, seed, scale, offset):
    """The two wheels the side-view search finds, back in the bike's own frame (metres)."""
    Vm, q = transform(V, seed, scale, offset)
    soup = mesh.Soup(Vm, T)
    rings, _, _ = silhouette.wheel_rings(soup)
    return sorted(((r.centre - offset) @ q / scale for r in rings), key=lambda c: c[0]), \
        [r.radius / scale for r in rings]


def _round_plate(b, c, r, lab, n=48):
    """A flat disc in the side plane (a round basket's side, a lamp, a covered front): a fan."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    V = np.concatenate([[c], c + r * np.stack([np.cos(a), np.sin(a), np.zeros(n)], 1)])
    b.add(V, [(0, 1 + i, 1 + (i + 1) % n) for i in range(n)], lab)


@pytest.mark.parametrize("seed,scale,offset", CASES)
def test_a_third_round_outline_above_the_ground_is_not_a_wheel(seed, scale, offset):
    """A wheel-sized round plate ahead of the bar at 1 m (a round front basket or a big lamp)
    and a 20 cm chainring: the wheels are still the two circles on the ground (this was
    refused as 'three wheels in the side view')."""
    V, T, lab, kp = synth_bike(nseg=10, tyre_r=0.03)
    b = Builder()
    b.add(V, T, lab)
    _round_plate(b, kp["front_axle"] + [0.45, 0.62, 0.0], 0.3, STEER)
    b.tube(kp["front_axle"] + [0.13, 0.62, 0.0], kp["front_axle"] + [0.2, 0.62, 0.0], 0.01, STEER)
    b.torus(kp["crank_axle"] + [0, 0, 0.05], 0.2, 0.006, 40, 4, FRAME)
    V, T, _ = b.arrays()
    cents, radii = _wheels(V, T, seed, scale, offset)
    assert np.linalg.norm(cents[0] - kp["rear_axle"]) < 0.02 and np.linalg.norm(cents[1] - kp["front_axle"]) < 0.02
    assert all(abs(r - 0.35) < 0.01 for r in radii), radii


@pytest.mark.parametrize("seed,scale,offset", CASES)
def test_a_third_wheel_on_the_ground_is_still_refused(seed, scale, offset):
    """A trailer's wheel in line, standing on the same ground, is a third wheel."""
    V, T, lab, kp = synth_bike(nseg=24)
    b = Builder()
    b.add(V, T, lab)
    c = kp["rear_axle"] - [0.95, 0.0, 0.0]
    b.torus(c, 0.35, 0.022, 24, 8, FRAME)
    b.tube(kp["rear_axle"], c, 0.015, FRAME)
    V, T, _ = b.arrays()
    with pytest.raises(UserError, match="three wheels"):
        pipeline.curate_arrays(transform(V, seed, scale, offset)[0], T, 0.7)


def _covered_scooter(R=0.23):
    """A motor scooter whose body covers the top of both small wheels: a box body low between
    and over the wheels, a front shield, no spokes to see (the wheels' lower halves show)."""
    b = Builder()
    ra, fa = np.array([-0.62, R, 0.0]), np.array([0.68, R, 0.0])
    for c in (ra, fa):
        b.torus(c, R, 0.05, 20, 8, FRAME)
        b.tube(c - [0, 0, 0.06], c + [0, 0, 0.06], 0.08, FRAME)
    b.box([-0.55, 0.55, 0.0], [0.35, 0.2, 0.17], FRAME)         # rear body over the rear wheel
    b.box([0.0, 0.32, 0.0], [0.3, 0.06, 0.15], FRAME)            # floorboard
    b.box([0.55, 0.75, 0.0], [0.1, 0.45, 0.2], FRAME)            # front shield
    b.box([0.7, 0.42, 0.0], [0.2, 0.06, 0.07], FRAME)            # front mudguard over the tyre
    b.tube([0.6, 1.2, -0.35], [0.6, 1.2, 0.35], 0.02, FRAME)     # bar
    V, T, lab = b.arrays()
    return V, T, ra, fa


@pytest.mark.parametrize("seed,scale,offset", CASES)
def test_covered_small_wheels_of_a_motor_scooter(seed, scale, offset):
    V, T, ra, fa = _covered_scooter()
    cents, radii = _wheels(V, T, seed, scale, offset)
    assert np.linalg.norm(cents[0] - ra) < 0.03 and np.linalg.norm(cents[1] - fa) < 0.03, cents
    assert all(abs(r - 0.23) < 0.015 for r in radii), radii


@pytest.mark.parametrize("seed,scale,offset", CASES)
def test_clean_spoked_wheels(seed, scale, offset):
    """Thin tyres, a deep rim and 36 spokes each (tyre, rim and hub outlines are concentric)."""
    b = Builder()
    V, T, lab, kp = synth_bike(nseg=64, tyre_r=0.014)
    b.add(V, T, lab)
    for c in (kp["rear_axle"], kp["front_axle"]):
        b.torus(c, 0.35 - 0.03, 0.012, 64, 6, FRAME, flat=2.0)
        for k in range(36):
            ang = k * np.pi / 18
            b.tube(c + [0, 0, 0.02 * (-1) ** k], c + 0.3 * np.array([np.cos(ang), np.sin(ang), 0]), 0.0015, FRAME, 4)
    V, T, _ = b.arrays()
    cents, radii = _wheels(V, T, seed, scale, offset)
    assert np.linalg.norm(cents[0] - kp["rear_axle"]) < 0.02 and np.linalg.norm(cents[1] - kp["front_axle"]) < 0.02
    assert all(abs(r - 0.35) < 0.01 for r in radii), radii


def test_ground_plane_under_a_tilted_bike_is_left_out():
    """A bike leaning 12 degrees on a 12 x 5 m ground sheet (a published scene): the sheet is
    the thinnest thing in the file, yet the wheels are the bike's."""
    V, T, lab, kp = synth_bike(nseg=24)
    t = np.radians(12)
    lean = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    b = Builder()
    b.add(V @ lean.T, T, lab)
    b.box([0.0, -0.001, 0.0], [6.0, 0.0005, 2.5], FRAME)
    V2, T2, _ = b.arrays()
    res = pipeline.curate_arrays(V2, T2, 0.7)
    wb = np.linalg.norm(res.keypoints["front_axle"] - res.keypoints["rear_axle"])
    assert abs(wb - np.linalg.norm(kp["front_axle"] - kp["rear_axle"])) < 0.02, wb


@pytest.mark.parametrize("scale,unit", [(1.0, "metres"), (100.0, "centimetres"), (1000.0, "millimetres")])
def test_size_from_the_files_units(scale, unit):
    """No wheel size given: a bicycle modelled at real size in metres, cm or mm keeps it."""
    V, T, lab, kp = synth_bike(nseg=24)
    res = pipeline.curate_arrays(transform(V, 51, scale, 0.0)[0], T, None)
    assert abs(res.wheel_diameter - 0.7) < 0.005, res.wheel_diameter
    assert res.record["size"]["class"] == "bicycle" and unit in res.record["size"]["cue"]


def test_size_in_arbitrary_units_and_disagreeing_cues_are_refused():
    """In arbitrary units a bicycle gets the typical 0.7 m wheels; a 'bicycle' whose wheelbase
    is 3.7 wheel diameters at that size is refused with the measured figures."""
    V, T, lab, kp = synth_bike(nseg=24)
    res = pipeline.curate_arrays(transform(V, 52, 3.3, 0.0)[0], T, None)
    assert res.wheel_diameter == pytest.approx(0.7) and res.record["size"]["cue"] == "a bicycle's typical wheels"
    V, T, lab, kp = synth_bike(nseg=24, wheelbase=2.6)
    with pytest.raises(UserError, match=r"size: the cues disagree: a bicycle .* wheelbase 2\.\d\d m"):
        pipeline.curate_arrays(transform(V, 53, 3.3, 0.0)[0], T, None)


def test_keypoints_off_their_part_are_refused_with_the_distance():
    """An annotator's handles 7 cm beyond the bar's ends: curation names them and the distance;
    its own keypoints on the same bike all lie within 3 cm of their parts."""
    V, T, lab, kp = synth_bike(nseg=24)
    res = pipeline.curate_arrays(V, T, 0.7)
    assert res.problems == []
    d = res.record["keypoint_distance_cm"]
    assert set(d) == set(keypoint_check.RULES) and max(d.values()) < 3.0, d
    given = {k: np.array(v) for k, v in res.keypoints.items()}
    given["handle_left"] = given["handle_left"] + [0, 0, -0.12]
    given["handle_right"] = given["handle_right"] + [0, 0, 0.12]
    res = pipeline.curate_arrays(V, T, 0.7, keypoints=given)
    bad = [p for p in res.problems if p.startswith("handle_")]
    assert len(bad) == 2 and all("cm from the steering surface" in p for p in bad), res.problems
    # the grip centre is 5 cm in from the bar's end: 12 cm further out is ~7 cm beyond it
    assert 5.5 < float(bad[0].split()[1]) < 8.5, bad


def _lower_body(b, seat_top, pl, pr):
    """A rider's hips and both legs as one connected piece (a low-poly or skinned person), astride
    the top tube, feet on the pedals."""
    from curation_synth import RIDER, fuse
    p = Builder()
    hip = seat_top + [0.0, 0.1, 0.0]
    p.box(hip, [0.12, 0.09, 0.17], RIDER)
    for s, ped in ((1, pr), (-1, pl)):
        knee = np.array([0.12, 0.72, s * 0.14])
        p.tube(hip + [0, 0, s * 0.11], knee, 0.06, RIDER)
        p.tube(knee, ped + [0, 0.06, 0.0], 0.05, RIDER)
    b.add(*fuse(*p.arrays())[:3])


@pytest.mark.parametrize("seed,scale", [(61, 1.0), (62, 100.0)])
def test_a_riders_one_piece_lower_body_goes_with_the_rider(seed, scale):
    """Torso, head and arms are separate pieces; hips and legs one piece astride the frame (it
    stayed on the saddle, and the seat keypoint sat on it)."""
    from curation_synth import RIDER
    V, T, lab, kp = synth_bike(nseg=24, rider=True)
    keep = ~((lab == RIDER) & (mesh.Soup(V, T).comp_of_tri >= 0) & (V[T].mean(1)[:, 1] < 1.1))   # drop its thighs
    b = Builder()
    b.add(V, T[keep], lab[keep])
    _lower_body(b, kp["seat"], kp["pedal_left"], kp["pedal_right"])
    V, T, lab = b.arrays()
    Vm, q = transform(V, seed, scale, 0.0)
    res = pipeline.curate_arrays(Vm, T, 0.7)
    assert res.problems == [], res.problems
    assert np.all(res.labels[lab == RIDER] == -1), (res.labels[lab == RIDER] != -1).sum()
    assert np.linalg.norm(res.keypoints["seat"] - kp["seat"]) < 0.03, res.keypoints["seat"]


@pytest.mark.parametrize("angle,seed", [(172.0, 71), (188.0, 72)])
def test_crank_arms_modelled_at_an_angle(angle, seed):
    """Crank arms 172 or 188 degrees apart (a pedal 2.4 cm off the opposite of the other): the
    pedals are still an opposite pair about the crank axle, each within 3 cm of its pedal body,
    and no 'not opposite' refusal."""
    V, T, lab, kp = synth_bike(nseg=24, crank_angle=angle)
    res = pipeline.curate_arrays(transform(V, seed, 1.0, 0.0)[0], T, 0.7)
    assert res.problems == [], res.problems
    k = res.keypoints
    assert np.linalg.norm((k["pedal_left"] - k["crank_axle"])[:2] + (k["pedal_right"] - k["crank_axle"])[:2]) < 0.03
    for n in ("pedal_left", "pedal_right"):
        assert np.linalg.norm(k[n] - kp[n]) < 0.03, (n, k[n], kp[n])


@pytest.mark.parametrize("kind,scale,cls,diameter", [("motorcycle", 3.3, "motorcycle", 0.64),
                                                     ("motorcycle", 100.0, "motorcycle", 0.60),
                                                     ("kick scooter", 7.0, "kick scooter", None)])
def test_size_by_vehicle_class(kind, scale, cls, diameter):
    """Without a wheel size: a motorcycle in arbitrary units gets a motorcycle's 0.64 m tyres, in
    centimetres its own 0.6 m; a kick scooter its top at 1 m (its bar, 0.96 m up, at ~1 m)."""
    from curation_synth import synth_motorcycle, synth_scooter
    V, T, lab, kp = synth_motorcycle() if kind == "motorcycle" else synth_scooter()
    res = pipeline.curate_arrays(transform(V, 81, scale, 0.0)[0], T, None)
    assert res.record["size"]["class"] == cls, res.record["size"]
    if diameter is not None:
        assert res.wheel_diameter == pytest.approx(diameter, abs=0.005)
    else:
        top = res.record["height_m"]
        assert abs(top - 1.0) < 0.02 and abs(res.wheel_diameter - 0.2 / 0.965) < 0.02, (top, res.wheel_diameter)


def test_a_car_is_still_refused():
    """The ground-standing pair needs less outline than before, and a car's side view shows two
    such wheels under its body: it is still refused with one line (today by the pose: no
    chainring and no handlebar to tell its front; the twin-wheel check comes later)."""
    b = Builder()
    for x in (-1.3, 1.3):
        for z in (-0.75, 0.75):
            b.torus(np.array([x, 0.32, z]), 0.32, 0.1, 24, 8, FRAME)
    b.box([0.0, 0.75, 0.0], [2.1, 0.3, 0.85], FRAME)        # body over the wheels' tops
    b.box([-0.2, 1.25, 0.0], [1.1, 0.22, 0.75], FRAME)      # cabin
    V, T, _ = b.arrays()
    for seed, scale in ((91, 1.0), (92, 100.0)):
        with pytest.raises(UserError) as e:
            pipeline.curate_arrays(transform(V, seed, scale, 0.0)[0], T, None)
        assert "\n" not in str(e.value), e.value
