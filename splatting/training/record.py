"""A trained model's training record, read one way for every stage.

What the trainer wrote beside the Gaussians tells a renderer how to draw them as they were trained:
the screen-space low-pass eps2d (px^2) and whether the mip filter (antialiased splatting) was on.
The rules, in one place:
  - a part's metrics are gaussians/<part>.json, else <part>_rest.json (a part fine-tuned by the
    library's posed stage keeps its training metrics with the rest-trained part);
  - its "config" holds "eps2d" and "antialiased"; EPS2D (0.3) and plain where nothing records them
    (assets made before they were recorded were all trained that way);
  - gaussians/posed_train.json (bike-posed-train) records the fine-tune's eps2d and the parts it
    wrote with their Gaussian counts: a part with that count was last drawn by the fine-tune;
  - an avatar's record is rider.json's "config";
  - parts of one bike that disagree are an error: a bike is one model, drawn with one filter.
Used by splatting.bike.model (BikeModel), bike.posed_train, relight.fit and rider.avatar.

The "config" of each record is cyclist_formats.typed_config.record_of(cfg): the one place a training
config (trainer.TrainConfig, bike.posed_train.PosedTrainConfig) becomes the dict a record holds.
"""
import math
import os

from cyclist_formats import bike_folder
from cyclist_formats.atomic import read_json_or_none
from cyclist_formats.errors import UserError
from splatting.raster.api import EPS2D


def check_model_eps2d(v, source):
    """A model's recorded eps2d: a finite number > 0 (UserError naming the source otherwise)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
        raise UserError(f"{source}: eps2d (the splats' low-pass the model was trained with) must be a "
                        f"finite number > 0, got {v!r}")
    return float(v)


def part_metrics_path(gdir, p):
    """A part's training metrics: gaussians/<part>.json, else <part>_rest.json (a part fine-tuned by
    the library's posed stage keeps its training metrics with the rest-trained part); None without."""
    for js in (os.path.join(gdir, p + ".json"), os.path.join(gdir, p + "_rest.json")):
        if os.path.isfile(js):
            return js
    return None


def part_config(gdir, p):
    """The "config" of the part's training metrics (part_metrics_path); None without metrics."""
    js = part_metrics_path(gdir, p)
    if js is None:
        return None
    doc = bike_folder.read_json(js, f"{p}.json")
    cfg = doc.get("config") if isinstance(doc, dict) else None
    return cfg if isinstance(cfg, dict) else None


def fine_tuned_eps2d(gdir):
    """(eps2d, {part: Gaussians}) of gaussians/posed_train.json: the low-pass its fine-tune
    rendered with (config "eps2d"; 0.3 in records from before --eps2d) and the parts it wrote, or
    None without a record (BikeModel reads each part's filter with it)."""
    m = read_json_or_none(os.path.join(gdir, "posed_train.json"))
    if not isinstance(m, dict) or not isinstance(m.get("config"), dict) or not isinstance(m.get("gaussians"), dict):
        return None
    return m["config"].get("eps2d", EPS2D), m["gaussians"]


def trained_eps2d(gdir, counts, fine_tuned=True):
    """The screen-space low-pass (px^2) the parts in gdir ({name: Gaussians in its .ply}) were last
    trained with: with fine_tuned, a part that bike-posed-train wrote (gaussians/posed_train.json
    records it with this many Gaussians; counted, not dated: a copied folder keeps no file times)
    has the fine-tune's (fine_tuned_eps2d), any other its <part>.json "config" "eps2d"
    (trainer.TrainConfig); EPS2D (0.3) where nothing records one.  Parts that disagree are an
    error, as for the mip filter."""
    posed = fine_tuned_eps2d(gdir) if fine_tuned else None
    vals = {}
    for p, n in counts.items():
        if posed is not None and posed[1].get(p) == n:
            vals[p] = check_model_eps2d(posed[0], os.path.join(gdir, "posed_train.json"))
        else:
            cfg = part_config(gdir, p)
            vals[p] = check_model_eps2d((cfg or {}).get("eps2d", EPS2D), os.path.join(gdir, p + ".json"))
    if len(set(vals.values())) > 1:
        raise UserError(f"{gdir}: parts trained with different eps2d ({', '.join(f'{p}: {v}' for p, v in vals.items())}); "
                        "retrain or fine-tune them with one value")
    return next(iter(vals.values()), EPS2D)


def trained_antialiased(gdir, names):
    """Whether the parts in gdir were trained with antialiased splatting: their part_config's
    "antialiased"; a part without metrics, e.g. imported, counts as plain.  Parts that disagree are
    an error: one renderer setting cannot draw both right (a mixed bike lost ~2 dB, docs/training.md)."""
    flags = {}
    for p in names:
        cfg = part_config(gdir, p)
        flags[p] = bool(cfg.get("antialiased", False)) if cfg is not None else False
    if len(set(flags.values())) > 1:
        raise UserError(f"{gdir}: parts trained with and without antialiasing "
                        f"({', '.join(f'{p}: {v}' for p, v in flags.items())}); retrain them with one setting")
    return any(flags.values())


def ply_trained_antialiased(ply_path):
    """Whether the Gaussians at ply_path were trained with the mip filter: their <stem>.json's
    "config" (trained_antialiased's rule; no metrics: plain)."""
    stem = os.path.splitext(os.path.basename(ply_path))[0]
    return trained_antialiased(os.path.dirname(ply_path), [stem])


def ply_trained_eps2d(ply_path, count):
    """The eps2d the Gaussians at ply_path (count of them) were last trained with (trained_eps2d)."""
    stem = os.path.splitext(os.path.basename(ply_path))[0]
    return trained_eps2d(os.path.dirname(ply_path), {stem: count})


def avatar_trained_eps2d(folder):
    """The screen-space low-pass (px^2) an avatar's Gaussians were trained with: rider.json's
    "config" "eps2d" (the trainer's record; rider-posed-train fine-tunes with the same value),
    0.3 for avatars trained before it was recorded or without metrics."""
    m = read_json_or_none(os.path.join(folder, "rider.json"))
    cfg = m.get("config") if isinstance(m, dict) else None
    return check_model_eps2d(cfg.get("eps2d", EPS2D) if isinstance(cfg, dict) else EPS2D,
                             os.path.join(folder, "rider.json"))
