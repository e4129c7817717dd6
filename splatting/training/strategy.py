"""Densification strategies, kept apart from the trainer the way gsplat's are: the trainer talks to
a `Strategy` only, and takes which one from its config (`TrainConfig.strategy`, a name in
STRATEGIES).  `DensifyStrategy` ("default") is adaptive density control (3DGS clone / split /
prune / opacity reset) with visual-hull pruning as an option; `FixedStrategy` ("fixed") never
changes the set (ablations, fine-tuning an existing model).

The standard INRIA rules, with every length tied to the object's size instead of the camera
distance: `extent` is the diagonal of the object's bounding box (points.ply or the initial
Gaussians).  On NeRF-synthetic INRIA's camera-based extent (1.1 x camera radius, ~4.4) is close to
the objects' bounding-box diagonal (~4.5), so the INRIA coefficients carry over unchanged; with
the 12 m ring they would make a bike part's "large Gaussian" threshold 13 cm instead of ~2.5 cm.

The parameters live in a dict name -> nn.Parameter with dim 0 = Gaussians, each in its own Adam
param group (`group["name"]`); every change to the set updates the Adam moments alongside.
"""
import torch

from cyclist_formats.errors import UserError
from splatting.training.config import DensifyConfig
from splatting.rotations import quat_to_rotmat


class Strategy:
    """What the trainer asks of a densification strategy.

    post_backward(it, params, optimizer, means2d_grad, radii, width, height): after each optimiser
        step at iteration `it` (1-based); may replace params[k] (and their Adam state) in place.
    finish(params, optimizer): once, after the last iteration.
    stats: a dict of counters that goes into the training metrics.
    """
    stats: dict

    def post_backward(self, it, params, optimizer, means2d_grad, radii, width, height):
        raise NotImplementedError

    def finish(self, params, optimizer):
        raise NotImplementedError


class FixedStrategy(Strategy):
    """The Gaussian set never changes."""

    def __init__(self, cfg: DensifyConfig = None, extent: float = 1.0, hull=None):
        self.stats = {}

    def post_backward(self, it, params, optimizer, means2d_grad, radii, width, height):
        return False

    def finish(self, params, optimizer):
        return None


