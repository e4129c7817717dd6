"""The IK's inputs: validation of user-given targets and tensors (one UserError line for NaN, wrong
shapes, missing targets)."""
import numpy as np
import torch

from cyclist_formats.errors import UserError


def finite_tensor(x, what, shape_tail, batch=None):
    try:
        t = torch.as_tensor(np.asarray(x, dtype=np.float64) if not torch.is_tensor(x) else x.detach(),
                            dtype=torch.float64)
    except (TypeError, ValueError) as e:
        raise UserError(f"ik: {what} is not numeric: {e}") from None
    if t.shape[-len(shape_tail):] != shape_tail or t.dim() > len(shape_tail) + 1:
        raise UserError(f"ik: {what} must have shape {tuple(shape_tail)} or (B, {', '.join(map(str, shape_tail))}), "
                        f"got {tuple(t.shape)}")
    if not torch.isfinite(t).all():
        raise UserError(f"ik: {what} contains NaN or Inf")
    if batch is not None and t.dim() == len(shape_tail) + 1 and t.shape[0] not in (1, batch):
        raise UserError(f"ik: {what} has {t.shape[0]} frames, expected {batch}")
    return t


def batch_of(t, tail):
    return t.shape[0] if t.dim() == tail + 1 else 1


# ------------------------------------------------------------------ the solver

def prepare_targets(targets, names, batch_hint):
    if not isinstance(targets, dict):
        raise UserError("ik: targets must be a dict name -> (B, 3) positions")
    missing = [n for n in names if n not in targets]
    if missing:
        raise UserError(f"ik: targets lack {', '.join(missing)} (have {', '.join(sorted(targets)) or 'none'})")
    ts = {n: finite_tensor(targets[n], f"target {n!r}", (3,)) for n in names}
    B = max([batch_hint] + [batch_of(t, 1) for t in ts.values()])
    for n, t in ts.items():
        if t.dim() == 2 and t.shape[0] not in (1, B):
            raise UserError(f"ik: target {n!r} has {t.shape[0]} frames, others have {B}")
    return {n: t.reshape(-1, 3).expand(B, 3) for n, t in ts.items()}, B
