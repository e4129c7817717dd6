"""Motion blur by smearing each Gaussian along its motion (sequences/velocity_blur.py, method B):
against the time average of many shifted renders (what a box shutter integrates), and the still
image when nothing moves."""
import torch
from dataclasses import replace

from helpers import look_at_camera


def scene():
    g = torch.Generator().manual_seed(3)
    from splatting.gaussians.container import Gaussians
    n = 6
    means = (torch.rand(n, 3, generator=g, dtype=torch.float64) - 0.5) * torch.tensor([1.0, 1.0, 0.3], dtype=torch.float64)
    quats = torch.nn.functional.normalize(torch.randn(n, 4, generator=g, dtype=torch.float64), dim=1)
    log_scales = torch.log(torch.rand(n, 3, generator=g, dtype=torch.float64) * 0.05 + 0.03)
    opacity_logits = torch.logit(torch.full((n,), 0.25, dtype=torch.float64))  # faint: compositing near-linear
    sh = torch.rand(n, 1, 3, generator=g, dtype=torch.float64)
    return Gaussians(means, quats, log_scales, opacity_logits, sh)


def render(g, cam):
    from splatting.raster.api import render_gaussians
    return render_gaussians(g, cam, sh_degree=0)["rgb"].double()


def test_smear_matches_the_time_average_and_is_the_still_without_motion():
    from splatting.dataset.sequences.velocity_blur import smear
    from splatting.raster.api import EPS2D
    cam = look_at_camera((0.0, 0.0, -4.0), width=64, height=48, focal=50.0)
    g = scene()
    d = torch.tensor([[0.5, 0.1, 0.0]], dtype=torch.float64).expand(len(g), 3)  # ~6 px across the screen
    n = 65
    ref = sum(render(replace(g, means=g.means + d * ((k + 0.5) / n - 0.5)), cam) for k in range(n)) / n
    still = render(g, cam)
    blurred = render(smear(g, d, cam, EPS2D, False), cam)
    err_still = (still - ref).abs().mean().item()
    err_smear = (blurred - ref).abs().mean().item()
    assert err_smear < 0.2 * err_still, (err_smear, err_still)
    # the energy a blur conserves: the image's sum stays
    assert abs(blurred.sum().item() - ref.sum().item()) < 0.03 * ref.sum().item()
    same = render(smear(g, torch.zeros_like(g.means), cam, EPS2D, False), cam)
    assert (same - still).abs().max().item() < 1e-5