class DensifyStrategy(Strategy):
    def __init__(self, cfg: DensifyConfig, extent: float, hull=None):
        """hull: a callable returning (N,) bool, True where a Gaussian's centre lies inside the
        visual hull of the training masks; used when cfg.hull_prune."""
        self.cfg = cfg
        self.hull = hull if cfg.hull_prune else None
        self.extent = float(extent)
        self.grad_accum = None
        self.count = None
        self.max_radii = None  # (N,) largest screen radius seen, as a fraction of the image width
        self.n_resets = 0
        self.stats = {"cloned": 0, "split": 0, "pruned": 0, "budget_capped": 0, "resets": 0}

    # -- statistics, after each backward ------------------------------------------------------
    def accumulate(self, means2d_grad, radii, full_width, full_height):
        """means2d_grad (N,2) in pixels of a render whose *uncropped* image is full_width x full_height."""
        n = means2d_grad.shape[0]
        if self.grad_accum is None or self.grad_accum.shape[0] != n:
            self._reset_stats(n, means2d_grad.device)
        vis = radii > 0
        # pixel -> NDC gradient (x W/2, x H/2) so the INRIA threshold holds at every resolution
        g = means2d_grad[vis] * means2d_grad.new_tensor([full_width / 2.0, full_height / 2.0])
        self.grad_accum[vis] += g.norm(dim=-1)
        self.count[vis] += 1
        self.max_radii[vis] = torch.maximum(self.max_radii[vis], radii[vis].to(self.max_radii) / full_width)

    def _reset_stats(self, n, device):
        self.grad_accum = torch.zeros(n, device=device)
        self.count = torch.zeros(n, device=device)
        self.max_radii = torch.zeros(n, device=device)

    # -- the Strategy interface ------------------------------------------------------------------
    @torch.no_grad()
    def post_backward(self, it, params, optimizer, means2d_grad, radii, width, height):
        self.accumulate(means2d_grad, radii, width, height)
        keep = self.hull() if self.hull is not None and self.is_densify_step(it) else None
        return self.step(it, params, optimizer, keep_mask=keep)

    @torch.no_grad()
    def finish(self, params, optimizer):
        """Final pruning: outside the visual hull, then invisible Gaussians (they only cost render time)."""
        if self.hull is not None:
            self.prune(params, optimizer, self.hull())
        if self.cfg.min_opacity > 0:
            keep = torch.sigmoid(params["opacity_logits"]) >= self.cfg.min_opacity
            if keep.any():
                self.prune(params, optimizer, keep)

    # -- the schedule ---------------------------------------------------------------------------
    def step(self, it, params, optimizer, keep_mask=None):
        """Call after optimizer.step() at iteration `it` (1-based). keep_mask (N,) bool, optional:
        extra pruning (e.g. Gaussians outside the visual hull). Returns True if the set changed."""
        c = self.cfg
        changed = False
        if self.is_densify_step(it) and self.grad_accum is not None:
            self._densify_and_prune(params, optimizer, keep_mask)
            changed = True
        if c.reset_every and it % c.reset_every == 0 and it <= c.stop:
            self._reset_opacity(params, optimizer)
            changed = True
        return changed

    def is_densify_step(self, it):
        """Every `every` iterations, offset by half a period so that evaluations at round
        iteration counts never see the model right after a clone (clones double the opacity until
        the optimiser separates them)."""
        c = self.cfg
        return c.start <= it <= c.stop and it % c.every == c.every // 2

    @torch.no_grad()
    def _densify_and_prune(self, params, optimizer, keep_mask=None):
        c = self.cfg
        opac = torch.sigmoid(params["opacity_logits"])
        scales = torch.exp(params["log_scales"]).max(-1).values
        prune = opac < c.min_opacity
        if self.n_resets:  # INRIA prunes by size only once opacities have been reset
            prune |= self.max_radii > c.max_screen_frac
            prune |= scales > c.max_world_frac * self.extent
        if keep_mask is not None:
            prune |= ~keep_mask
        if prune.all():  # never empty the model
            prune[torch.argmax(opac)] = False

        avg = self.grad_accum / self.count.clamp_min(1)
        cand = (avg >= c.grad_threshold) & ~prune
        big = scales > c.percent_dense * self.extent
        # budget: each clone or split adds one Gaussian (split_n - 1 for splits); keep the strongest
        n_after_prune = int((~prune).sum())
        room = max(0, c.max_gaussians - n_after_prune)
        cost = torch.where(big, c.split_n - 1, 1)
        idx = torch.nonzero(cand).squeeze(1)
        if int(cost[idx].sum()) > room:
            order = idx[torch.argsort(avg[idx], descending=True)]
            fits = torch.cumsum(cost[order], 0) <= room
            self.stats["budget_capped"] += int((~fits).sum())
            cand = torch.zeros_like(cand)
            cand[order[fits]] = True
        clone = cand & ~big
        split = cand & big
        self.stats["cloned"] += int(clone.sum())
        self.stats["split"] += int(split.sum())
        self.stats["pruned"] += int(prune.sum())

        new = self._split_values(params, split)
        for k, v in params.items():
            new[k] = torch.cat([v.data[clone], new[k]], 0)
        keep = ~(prune | split)  # split originals are replaced by their children
        self._replace(params, optimizer, keep, new)
        self._reset_stats(len(params["means"]), params["means"].device)

    def _split_values(self, params, split):
        n = self.cfg.split_n
        means = params["means"].data[split]
        scales = torch.exp(params["log_scales"].data[split])
        q = params["quats"].data[split]
        rot = quat_to_rotmat(q / q.norm(dim=-1, keepdim=True))
        samples = torch.randn(n, *means.shape, device=means.device, dtype=means.dtype) * scales
        new_means = (means + torch.einsum("nij,knj->kni", rot, samples)).reshape(-1, 3)
        out = {}
        for k, v in params.items():
            out[k] = v.data[split].repeat(n, *([1] * (v.dim() - 1)))
        out["means"] = new_means
        out["log_scales"] = torch.log(scales / (0.8 * n)).repeat(n, 1)
        return out

    def _replace(self, params, optimizer, keep, new):
        """params[k] <- cat(params[k][keep], new[k]); Adam moments kept for survivors, zero for new."""
        for group in optimizer.param_groups:
            name = group["name"]
            old = group["params"][0]
            p = torch.nn.Parameter(torch.cat([old.data[keep], new[name]], 0))
            state = optimizer.state.pop(old, None)
            if state:
                for key in ("exp_avg", "exp_avg_sq"):
                    s = state[key]
                    state[key] = torch.cat([s[keep], s.new_zeros((len(new[name]),) + s.shape[1:])], 0)
                optimizer.state[p] = state
            group["params"][0] = p
            params[name] = p

    @torch.no_grad()
    def _reset_opacity(self, params, optimizer):
        """Clamp opacities to <= 0.01 (INRIA) and zero their Adam moments."""
        o = params["opacity_logits"]
        o.data.clamp_(max=float(torch.logit(torch.tensor(0.01))))
        st = optimizer.state.get(o)
        if st:
            st["exp_avg"].zero_()
            st["exp_avg_sq"].zero_()
        self.n_resets += 1
        self.stats["resets"] += 1

    def prune(self, params, optimizer, keep):
        """Remove Gaussians where keep is False (outside the visual hull, at the end of training)."""
        empty = {k: v.data[:0] for k, v in params.items()}
        self._replace(params, optimizer, keep, empty)
        self._reset_stats(len(params["means"]), params["means"].device)


# the classes behind config.STRATEGY_NAMES, the names TrainConfig.strategy takes (tests/test_config_flags.py)
STRATEGIES = {"default": DensifyStrategy, "fixed": FixedStrategy}


def make_strategy(name, cfg: DensifyConfig, extent, hull=None) -> Strategy:
    if name not in STRATEGIES:
        raise UserError(f"unknown densification strategy '{name}' (choose from {', '.join(STRATEGIES)})")
    return STRATEGIES[name](cfg, extent, hull)
