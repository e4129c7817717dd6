"""URDF export: three links (frame, steering, crank), a revolute steering joint and a continuous
crank joint, OBJ meshes, inertials from mesh volume at a stated density (numpy only).

Frame: ROS REP-103 (x forward, y left, z up), metres, which is exactly the Blender frame:
URDF (x, y, z) = canonical (X, -Z, Y).  Each child link's frame sits at its pivot (a point on
its joint axis: steer_bottom, crank_axle) with the root's orientation, so joint values are the
8-DoF pose's angles in radians: steering = theta_s, crank = theta_p (forward pedalling positive).
keypoints.json beside the URDF gives every bike keypoint as (link, position in that link's frame).
"""
import json
import os
import xml.etree.ElementTree as ET

from .. import frames
from .mass import mass_properties
from .meshes import write_obj

JOINT_EFFORT_NM = 100.0  # nominal actuator limits: URDF requires them on a revolute joint
JOINT_VELOCITY_RAD_S = 10.0


def _xyz(v):
    return " ".join(f"{float(x):.9g}" for x in v)


def build(rig, meshes, density, steer_limit_rad, name, hull=None):
    """-> (urdf text, {relative path: bytes-producing writer}, keypoints doc, {part: MassProperties})."""
    robot = ET.Element("robot", name=name)
    robot.append(ET.Comment(
        f" exported by 3DArticCyclists blender_scripts/export_bike.py; frame: x forward, y left, z up (m); "
        f"inertials from mesh volume at a stated density of {density:g} kg/m^3 (solid meshes) "))
    files, masses = {}, {}
    for part in rig.parts:
        if part not in meshes:
            continue
        m = meshes[part]
        origin = frames.to_blender(rig.origin(part))
        verts = frames.to_blender(m.verts) - origin  # in the link's frame
        mp = mass_properties(verts, m.tris, density, hull=hull)
        masses[part] = mp
        link = ET.SubElement(robot, "link", name=part)
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "origin", xyz=_xyz(mp.com), rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=f"{mp.mass:.9g}")
        I = mp.inertia
        ET.SubElement(inertial, "inertia", ixx=f"{I[0, 0]:.9g}", ixy=f"{I[0, 1]:.9g}", ixz=f"{I[0, 2]:.9g}",
                      iyy=f"{I[1, 1]:.9g}", iyz=f"{I[1, 2]:.9g}", izz=f"{I[2, 2]:.9g}")
        rel = f"meshes/{part}.obj"
        for tag in ("visual", "collision"):
            el = ET.SubElement(link, tag)
            ET.SubElement(el, "origin", xyz="0 0 0", rpy="0 0 0")
            ET.SubElement(ET.SubElement(el, "geometry"), "mesh", filename=rel)
            if tag == "visual":
                mat = ET.SubElement(el, "material", name=f"{part}_colour")
                ET.SubElement(mat, "color", rgba=_xyz(m.area_weighted_colour()))
        files[rel] = (verts, m, f"{part}.mtl")
    for j in rig.joints:
        if j.name not in meshes:
            continue
        joint = ET.SubElement(robot, "joint", name=j.name, type=j.kind)
        ET.SubElement(joint, "parent", link=j.parent)
        ET.SubElement(joint, "child", link=j.name)
        # parent frames sit at the origin (frame is the only parent), so the pivot is the offset
        ET.SubElement(joint, "origin", xyz=_xyz(frames.to_blender(j.pivot) - frames.to_blender(rig.origin(j.parent))),
                      rpy="0 0 0")
        ET.SubElement(joint, "axis", xyz=_xyz(frames.to_blender(j.axis)))
        if j.kind == "revolute":
            ET.SubElement(joint, "limit", lower=f"{-steer_limit_rad:.9g}", upper=f"{steer_limit_rad:.9g}",
                          effort=f"{JOINT_EFFORT_NM:g}", velocity=f"{JOINT_VELOCITY_RAD_S:g}")
    ET.indent(robot)
    text = '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"
    kp = {"frame": "URDF link frames: x forward, y left, z up", "units": "m",
          "joints": {"steering": "theta_s of the 8-DoF pose (radians), + turns the front wheel left",
                     "crank": "theta_p of the 8-DoF pose (radians), + is forward pedalling"},
          "density_kg_m3": density,
          "mass_kg": {p: round(float(mp.mass), 6) for p, mp in masses.items()},
          "keypoints": {k: {"link": rig.keypoint_part[k],
                            "xyz": [float(x) for x in frames.to_blender(v) - frames.to_blender(rig.origin(rig.keypoint_part[k]))]}
                        for k, v in rig.keypoints.items() if rig.keypoint_part[k] in meshes}}
    return text, files, kp, masses


def write(folder, name, text, files, kp):
    """Write <folder>/<name>.urdf, meshes/*.obj|mtl and keypoints.json into an existing empty folder."""
    os.makedirs(os.path.join(folder, "meshes"), exist_ok=True)
    for rel, (verts, mesh, mtl) in files.items():
        with open(os.path.join(folder, rel), "w") as fo, \
                open(os.path.join(folder, "meshes", mtl), "w") as fm:
            write_obj(fo, fm, mtl, verts, mesh)
    with open(os.path.join(folder, name + ".urdf"), "w") as f:
        f.write(text)
    with open(os.path.join(folder, "keypoints.json"), "w") as f:
        json.dump(kp, f, indent=1)
        f.write("\n")
