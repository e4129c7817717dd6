"""The street renderer's shortcuts give what the long way gives: conservative slot screen boxes,
the COCO RLE of a box mask, the background composited only inside the render's box."""
import numpy as np
import pytest
import torch

from helpers import look_at_camera


def _scene(seed, n=300):
    from splatting.gaussians.container import Gaussians
    g = torch.Generator().manual_seed(seed)
    means = torch.randn(n, 3, generator=g) * torch.tensor([1.5, 0.8, 1.0])
    return Gaussians(means=means, quats=torch.randn(n, 4, generator=g),
                     log_scales=torch.log(torch.rand(n, 3, generator=g) * 0.15 + 0.01),
                     opacity_logits=torch.randn(n, generator=g) + 2.0,
                     sh=torch.rand(n, 1, 3, generator=g))


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_slot_boxes_hold_every_pixel_the_slot_renders(seed):
    """Every pixel a slot's Gaussians reach (alpha > 1e-6 when rendered alone, whole image) lies in
    its box, and the box is not much larger than those pixels' extent (it is a useful crop)."""
    torch.set_num_threads(1)
    from splatting.cyclist.scene_render import slot_boxes
    from splatting.raster.sparse import render_gaussians
    g = _scene(seed)
    slots = torch.arange(len(g)) % 3
    cam = look_at_camera((0.5, 1.0, 7.0), width=160, height=96, focal=90.0, cx=70.0, cy=40.0)
    boxes = slot_boxes(g.means, g.scales, slots, 3, cam)
    for s in range(3):
        a = render_gaussians(g[slots == s], cam)["alpha"].numpy()
        ys, xs = np.nonzero(a > 1e-6)
        u0, v0, w, h = boxes[s]
        assert xs.min() >= u0 and xs.max() < u0 + w and ys.min() >= v0 and ys.max() < v0 + h
        assert w * h <= 2.5 * (xs.ptp() + 1) * (ys.ptp() + 1) or (w, h) == (160, 96)


def test_slot_boxes_widen_with_the_low_pass():
    """A model drawn with a wide low-pass (eps2d 4 px^2: every splat 2 px wider in sigma) still
    fits its boxes when slot_boxes is told its eps2d; the fixed 2 px margin would cut it."""
    torch.set_num_threads(1)
    from splatting.cyclist.scene_render import slot_boxes
    from splatting.raster.sparse import render_gaussians
    import dataclasses
    g = _scene(4)
    g = dataclasses.replace(g, log_scales=g.log_scales - 3.0)  # tiny: the low-pass sets their footprint
    slots = torch.arange(len(g)) % 3
    cam = look_at_camera((0.5, 1.0, 7.0), width=160, height=96, focal=90.0, cx=70.0, cy=40.0)
    eps = torch.full((len(g),), 0.3)
    eps[slots == 1] = 4.0  # one model with the wide filter: the max decides the margin
    cut = 0
    for boxes, must_hold in ((slot_boxes(g.means, g.scales, slots, 3, cam, eps2d=eps), True),
                             (slot_boxes(g.means, g.scales, slots, 3, cam), False)):
        a = render_gaussians(g[slots == 1], cam, eps2d=4.0)["alpha"].numpy()
        ys, xs = np.nonzero(a > 1e-6)
        u0, v0, w, h = boxes[1]
        holds = xs.min() >= u0 and xs.max() < u0 + w and ys.min() >= v0 and ys.max() < v0 + h
        if must_hold:
            assert holds
        else:
            cut += not holds
    assert cut == 1


def test_slot_boxes_none_behind_camera_and_off_screen():
    from splatting.cyclist.scene_render import slot_boxes
    g = _scene(3, n=20)
    cam = look_at_camera((0.0, 0.0, 10.0), width=64, height=48, focal=60.0)
    means = g.means.clone()
    means[10:] += torch.tensor([0.0, 0.0, 30.0])  # slot 1 behind the camera (it looks along -Z)
    slots = torch.tensor([0] * 10 + [1] * 10)
    boxes = slot_boxes(means, g.scales, slots, 3, cam)
    assert boxes[0] is not None and boxes[1] is None and boxes[2] is None  # slot 2: empty
    far_right = g.means + torch.tensor([100.0, 0.0, 0.0])
    assert slot_boxes(far_right, g.scales, torch.zeros(20, dtype=torch.long), 1, cam) == [None]


def test_box_mask_rle_equals_pycocotools_on_the_full_mask():
    from pycocotools import mask as mu
    from splatting.dataset.labels import BoxMask, rle
    rng = np.random.default_rng(0)
    for _ in range(200):
        H, W = (int(x) for x in rng.integers(1, 25, 2))
        h, w = int(rng.integers(1, H + 1)), int(rng.integers(1, W + 1))
        v0, u0 = int(rng.integers(0, H - h + 1)), int(rng.integers(0, W - w + 1))
        crop = rng.random((h, w)) < rng.random()
        full = BoxMask(crop, u0, v0).full(W, H)
        ref = mu.encode(np.asfortranarray(full.astype(np.uint8)))
        r, seg = rle(BoxMask(crop, u0, v0), W, H)
        assert r["counts"] == ref["counts"] and seg["size"] == [H, W]
        assert rle(full)[0]["counts"] == ref["counts"]
        assert (mu.decode(r).astype(bool) == full).all()
        bb = BoxMask(crop, u0, v0).bbox_xyxy()
        if full.any():
            ys, xs = np.nonzero(full)
            assert bb == [xs.min(), ys.min(), xs.max() + 1, ys.max() + 1]
        else:
            assert bb is None


