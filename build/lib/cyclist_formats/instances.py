"""Instance ids (docs/contract.md "Instance ids"): Blender pass_index, rendered id masks and the
Gaussians' id channel all use these numbers; 0 is background."""

PART_IDS = {"frame": 1, "steering": 2, "crank": 3}
RIDER_ID = 4
IDS = {**PART_IDS, "rider": RIDER_ID}
ID_NAMES = {v: k for k, v in IDS.items()}
# optional wheel and pedal sub-parts move with the part they belong to, so they share its id
SUB_PART_IDS = {"rear_wheel": PART_IDS["frame"], "front_wheel": PART_IDS["steering"],
                "pedal_left": PART_IDS["crank"], "pedal_right": PART_IDS["crank"]}
