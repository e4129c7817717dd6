"""The looks' config-facing constants, without torch: the dataset config's models
(splatting/dataset/config_models.py) take their defaults from here, and `--help` stays fast."""

# measured by bench/lod.py (docs/street_scenes.md): each level costs <= 0.5 dB box PSNR below its height
DEFAULT_LEVELS = [{"below_px": 55, "keep": 0.7}, {"below_px": 45, "keep": 0.5}]
DEFAULT_COMPENSATE = 1.0

RECOLOUR = ("top", "bottom", "shoes", "helmet", "paint")  # regions appearance variety can recolour
# the roster's looks added hair and bags (splatting/rider/looks.py): drawn from their own Generator, so the
# draws above (and every dataset made before) stay as they were
RECOLOUR_EXTRA = ("hair", "bag")
# the hair styles of the roster's looks (splatting/rider/looks.py HAIR_STYLES, which loads numpy and torch;
# tests/test_accessories.py checks they are the same): what `appearance.hair_styles` may list
HAIR_STYLES = ("bald", "buzz", "short", "long", "bun")
