"""The looks' config-facing constants, without torch: the dataset config's models
(splatting/dataset/config_models.py) take their defaults from here, and `--help` stays fast."""
# HAIR_STYLES: what `appearance.hair_styles` may list, from the torch-free names module (not
# splatting/rider/looks.py, which loads numpy and torch)
from splatting.rider.look_names import HAIR_STYLES  # noqa: F401

# measured by bench/lod.py (docs/street_scenes.md): each level costs <= 0.5 dB box PSNR below its height
DEFAULT_LEVELS = [{"below_px": 55, "keep": 0.7}, {"below_px": 45, "keep": 0.5}]
DEFAULT_COMPENSATE = 1.0

RECOLOUR = ("top", "bottom", "shoes", "helmet", "paint")  # regions appearance variety can recolour
# the roster's looks added hair and bags (splatting/rider/looks.py): drawn from their own Generator, so the
# draws above (and every dataset made before) stay as they were
RECOLOUR_EXTRA = ("hair", "bag")
