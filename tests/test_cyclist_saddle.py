"""The IK's saddle auto-fit moves the rendered saddle: saddle + seat-post Gaussians slide with it."""
import numpy as np
import pytest
import torch

from addon.core.procedural import build, layout
from addon.core.procedural import spec as S
from splatting.bike.model import BikeModel
from splatting.cyclist.compose import Cyclist, saddle_slide
from splatting.gaussians.container import Gaussians


def _bike_from_mesh(style):
    """A BikeModel whose Gaussians sit on the procedural mesh's vertices (materials kept as truth)."""
    sp = S.sample_spec(style, 0, 0)
    lay, builders = build.part_builders(sp)
    parts, mats = {}, None
    for name, mb in builders.items():
        V = np.asarray(mb.vertices, float)
        n = len(V)
        parts[name] = Gaussians(torch.tensor(V, dtype=torch.float32), torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
                                torch.full((n, 3), -5.0), torch.zeros(n), torch.zeros(n, 1, 3))
        if name == "frame":
            vm = np.empty(n, dtype=object)  # a vertex's material: that of (any) face using it
            for f, m in zip(mb.faces, mb.materials):
                vm[list(f)] = m
            mats = vm
    kp = layout.keypoints(sp)
    doc = {"frame": "canonical", "units": "m", "keypoints": kp, "parts": {k: list(v) for k, v in layout.part_keypoints(sp).items()}}
    meta = {"bike_id": f"{style}_00", "has_crank": True, "dimensions": build.dimensions(sp, lay)}
    return BikeModel(parts, doc, meta), mats


@pytest.mark.parametrize("style", ["road", "mountain", "city", "bmx", "kids", "gravel", "cruiser"])
def test_saddle_mask_is_saddle_and_post_only(style):
    bike, mats = _bike_from_mesh(style)
    mask, u = saddle_slide(bike)
    a, e = bike.ranges[bike.part_names.index("frame")]
    m = mask[a:e].numpy()
    assert m[mats == "saddle"].mean() > 0.99  # the whole saddle slides
    assert not m[mats == "paint"].any()  # no frame tube moves
    assert not m[mats == "rubber"].any() and not m[mats == "rim"].any()  # nor the rear wheel
    assert not mask[e:].any()  # steering and crank untouched
    seat_dir = np.array(bike.keypoints["seat"] - bike.keypoints["crank_axle"])
    assert np.allclose(u.numpy(), seat_dir / np.linalg.norm(seat_dir))


def test_no_saddle_slide_without_seat_tube_length():
    bike, _ = _bike_from_mesh("road")
    bike.meta = {"bike_id": "road_00"}  # e.g. a curated bike without generator dimensions
    assert saddle_slide(bike) == (None, None)


def test_lowered_seat_moves_saddle_gaussians_and_seat_keypoint():
    from splatting.cyclist.assets import mesh_avatar
    from splatting.rider.roster import load_rider

    bike, _ = _bike_from_mesh("road")
    cyc = Cyclist(bike, mesh_avatar(load_rider("f_teen_slim_150"), n=800), ik_iterations=10)
    poses = torch.tensor([[30.0, 10.0, 0.0, 70.0, 0.0, 0.5, 0.0, -0.3]], dtype=torch.float64)
    (frame,) = cyc.pose(poses)
    off = frame.ik["seat_offset_m"]
    assert off < -0.01, "a 1.50 m rider on a road bike needs the seat lowered"
    bare = bike.pose_tensors(poses)
    moved = frame.gaussians.means[: len(bike)].double() - bare["means"][0].double()
    # the slide is off * (R_g u) for the saddle Gaussians, zero elsewhere
    yaw = np.radians(70.0)
    Ry = torch.tensor([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]], dtype=torch.float64)
    expect = off * (Ry @ cyc.saddle_axis)
    assert torch.allclose(moved[cyc.saddle_mask], expect.expand(int(cyc.saddle_mask.sum()), 3), atol=1e-5)
    assert moved[~cyc.saddle_mask].abs().max() < 1e-6
    seat0 = bare["keypoints"][0, bare["keypoint_names"].index("seat")].numpy()
    assert np.allclose(frame.bike_keypoints["seat"] - seat0, expect.numpy(), atol=1e-9)
