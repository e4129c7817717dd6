"""The Blender oracle: pose the articulated mesh with an 8-DoF pose and render it from a camera.

This is the ground truth every Gaussian-space result is checked against (docs/contract.md).
"""
import os

import numpy as np

from .. import frames
from . import render
from ..contract import UserError, bike_folder, ring
from ..contract import pose as pose_format

POSE_FIELDS = pose_format.POSE_FIELDS


def parse_pose(text):
    """'p,s,X,Y,Z,tx,ty,tz' (degrees, metres) -> list of 8 finite floats."""
    return [float(v) for v in pose_format.parse_pose_string(text)]


def load_camera(spec, bike_dir):
    """'FILE:cameraNNNN' (a SHERF cameras.json) or 'FILE' holding one {"K","R","T"}.

    A FILE that does not exist as given is looked up in the bike's views/whole/.
    """
    path, _, name = spec.partition(":") if not os.path.isfile(spec) else (spec, "", "")
    if not os.path.isfile(path):
        alt = os.path.join(bike_dir, "views", "whole", path)
        if not os.path.isfile(alt):
            raise UserError(f"no camera file: {path}")
        path = alt
    if name:
        return ring.camera_entry(path, name)
    cam = bike_folder.read_json(path, "camera file")
    try:
        K, R, T = (np.asarray(cam[k], float) for k in ("K", "R", "T"))
        K, R, T = K.reshape(3, 3), R.reshape(3, 3), T.reshape(3)
    except (KeyError, ValueError, TypeError):
        raise UserError(f"camera '{name or path}' needs K (3x3), R (3x3) and T (3)")
    return K, R, T


def render_pose(bike_dir, pose, camera, out, keypoints_out=None, settings=None, lights_follow=True):
    import bpy

    from ..rig.articulation import apply_pose, global_matrix, posed_keypoints
    from ..contract import write_json
    from ..bike_asset import open_bike

    K, R, T = load_camera(camera, bike_dir)
    bike = open_bike(bike_dir)
    scene = bpy.context.scene
    size = int(round(2 * K[0, 2]))
    if abs(K[0, 0] - K[1, 1]) > 1e-6 * K[0, 0] or abs(2 * K[1, 2] - size) > 0.5:
        raise UserError("render_pose supports square pixels with the principal point at the image centre")
    s = settings or render.RenderSettings()
    from dataclasses import replace

    s = replace(s, size=size)
    render.configure_cycles(scene, s)
    render.setup_lighting(scene)
    apply_pose(bike["armature"], pose[0], pose[1], tuple(pose[2:5]), tuple(pose[5:8]))
    if lights_follow:
        # the Gaussians carry the shading they were trained with; moving the sun with the bike
        # keeps that shading, so the comparison measures geometry and not relighting
        import mathutils

        Hb = mathutils.Matrix(frames.matrix_to_blender(global_matrix(pose[2:5], pose[5:8])).tolist())
        for o in scene.objects:
            if o.type == "LIGHT":
                o.matrix_world = Hb @ o.matrix_world
    render.show_only(scene, list(bike["parts"].values()))
    cam = render.ensure_camera(scene, size, K[0, 0])
    render.place_camera(cam, R, T)
    bpy.context.view_layer.update()
    paths = render.render_atomic(scene, out)
    if keypoints_out:
        write_json(keypoints_out, {"frame": "canonical", "units": "m", "pose": dict(zip(POSE_FIELDS, pose)),
                                   "keypoints": {k: list(map(float, v)) for k, v in posed_keypoints(bike["armature"]).items()}})
    return paths
