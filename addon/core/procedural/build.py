"""build_bike(spec): the bike's part meshes, materials and armature in the current scene (bpy).

Meshes are built in the canonical frame by the numpy builders and converted once here with
frames.to_blender; each part is ONE mesh object (frame / steering / crank) with pass_index
1 / 2 / 3, rigidly parented to its bone of the object named `armature`.

With sub-parts (bicycles; docs/contract.md "Sub-parts") the wheels and the pedal bodies are
their own mesh objects (front_wheel, rear_wheel, pedal_left, pedal_right) cut from the same
geometry (the builders tag those faces), with their main part's pass_index; the armature then
spins the wheels about their axles and keeps the pedals level (armature.py, articulation.py).
"""
import bpy
import numpy as np

from ..rig import armature as arm_mod
from ..contract import bike_folder, instances
from ..frames import to_blender
from . import cockpit, drivetrain, extras, layout, tubes
from .materials import make_materials

PASS_INDEX = {**instances.PART_IDS, **instances.SUB_PART_IDS}  # docs/contract.md instance ids
CHAIN_PITCH_M = 0.0127  # 1/2-inch chain (wheels.chainring's tooth spacing)


def gear_ratio(spec):
    """Wheel turns per crank turn: chainring teeth / the middle rear cog's teeth (a cog of radius
    r has 2 pi r / pitch teeth); None for rideables without pedals."""
    if spec["rideable"] != "bicycle":
        return None
    cogs = tubes.cog_radii(spec)
    teeth = max(9, round(2 * np.pi * cogs[len(cogs) // 2] / CHAIN_PITCH_M))
    return round(float(spec["chainring_teeth"]) / teeth, 5)


def part_builders(spec, sub_parts=False):
    """{part: MeshBuilder} in the canonical frame (pure numpy; usable without Blender).
    sub_parts: bicycles' wheels and pedal bodies as their own builders (front_wheel, rear_wheel,
    pedal_left, pedal_right), cut out of frame / steering / crank; otherwise inside them."""
    L = layout.layout_for(spec)
    kind = spec["rideable"]
    if kind == "bicycle":
        main = {"frame": tubes.build_frame(spec, L), "steering": cockpit.build_steering(spec, L),
                "crank": drivetrain.build_crank(spec, L)}
        if not sub_parts:
            return L, main
        out, subs = {}, {}
        for name, mb in main.items():
            out[name], tagged = mb.split_tags()
            subs.update(tagged)
        return L, {**out, **{k: subs[k] for k in bike_folder.SUB_PARTS if k in subs}}
    if kind == "kick_scooter":
        return L, {"frame": extras.scooter_frame(spec, L), "steering": extras.scooter_steering(spec, L)}
    return L, {"frame": extras.motorcycle_frame(spec, L), "steering": extras.motorcycle_steering(spec, L)}


def mesh_object(name, mb, materials, collection=None):
    """One Blender mesh object from a MeshBuilder (canonical -> Blender coordinates)."""
    verts = to_blender(mb.vertices)
    mesh = bpy.data.meshes.new(name)
    mesh.from_pydata([tuple(v) for v in verts], [], mb.faces)
    keys = []
    for m in mb.materials:
        if m not in keys:
            keys.append(m)
    for k in keys:
        mesh.materials.append(materials[k])
    idx = {k: i for i, k in enumerate(keys)}
    mesh.polygons.foreach_set("material_index", [idx[m] for m in mb.materials])
    mesh.polygons.foreach_set("use_smooth", mb.smooth)
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    (collection or bpy.context.scene.collection).objects.link(obj)
    obj.pass_index = PASS_INDEX[name]
    return obj


def build_bike(spec, sub_parts=False):
    """Build the bike in the current scene. Returns dict(parts={name: obj}, armature=obj,
    keypoints={name: [x, y, z] canonical}, layout=..., triangles={part: n}, gear_ratio=float or
    None).  sub_parts: see part_builders (only bicycles have them)."""
    L, builders = part_builders(spec, sub_parts)
    kp = layout.keypoints(spec, L)
    mats = make_materials(spec)
    parts = {name: mesh_object(name, mb, mats) for name, mb in builders.items()}
    g = gear_ratio(spec)
    arm = arm_mod.build_armature(kp, spec, list(parts), gear_ratio=g)
    for name, obj in parts.items():
        arm_mod.attach(obj, arm, name)
    bpy.context.view_layer.update()
    return {"parts": parts, "armature": arm, "keypoints": kp, "layout": L, "gear_ratio": g,
            "triangles": {n: int(mb.triangle_count()) for n, mb in builders.items()}}


def dimensions(spec, L):
    """Measured dimensions for meta.json (metres, degrees)."""
    u = L["u"]
    d = {"wheel_diameter_m": 2 * L["R"],
         "wheelbase_m": float(L["front_axle"][0] - L["rear_axle"][0]),
         "head_angle_deg": float(np.degrees(np.arctan2(u[1], -u[0]))),
         "tyre_width_m": spec["tyre_width_m"]}
    if spec["rideable"] == "bicycle":
        sd = L["sdir"]
        fa = L["front_axle"]
        # trail: where the steering axis meets the ground, minus the front contact point
        hb = L["head_bottom"]
        x_ground = hb[0] - hb[1] * (-u[0] / u[1])
        d.update({"seat_angle_deg": float(np.degrees(np.arctan2(sd[1], -sd[0]))),
                  "bb_height_m": float(L["bb"][1]),
                  "chainstay_m": spec["chainstay_m"],
                  "stack_m": float(L["head_top"][1] - L["bb"][1]),
                  "reach_m": float(L["head_top"][0]),
                  "head_tube_m": spec["head_tube_m"],
                  "fork_axle_to_crown_m": float(L["fork_a2c"]),
                  "fork_offset_m": spec["fork_offset_m"],
                  "trail_m": float(x_ground - fa[0]),
                  "seat_tube_m": float(L["seat_tube_m"]),
                  "saddle_height_m": spec["saddle_height_m"],
                  "crank_length_m": spec["crank_length_m"],
                  "bar_width_m": spec["bar_width_m"],
                  "handlebar": spec["handlebar"],
                  "frame_type": spec["frame_type"]})
    else:
        d["bar_width_m"] = spec["bar_width_m"]
    return {k: (round(v, 5) if isinstance(v, float) else v) for k, v in d.items()}
