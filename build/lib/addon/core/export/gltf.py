"""Binary glTF 2.0 export: the three parts as nodes pivoting on the steering axis and the crank
axle, keypoint nodes, and a pedalling + steering animation clip (numpy + json only).

Frame: the canonical one (X forward, Y up, Z right, metres).  glTF only asks for +Y up, and
Blender's importer maps glTF (x, y, z) to Blender (x, -z, y), which is docs/contract.md's Blender frame,
so the imported bike lands where bike.blend has it.

Nodes: `frame` (root, at the origin) with children `steering` (translation = steer_bottom) and
`crank` (translation = crank_axle); their meshes are stored relative to those pivots, so a node
rotation about the joint axis is the 8-DoF pose's H_s / H_p.  Every keypoint is an empty node
`kp_<name>` under the part that carries it.

Clip `pedal_steer` (LINEAR, keys every 10 degrees of crank): theta_p(t) = 360 deg * t / T,
theta_s(t) = A sin(2 pi t / T); T and A are arguments, and the per-key angles are repeated in the
animation's extras (theta_p_deg, theta_s_deg) so a consumer can map keys back to poses.
"""
import json
import math
import struct

import numpy as np

from .articulation import quaternion_xyzw

CLIP_KEYS = 36  # one key per 10 degrees of crank; linear slerp between keys stays on the axis


class _Buffer:
    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def add(self, arr, component, type_, target=None, minmax=False):
        arr = np.ascontiguousarray(arr)
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": arr.nbytes}
        if target:
            view["target"] = target
        self.data += arr.tobytes()
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": component,
               "count": int(arr.shape[0]), "type": type_}
        if minmax:
            acc["min"] = [float(x) for x in arr.reshape(arr.shape[0], -1).min(0)]
            acc["max"] = [float(x) for x in arr.reshape(arr.shape[0], -1).max(0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


FLOAT, UINT32 = 5126, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


def build(rig, meshes, name, clip_seconds=2.0, clip_steer_rad=math.radians(20.0)):
    """-> glb bytes."""
    buf = _Buffer()
    materials, mat_index = [], {}
    gl_meshes, nodes = [], []
    part_node = {}
    for part in rig.parts:
        if part not in meshes:
            continue
        m = meshes[part]
        local = (m.verts - rig.origin(part)).astype(np.float32)
        prims = []
        for k in np.unique(m.mat):
            mname, rgba, metal, rough = m.materials[k] if m.materials else ("default", (0.8, 0.8, 0.8, 1.0), 0.0, 0.6)
            if mname not in mat_index:
                mat_index[mname] = len(materials)
                materials.append({"name": mname, "pbrMetallicRoughness": {
                    "baseColorFactor": [float(x) for x in rgba], "metallicFactor": float(metal),
                    "roughnessFactor": float(rough)},
                    "doubleSided": True})
            t = m.tris[m.mat == k]
            used, inv = np.unique(t, return_inverse=True)  # each primitive carries only its vertices
            pos = buf.add(local[used], FLOAT, "VEC3", ARRAY_BUFFER, minmax=True)
            idx = buf.add(inv.reshape(-1).astype(np.uint32), UINT32, "SCALAR", ELEMENT_ARRAY_BUFFER)
            prims.append({"attributes": {"POSITION": pos}, "indices": idx, "material": mat_index[mname]})
        gl_meshes.append({"name": part, "primitives": prims})
        node = {"name": part, "mesh": len(gl_meshes) - 1}
        j = rig.joint(part)
        if j is not None:
            node["translation"] = [float(x) for x in j.pivot - rig.origin(j.parent)]
        part_node[part] = len(nodes)
        nodes.append(node)
    for k, v in rig.keypoints.items():
        p = rig.keypoint_part[k]
        if p not in part_node:
            continue
        nodes.append({"name": f"kp_{k}", "translation": [float(x) for x in v - rig.origin(p)]})
        nodes[part_node[p]].setdefault("children", []).append(len(nodes) - 1)
    root = part_node["frame"]
    nodes[root]["children"] = sorted(set(nodes[root].get("children", []))
                                     | {part_node[j.name] for j in rig.joints if j.name in part_node})

    times = np.linspace(0.0, clip_seconds, CLIP_KEYS + 1)
    phase = 2 * math.pi * times / clip_seconds
    angles = {"crank": phase, "steering": clip_steer_rad * np.sin(phase)}
    t_acc = buf.add(times.astype(np.float32), FLOAT, "SCALAR", minmax=True)
    samplers, channels = [], []
    for j in rig.joints:
        if j.name not in part_node:
            continue
        q = np.stack([quaternion_xyzw(j.axis, a) for a in angles[j.name]]).astype(np.float32)
        samplers.append({"input": t_acc, "output": buf.add(q, FLOAT, "VEC4"), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": part_node[j.name], "path": "rotation"}})
    doc = {
        "asset": {"version": "2.0", "generator": "3DArticCyclists export_bike.py"},
        "extras": {"frame": "canonical bike frame: X forward, Y up, Z right (m)"},
        "scene": 0, "scenes": [{"name": name, "nodes": [root]}],
        "nodes": nodes, "meshes": gl_meshes, "materials": materials,
        "animations": [{"name": "pedal_steer", "samplers": samplers, "channels": channels,
                        "extras": {"theta_p_deg": [float(x) for x in np.degrees(angles["crank"])],
                                   "theta_s_deg": [float(x) for x in np.degrees(angles["steering"])]}}],
        "buffers": [{"byteLength": 0}], "bufferViews": buf.views, "accessors": buf.accessors,
    }
    if not channels:
        del doc["animations"]
    while len(buf.data) % 4:
        buf.data.append(0)
    doc["buffers"][0]["byteLength"] = len(buf.data)
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    total = 12 + 8 + len(js) + 8 + len(buf.data)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(js), 0x4E4F534A) + js
            + struct.pack("<II", len(buf.data), 0x004E4942) + bytes(buf.data))
