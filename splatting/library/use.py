"""What a dataset may use: trained assets only, unless stand-ins are asked for explicitly.

`synthetic_assets: always` is the opt-in to stand-in Gaussians (keypoint tubes, an untrained
mesh avatar).  Otherwise ('auto' and 'never' alike) every bike and rider the config resolves to
must have trained Gaussians; a missing one is an error naming the command that builds it, never
a silent fallback.  Where a library.json lies beside the bikes (OUT/library.json for
OUT/bikes), an asset it marks below the quality floor is refused unless allow_low_quality.
"""
import os

from cyclist_formats.errors import UserError
from splatting.cyclist.assets import has_trained_gaussians
from splatting.dataset.config import resolve_assets
from splatting.library.manifest import load_manifest
from splatting.rider.avatar import PLY_NAME, SKINNING_NAME


def _manifest_for(bikes_root):
    return load_manifest(os.path.dirname(os.path.abspath(bikes_root)))


def check_dataset_assets(cfg, allow_low_quality=False):
    """Raise UserError naming the first unusable asset of a validated config; returns the resolved config."""
    cfg = resolve_assets(cfg)
    if cfg.synthetic_assets == "always":
        return cfg
    root = os.path.dirname(os.path.abspath(cfg.bikes_root)) or "."
    for b in cfg.bikes:
        d = b if os.path.isdir(b) else os.path.join(cfg.bikes_root, b)
        if not has_trained_gaussians(d):
            bid = os.path.basename(os.path.normpath(d))
            raise UserError(f"bike {bid} has no trained part Gaussians ({os.path.join(d, 'gaussians')}); build them with "
                            f"`python -m splatting library build --out {root} --bikes {bid}`, "
                            f"or set synthetic_assets: always for keypoint stand-ins")
    for r in cfg.riders:
        folder = os.path.join(cfg.riders_root, r)
        if not all(os.path.isfile(os.path.join(folder, f)) for f in (PLY_NAME, SKINNING_NAME)):
            raise UserError(f"rider {r} has no trained avatar in {folder}; build it with "
                            f"`python -m splatting library build --out {root} --riders {r} --riders-root {cfg.riders_root}`"
                            f", or set synthetic_assets: always for the untrained mesh avatar")
    doc = _manifest_for(cfg.bikes_root)
    if doc is not None and not allow_low_quality:
        for kind, ids in (("bikes", cfg.bikes), ("riders", cfg.riders)):
            for a in ids:
                rec = doc.get(kind, {}).get(os.path.basename(os.path.normpath(a)))
                if rec is not None and not rec.get("usable", False):
                    why = "; ".join(rec.get("below_floor") or []) or "incomplete build"
                    raise UserError(f"{kind[:-1]} {a} is marked unusable in {os.path.join(root, 'library.json')} "
                                    f"({why}); rebuild it with a larger budget, or pass --allow-low-quality")
    return cfg
