"""Level of detail: a far instance is rendered with a fraction of its Gaussians.

A cyclist 40 m away is ~30 px tall; its ~20-70k Gaussians then share a few hundred pixels and most
of them change nothing a detector could see.  Each asset's Gaussians are ranked once by an
importance, opacity x the largest scale (measured against opacity alone, x area and x volume),
ties broken by a fixed random permutation (so equal-sized Gaussians, e.g. a mesh
avatar's, thin out evenly over the body instead of by index), each part on its own (see ranking).  Level `keep` = the top
ceil(keep N) of the ranking, so a smaller level is a subset of a larger one; the kept Gaussians'
scales grow by (total importance / kept importance) ** (compensate / 2), per part, so the level
covers about what the full part covers (compensate = 0: plain top-k; 1 measured best).  Which level an instance gets follows its height on
screen: the level with the smallest `below_px` above the instance's pixel height (config
`lod.levels`; bench/lod.py measures box PSNR and mask IoU per level and height and chose the
defaults).
"""
import math
from dataclasses import replace

import torch

from splatting.cyclist.look_defaults import DEFAULT_COMPENSATE, DEFAULT_LEVELS  # noqa: F401 (bench/lod.py reads them here)


def importance(g):
    """(N,) opacity x the largest scale (bench/lod.py: on a trained bike this keeps thin tubes and
    spokes far better than opacity x area or x volume, which favour the big, blurry Gaussians)."""
    return torch.sigmoid(g.opacity_logits) * torch.exp(g.log_scales.max(1).values)


def ranking(g, groups=None, seed=0):
    """(N,) long: Gaussian indices, most important first (ties in a fixed random order).  groups
    (N,) ints (e.g. part ids): each group is ranked on its own and the groups are interleaved by
    rank quantile, so every prefix keeps about the same share of every part (a rider made of
    smaller Gaussians than its bike does not vanish from the small levels)."""
    n = len(g)
    perm = torch.randperm(n, generator=torch.Generator().manual_seed(seed))
    imp = importance(g).double()[perm]
    order = perm[torch.argsort(-imp, stable=True)]
    if groups is None:
        return order
    gr = torch.as_tensor(groups).long()[order]
    quantile = torch.empty(n, dtype=torch.float64)
    for v in gr.unique():
        m = torch.nonzero(gr == v).squeeze(1)  # this group's members, most important first
        quantile[m] = (torch.arange(len(m), dtype=torch.float64) + 0.5) / len(m)
    return order[torch.argsort(quantile, stable=True)]


def level_keep(height_px, levels):
    """The share of Gaussians for an instance height_px tall: the smallest level's keep among the
    levels with below_px > height_px, 1 when none."""
    keep = 1.0
    for lv in sorted(levels, key=lambda x: -x["below_px"]):
        if height_px < lv["below_px"]:
            keep = lv["keep"]
    return float(keep)


def kept(order, keep):
    """Indices (ascending) of the level keeping `keep` of the ranked Gaussians."""
    n = max(1, math.ceil(keep * len(order))) if len(order) else 0
    return order[:n].sort().values


def reduce(g, order, keep, compensate=DEFAULT_COMPENSATE, groups=None):
    """(Gaussians of the level, their indices into g); keep >= 1 returns g itself.  The kept
    Gaussians of each group (all one group when groups is None) grow by that group's
    sqrt(total / kept importance) ** compensate."""
    if keep >= 1.0:
        return g, torch.arange(len(g))
    idx = kept(order, keep)
    sub = g[idx]
    if compensate:
        imp = importance(g).double()
        gr = torch.zeros(len(g), dtype=torch.long) if groups is None else torch.as_tensor(groups).long()
        total = torch.zeros(int(gr.max()) + 1, dtype=torch.float64).index_add_(0, gr, imp)
        part = torch.zeros_like(total).index_add_(0, gr[idx], imp[idx])
        grow = 0.5 * compensate * torch.log(total / part.clamp_min(1e-30)).clamp_min(0.0)
        sub = replace(sub, log_scales=sub.log_scales + grow[gr[idx]].to(sub.log_scales.dtype)[:, None])
    return sub, idx


def height_px(h_m, depth_m, fy):
    """Screen height of an instance h_m tall at camera depth depth_m (pinhole, upright)."""
    return float(fy) * float(h_m) / max(float(depth_m), 1e-3)
