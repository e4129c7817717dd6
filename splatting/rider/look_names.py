"""The names a rider's look may take that configs refer to, without numpy or torch: the dataset
config's `appearance.hair_styles` is checked against them at --help / validation time
(splatting/cyclist/look_defaults.py), and splatting/rider/looks.py draws and dresses them."""

HAIR_STYLES = ("bald", "buzz", "short", "long", "bun")
