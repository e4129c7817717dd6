"""Sample bike specs from the style ranges in blend_assets/bike_styles.yaml (no bpy).

A spec is a flat JSON-able dict: style, rideable, sampled numbers (metres, degrees), choices,
and a frame colour.  Every bike draws from its own generator seeded by (seed, style, number),
so a bike does not change when --count changes, and a resumed run rebuilds the same bikes.
"""
import os
import zlib

import numpy as np
import yaml

from ..contract import UserError
from . import layout

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))
STYLES_PATH = os.path.join(ROOT, "blend_assets", "bike_styles.yaml")


SADDLE_BROWNS = [[0.16, 0.06, 0.025], [0.42, 0.22, 0.08]]  # linear RGB: dark brown, tan leather


def load_styles(path=STYLES_PATH):
    try:
        with open(path) as f:
            doc = yaml.safe_load(f)
    except (OSError, yaml.YAMLError) as e:
        raise UserError(f"cannot read bike styles {path}: {e}") from None
    if not isinstance(doc, dict) or "styles" not in doc or "order" not in doc:
        raise UserError(f"bike styles {path}: expected keys 'order' and 'styles'")
    for name in list(doc["order"]) + list(doc.get("extras", [])):
        if name not in doc["styles"]:
            raise UserError(f"bike styles {path}: style '{name}' listed but not defined")
    return doc


def _draw(value, rng):
    if isinstance(value, list) and len(value) == 2 and all(isinstance(v, (int, float)) for v in value):
        lo, hi = float(value[0]), float(value[1])
        return float(rng.uniform(lo, hi))
    if isinstance(value, dict) and "choice" in value:
        opts = value["choice"]
        return opts[int(rng.integers(len(opts)))]
    if isinstance(value, dict) and "p" in value:
        return bool(rng.random() < float(value["p"]))
    return value


def _colour(hexes, rng):
    """One of the style's paints, jittered a little in brightness so repeats differ."""
    h = hexes[int(rng.integers(len(hexes)))].lstrip("#")
    rgb = np.array([int(h[i:i + 2], 16) / 255.0 for i in (0, 2, 4)])
    rgb = np.clip(rgb * rng.uniform(0.85, 1.1), 0, 1)
    return [float(c) for c in rgb ** 2.2]  # sRGB-ish -> linear for Base Color


def style_seed(seed, style, number):
    return [int(seed), zlib.crc32(style.encode()), int(number)]


def sample_spec(style, number, seed, styles=None, max_tries=500):
    """The spec of bike `<style>_<number:02d>` for a library seed (deterministic)."""
    styles = styles or load_styles()
    if style not in styles["styles"]:
        raise UserError(f"unknown bike style '{style}' (known: {', '.join(styles['styles'])})")
    ranges = styles["styles"][style]
    rng = np.random.default_rng(style_seed(seed, style, number))
    for _ in range(max_tries):
        spec = {"style": style, "bike_id": f"{style}_{number:02d}", "seed": int(seed), "number": int(number)}
        for key, value in ranges.items():
            if key in ("colours", "wheelbase_m"):
                continue
            spec[key] = _draw(value, rng)
        spec["frame_colour"] = _colour(ranges["colours"], rng)
        spec["accent_dark"] = bool(rng.random() < 0.6)  # black vs silver components
        leather = style in ("city", "cruiser") and rng.random() < 0.6
        spec["saddle_colour"] = SADDLE_BROWNS[int(rng.integers(2))] if leather else [0.012, 0.012, 0.012]
        wb_lo, wb_hi = ranges["wheelbase_m"]
        wb = layout.wheelbase(spec)
        if wb_lo <= wb <= wb_hi:
            spec["wheelbase_m"] = float(wb)
            return spec
    raise UserError(f"style '{style}': no draw in {max_tries} gave a wheelbase in {ranges['wheelbase_m']}")


def library_plan(count, seed, extras=True, styles=None):
    """[(style, number)] for a library: styles cycled in the YAML's order, then the extras."""
    styles = styles or load_styles()
    order = list(styles["order"])
    plan = [(order[i % len(order)], i // len(order)) for i in range(int(count))]
    if extras:
        plan += [(name, 0) for name in styles.get("extras", [])]
    return plan


def library_specs(count, seed, extras=True, styles=None):
    styles = styles or load_styles()
    return [sample_spec(st, n, seed, styles) for st, n in library_plan(count, seed, extras, styles)]