@pytest.mark.parametrize("photo_bytes", [False, True])
def test_over_in_box_equals_over_on_the_whole_image(photo_bytes):
    from splatting.cyclist.render import over
    from splatting.dataset.generate import over_in_box
    rng = np.random.default_rng(1)
    H, W = 30, 50
    alpha = np.zeros((H, W), np.float32)
    rgb = np.zeros((H, W, 3), np.float32)
    alpha[5:20, 10:30] = rng.random((15, 20))
    rgb[5:20, 10:30] = rng.random((15, 20, 3)) * alpha[5:20, 10:30, None]
    bg8 = rng.integers(0, 256, (H, W, 3)).astype(np.uint8)
    bgf = bg8.astype(np.float32) / 255.0
    want = over({"rgb": rgb, "alpha": alpha}, bgf)
    got = over_in_box({"rgb": rgb, "alpha": alpha}, bg8 if photo_bytes else bgf, (10, 5, 20, 15))
    assert got.dtype == np.uint8 and (got == want).all()


@pytest.mark.parametrize("seed, W, H", [(0, 40, 24), (5, 17, 33), (9, 1, 8)])
def test_generated_backgrounds_equal_the_per_pixel_formulas(seed, W, H):
    """The separable noise (one matmul for every octave's columns) and the broadcast gradient give
    the per-pixel definitions: bilinear value noise of 4 octaves, a clipped linear ramp."""
    from splatting.dataset.backgrounds import generated
    rng = np.random.default_rng(seed)
    want = np.zeros((H, W, 3))
    amp, total = 1.0, 0.0
    for cells in (4, 8, 16, 64):
        grid = rng.uniform(0, 1, (cells + 1, cells + 1, 3))
        for i in range(H):
            for j in range(W):
                y, x = i * cells / max(H - 1, 1), j * cells / max(W - 1, 1)
                y0, x0 = min(int(y), cells - 1), min(int(x), cells - 1)
                fy, fx = y - y0, x - x0
                want[i, j] += amp * ((1 - fy) * ((1 - fx) * grid[y0, x0] + fx * grid[y0, x0 + 1])
                                     + fy * ((1 - fx) * grid[y0 + 1, x0] + fx * grid[y0 + 1, x0 + 1]))
        total += amp
        amp *= 0.5
    got = generated("noise", seed, W, H)
    assert got.dtype == np.float32 and got.shape == (H, W, 3)
    assert np.abs(got - want / total).max() < 1e-6
    rng = np.random.default_rng(seed)
    a, b, ang = rng.uniform(0, 1, 3), rng.uniform(0, 1, 3), rng.uniform(0, 2 * np.pi)
    grad = generated("gradient", seed, W, H)
    for i, j in ((0, 0), (H - 1, W - 1), (H // 2, W // 3)):
        t = min(max((j / max(W - 1, 1) - 0.5) * np.cos(ang) + (i / max(H - 1, 1) - 0.5) * np.sin(ang) + 0.5, 0), 1)
        assert np.abs(grad[i, j] - ((1 - t) * a + t * b)).max() < 1e-6


@pytest.mark.parametrize("seed", [0, 1])
def test_one_pass_amodal_alphas_equal_each_slot_rendered_alone(seed):
    """render_scene's amodal alphas from the image's own pass (groups) equal each slot's
    Gaussians rasterized alone through its cropped camera (_subset_alpha at full size), also
    when amodal_max_px sends the larger slots to the reduced-resolution path; and the slots do
    occlude each other (the amodal masks are larger than the visible ones)."""
    torch.set_num_threads(1)
    from splatting.cyclist.scene_render import _subset_alpha, render_scene
    g = _scene(seed, n=600)
    slots = torch.arange(len(g)) % 3
    slots[:100] = 2  # uneven slots: slot 2 larger on screen
    cam = look_at_camera((0.5, 1.0, 7.0), width=160, height=96, focal=90.0, cx=70.0, cy=40.0)
    t = (g.means.float(), g.quats.float(), g.scales.float(), g.opacities.float())
    one = render_scene(g, slots, 3, cam, (1, 2))
    for s in (1, 2):
        ref, rt = _subset_alpha(t, torch.nonzero(slots == s).squeeze(1), cam, one["boxes"][s])
        a, at = one["amodal"][s]
        assert at == rt and a.shape == ref.shape
        assert np.abs(a - ref).max() < 1e-5
        u0, v0 = at
        vis = one["label"][v0:v0 + a.shape[0], u0:u0 + a.shape[1]] == s
        assert (a > 0.5).sum() > vis.sum() + 20
    # a max_px between the two boxes: the smaller slot stays in the one pass, the larger is reduced
    sizes = {s: max(one["boxes"][s][2:]) for s in (1, 2)}
    small, big = sorted(sizes, key=sizes.get)
    assert sizes[small] < sizes[big]
    mixed = render_scene(g, slots, 3, cam, (1, 2), amodal_max_px=sizes[small])
    for k in ("rgb", "alpha", "depth", "label"):
        assert (mixed[k] == one[k]).all(), k
    assert (mixed["amodal"][small][0] == one["amodal"][small][0]).all()
    want = _subset_alpha(t, torch.nonzero(slots == big).squeeze(1), cam, one["boxes"][big], sizes[small])
    assert (mixed["amodal"][big][0] == want[0]).all() and mixed["amodal"][big][1] == want[1]


def _two_slots_far_apart(seed_a, seed_b, shrink):
    """Two 150-Gaussian models, their scales / exp(shrink), one in each half of a 160 x 96 view:
    (Gaussians, slots 1 | 2, camera)."""
    from splatting.gaussians.container import Gaussians
    a, b = _scene(seed_a, n=150), _scene(seed_b, n=150)
    a = Gaussians(a.means * 0.3 - torch.tensor([1.6, 0.0, 0.0]), a.quats, a.log_scales - shrink, a.opacity_logits, a.sh)
    b = Gaussians(b.means * 0.3 + torch.tensor([1.6, 0.0, 0.0]), b.quats, b.log_scales - shrink, b.opacity_logits, b.sh)
    return Gaussians.cat([a, b]), torch.tensor([1] * 150 + [2] * 150), look_at_camera((0.0, 0.0, 9.0), width=160,
                                                                                  height=96, focal=90.0)


@pytest.mark.parametrize("amodal_max_px", [None, 24])
def test_antialiased_mask_draws_each_slot_as_it_was_trained(amodal_max_px):
    """render_scene(antialiased=mask): a bike trained with the mip filter beside a rider trained
    without, far apart on screen: each one's pixels and amodal alpha are those of a render with the
    filter on (slot 1) or off (slot 2) for everything; a mask of the wrong length is refused."""
    torch.set_num_threads(1)
    from splatting.cyclist.scene_render import render_scene
    g, slots, cam = _two_slots_far_apart(4, 5, 1.5)
    mask = slots == 1
    kw = dict(amodal_slots=(1, 2), amodal_max_px=amodal_max_px)
    mixed = render_scene(g, slots, 3, cam, antialiased=mask, **kw)
    on, off = (render_scene(g, slots, 3, cam, antialiased=f, **kw) for f in (True, False))
    left = np.s_[:, :80]
    np.testing.assert_allclose(mixed["alpha"][left], on["alpha"][left], atol=1e-6)
    np.testing.assert_allclose(mixed["alpha"][:, 80:], off["alpha"][:, 80:], atol=1e-6)
    assert np.abs(on["alpha"][left] - off["alpha"][left]).max() > 0.02  # the filter matters here
    for s, want in ((1, on), (2, off)):
        np.testing.assert_allclose(mixed["amodal"][s][0], want["amodal"][s][0], atol=1e-6)
        assert np.abs(on["amodal"][s][0] - off["amodal"][s][0]).max() > 0.02  # the amodal alphas follow it too
    with pytest.raises(ValueError, match="antialiased mask"):
        render_scene(g, slots, 3, cam, antialiased=mask[:10], **kw)


@pytest.mark.parametrize("amodal_max_px", [None, 24])
def test_per_gaussian_eps2d_draws_each_slot_with_its_own_filter(amodal_max_px):
    """render_scene(eps2d=(N,)): a bike at Cycles' 0.173 px^2 beside a rider at 0.3, far apart on
    screen: each one's pixels and amodal alpha (one pass or reduced resolution) are those of a
    render with its value for everything."""
    torch.set_num_threads(1)
    from splatting.cyclist.scene_render import render_scene
    g, slots, cam = _two_slots_far_apart(6, 7, 2.5)
    eps = torch.where(slots == 1, 0.173, 0.3).double()
    kw = dict(amodal_slots=(1, 2), amodal_max_px=amodal_max_px, antialiased=True)
    mixed = render_scene(g, slots, 3, cam, eps2d=eps, **kw)
    lo, hi = (render_scene(g, slots, 3, cam, eps2d=e, **kw) for e in (0.173, 0.3))
    left = np.s_[:, :80]
    np.testing.assert_allclose(mixed["alpha"][left], lo["alpha"][left], atol=1e-6)
    np.testing.assert_allclose(mixed["alpha"][:, 80:], hi["alpha"][:, 80:], atol=1e-6)
    np.testing.assert_allclose(mixed["rgb"][left], lo["rgb"][left], atol=1e-6)
    assert np.abs(lo["alpha"][left] - hi["alpha"][left]).max() > 0.01  # the filter matters here
    for s, want in ((1, lo), (2, hi)):
        np.testing.assert_allclose(mixed["amodal"][s][0], want["amodal"][s][0], atol=1e-6)
        assert np.abs(lo["amodal"][s][0] - hi["amodal"][s][0]).max() > 0.01  # the amodal alphas follow it too
