"""Operators of the annotator panel.

Each operator is a thin wrapper over the curation functions in addon/core/curation/ (the same
ones blender_scripts/curate.py calls headless): a UserError becomes an ERROR report and
CANCELLED (bpy.ops then raises RuntimeError with the message).  The curation modules load
inside the operators: they need numpy, and the add-on registers without it (requirements.py).
"""
import math
import os

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, StringProperty

from .core.script import UserError

PART_ITEMS = [("frame", "Frame", "frame, rear wheel, saddle"), ("steering", "Steering", "fork, front wheel, bar"),
              ("crank", "Crank", "crank arms, chainring, pedals"),
              ("junk", "Junk", "not the bike (a rider, a stand, a ground): left out of every part")]


class _Op:
    bl_options = {"REGISTER", "UNDO"}

    def execute(self, context):
        from .requirements import requirements_problem
        if requirements_problem():  # no numpy: say what to install, not ModuleNotFoundError
            self.report({"ERROR"}, requirements_problem())
            return {"CANCELLED"}
        try:
            msg = self.run(context)
        except UserError as e:
            self.report({"ERROR"}, str(e))
            return {"CANCELLED"}
        if msg:
            self.report({"INFO"}, msg)
        return {"FINISHED"}


class ARTICCYC_OT_import_model(_Op, bpy.types.Operator):
    """Import a bicycle model (.glb .gltf .obj .fbx .ply .stl .blend) into an emptied scene"""
    bl_idname = "articcyc.import_model"
    bl_label = "Import model"
    filepath: StringProperty(name="Model", subtype="FILE_PATH", default="")
    clear_scene: BoolProperty(name="Clear scene", default=True)

    def invoke(self, context, event):
        if not self.filepath and context.scene.articcyc_model_path:
            self.filepath = bpy.path.abspath(context.scene.articcyc_model_path)
        if self.filepath:
            return self.execute(context)
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        from .core.curation import importers
        path = bpy.path.abspath(self.filepath or context.scene.articcyc_model_path)
        if not path:
            raise UserError("no model file given")
        if self.clear_scene:
            for o in list(context.scene.objects):
                bpy.data.objects.remove(o, do_unlink=True)
        new = importers.import_model(path)
        context.scene.articcyc_model_path = path
        context.scene.articcyc_problems.clear()
        return f"imported {len(new)} object(s) from {path}"


class ARTICCYC_OT_auto_curate(_Op, bpy.types.Operator):
    """Remove non-bike objects, find the wheels, put the bike in the canonical pose and scale,
    estimate keypoints and split the three parts"""
    bl_idname = "articcyc.auto_curate"
    bl_label = "Auto curate"
    wheel_diameter: FloatProperty(name="Wheel diameter (m)", default=0.0, min=0.0,
                                  description="tyre outer diameter; 0 = the panel's value")
    auto_wheel: BoolProperty(name="Automatic wheel size", default=False,
                             description="0.7 m, or for a kick scooter's small wheels the size that puts its bar 1 m high")
    keypoints_file: StringProperty(name="Keypoints JSON", subtype="FILE_PATH", default="",
                                   description="canonical keypoints that replace the automatic ones")

    def run(self, context):
        from .core.curation.curate_scene import auto_curate
        from .core.curation.keypoint_empties import read_keypoints_file
        sc = context.scene
        d = None if self.auto_wheel else (self.wheel_diameter or sc.articcyc_wheel_diameter or None)
        kp = read_keypoints_file(bpy.path.abspath(self.keypoints_file)) if self.keypoints_file else None
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        res = auto_curate(d, kp, source_path=sc.articcyc_model_path or None)
        _store_problems(sc, res.problems)
        return (f"curated: scale {res.scale:.5g} m/unit, {len(res.keypoints)} keypoints, "
                f"{len(res.problems)} problem(s)")


class ARTICCYC_OT_place_wheels(_Op, bpy.types.Operator):
    """Put the wheel centre empties kp.front_axle / kp.rear_axle on the model to drag onto the
    hubs (when the automatic wheel search failed or found the wrong circles)"""
    bl_idname = "articcyc.place_wheels"
    bl_label = "Place wheel centres"

    def run(self, context):
        from .core.curation.keypoint_empties import place_wheel_empties
        place_wheel_empties()
        return "drag kp.front_axle and kp.rear_axle onto the hubs, then Curate from wheel centres"


class ARTICCYC_OT_curate_from_wheels(_Op, bpy.types.Operator):
    """Re-derive pose, scale, keypoints and parts from the wheel centre empties where you put
    them (kp.front_axle, kp.rear_axle); painted faces are kept"""
    bl_idname = "articcyc.curate_from_wheels"
    bl_label = "Curate from wheel centres"

    def run(self, context):
        from .core.curation.curate_scene import auto_curate
        sc = context.scene
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        res = auto_curate(sc.articcyc_wheel_diameter or None, None, source_path=sc.articcyc_model_path or None,
                                from_wheel_empties=True)
        _store_problems(sc, res.problems)
        return f"curated from the wheel centres: {len(res.problems)} problem(s)"


class ARTICCYC_OT_resume(_Op, bpy.types.Operator):
    """List the problems saved with a partial curation (a .partial.blend from curate.py)"""
    bl_idname = "articcyc.resume"
    bl_label = "Resume partial curation"

    def run(self, context):
        from .core.curation.scene_state import SOURCE, record_problems
        if bpy.data.objects.get(SOURCE) is None:
            raise UserError("no curation in this file: import a model and Auto curate")
        probs = record_problems()
        _store_problems(context.scene, probs)
        return f"{len(probs)} problem(s) to fix" if probs else "no problems recorded: Save bike folder"


class ARTICCYC_OT_load_keypoints(_Op, bpy.types.Operator):
    """Place the keypoint empties from a JSON file (canonical frame)"""
    bl_idname = "articcyc.load_keypoints"
    bl_label = "Load keypoints"
    filepath: StringProperty(name="Keypoints JSON", subtype="FILE_PATH", default="")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def run(self, context):
        from .core.curation.keypoint_empties import read_keypoints_file, set_keypoint_empties
        kp = read_keypoints_file(bpy.path.abspath(self.filepath))
        set_keypoint_empties(kp)
        return f"{len(kp)} keypoints loaded"


class ARTICCYC_OT_snap_keypoints(_Op, bpy.types.Operator):
    """Snap the selected keypoint empties to the closest surface point of the bike"""
    bl_idname = "articcyc.snap_keypoints"
    bl_label = "Snap to surface"

    def run(self, context):
        from .core.curation.keypoint_empties import snap_to_surface
        from .core.curation.scene_state import PARTS, SOURCE
        kps = [o for o in context.selected_objects if o.name.startswith("kp.")]
        if not kps:
            raise UserError("select keypoint empties (kp.*) to snap")
        targets = [bpy.data.objects[n] for n in PARTS if n in bpy.data.objects]
        if not targets and SOURCE in bpy.data.objects:
            targets = [bpy.data.objects[SOURCE]]
        return f"snapped {snap_to_surface(kps, targets)} keypoint(s)"


class ARTICCYC_OT_validate(_Op, bpy.types.Operator):
    """Check the keypoints; the problems are listed in the panel"""
    bl_idname = "articcyc.validate"
    bl_label = "Validate"

    def run(self, context):
        from .core.curation.keypoint_empties import validate_scene
        probs = validate_scene()
        _store_problems(context.scene, probs)
        if probs:
            self.report({"WARNING"}, f"{len(probs)} problem(s): {probs[0]}")
            return None
        return "keypoints valid"


class ARTICCYC_OT_edit_parts(_Op, bpy.types.Operator):
    """Show the curated model in Edit Mode (face select) to repaint part labels"""
    bl_idname = "articcyc.edit_parts"
    bl_label = "Edit part labels"

    def run(self, context):
        from .core.curation.scene_state import SOURCE
        src = bpy.data.objects.get(SOURCE)
        if src is None:
            raise UserError("run Auto curate first")
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        src.hide_set(False)
        for o in context.view_layer.objects:
            o.select_set(False)
        src.select_set(True)
        context.view_layer.objects.active = src
        bpy.ops.object.mode_set(mode="EDIT")
        bpy.ops.mesh.select_mode(type="FACE")
        return None


class ARTICCYC_OT_paint_part(_Op, bpy.types.Operator):
    """Assign the selected faces to a part (then Split parts)"""
    bl_idname = "articcyc.paint_part"
    bl_label = "Assign to part"
    part: EnumProperty(name="Part", items=PART_ITEMS)

    def run(self, context):
        from .core.curation.part_objects import paint_selected
        return f"{paint_selected(self.part)} face(s) -> {self.part}"


class ARTICCYC_OT_split_parts(_Op, bpy.types.Operator):
    """(Re)split frame / steering / crank from the keypoints and painted faces"""
    bl_idname = "articcyc.split_parts"
    bl_label = "Split parts"
    relabel: BoolProperty(name="Recompute from keypoints", default=True)

    def run(self, context):
        from .core.curation.part_objects import split_parts
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        parts = split_parts(self.relabel)
        return "parts: " + ", ".join(f"{n} {len(o.data.polygons)} faces" for n, o in parts.items())


class ARTICCYC_OT_build_rig(_Op, bpy.types.Operator):
    """Build the armature (part bones + keypoint bones) and parent the parts to it"""
    bl_idname = "articcyc.build_rig"
    bl_label = "Build rig"

    def run(self, context):
        from .core.curation.rigging import build_rig
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        build_rig()
        _preview(context.scene)
        return "rig built"


class ARTICCYC_OT_save_bike(_Op, bpy.types.Operator):
    """Write the bike folder (bike.blend, keypoints.json, meta.json) as make_bikes does"""
    bl_idname = "articcyc.save_bike"
    bl_label = "Save bike folder"
    directory: StringProperty(name="Bike folder", subtype="DIR_PATH", default="")
    allow_problems: BoolProperty(name="Save despite problems", default=False)

    def run(self, context):
        from .core.curation.saving import save
        sc = context.scene
        out = bpy.path.abspath(self.directory or sc.articcyc_out_dir)
        if not out:
            raise UserError("no output folder given")
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        meta = save(out.rstrip("/\\"), self.allow_problems)
        sc.articcyc_out_dir = out
        _store_problems(sc, meta["curation"]["problems"])
        return f"saved {out}"


class ARTICCYC_OT_render_views(_Op, bpy.types.Operator):
    """Render the 36-view ring of a saved bike folder (opens its bike.blend)"""
    bl_idname = "articcyc.render_views"
    bl_label = "Render views"
    directory: StringProperty(name="Bike folder", subtype="DIR_PATH", default="")
    parts: StringProperty(name="Parts", default="all")
    views: StringProperty(name="Views", default="", description="comma list of view indices; empty = all 36")
    samples: bpy.props.IntProperty(name="Samples", default=0, min=0, description="0 = default")

    def run(self, context):
        from .core.render import render_views
        out = bpy.path.abspath(self.directory or context.scene.articcyc_out_dir).rstrip("/\\")
        res = render_views.render_bike(out, parts=self.parts, views=self.views or None,
                                       samples=self.samples or None)
        return f"rendered {', '.join(res)}"


class ARTICCYC_OT_import_rider(_Op, bpy.types.Operator):
    """Save a rigged human as a rider for the generator (bones -> 24 SMPL joints, T-pose, weights, texture
    colours): the model file when one is given (imported into this scene), else the scene's armature"""
    bl_idname = "articcyc.import_rider"
    bl_label = "Save as rider"
    overwrite: BoolProperty(name="Overwrite", default=False, description="replace an earlier rider with this id")

    def run(self, context):
        from .core.rider import rider_rig
        sc = context.scene
        if context.mode != "OBJECT":
            bpy.ops.object.mode_set(mode="OBJECT")
        model = bpy.path.abspath(sc.articcyc_rider_model) if sc.articcyc_rider_model else ""
        if model:
            from .core.contract import gltf_extensions
            from .core.curation import importers
            gltf_extensions.check_readable(model)
            objects, what = importers.import_model(model), model
        else:  # the open scene: the selected armature's rig when one is selected, else every object
            sel = [o for o in context.selected_objects if o.type == "ARMATURE"]
            objects = list(sc.objects) if not sel else [sel[0]] + [o for o in sc.objects if o.type == "MESH"]
            what = bpy.data.filepath or "this scene"
        folder = bpy.path.abspath(sc.articcyc_rider_dir).rstrip("/\\")
        path, meta = rider_rig.save_rider(objects, sc.articcyc_rider_id, folder, what,
                                          sc.articcyc_rider_height or None, self.overwrite,
                                          model_dir=os.path.dirname(model) if model else None)
        return (f"rider {meta['id']}: {meta['scheme']} rig, {meta['rest_pose']}-pose rest, {meta['height_m']} m "
                f"-> {path}")


def _store_problems(scene, probs):
    scene.articcyc_problems.clear()
    for p in probs:
        scene.articcyc_problems.add().name = p
    scene.articcyc_validated = True


def _preview(scene):
    arm = bpy.data.objects.get("armature")
    if arm is None or arm.type != "ARMATURE":
        return
    from .core.rig.articulation import apply_pose
    apply_pose(arm, scene.articcyc_theta_p_deg, scene.articcyc_theta_s_deg)


def preview_update(self, context):
    from .requirements import requirements_problem
    if requirements_problem():  # the Missing-numpy panel already says why the sliders do nothing
        return
    if math.isfinite(self.articcyc_theta_p_deg) and math.isfinite(self.articcyc_theta_s_deg):
        _preview(self)


class ARTICCYC_Problem(bpy.types.PropertyGroup):
    name: StringProperty()


CLASSES = (ARTICCYC_Problem, ARTICCYC_OT_import_model, ARTICCYC_OT_auto_curate, ARTICCYC_OT_place_wheels,
           ARTICCYC_OT_curate_from_wheels, ARTICCYC_OT_resume, ARTICCYC_OT_load_keypoints,
           ARTICCYC_OT_snap_keypoints, ARTICCYC_OT_validate, ARTICCYC_OT_edit_parts, ARTICCYC_OT_paint_part,
           ARTICCYC_OT_split_parts, ARTICCYC_OT_build_rig, ARTICCYC_OT_save_bike, ARTICCYC_OT_render_views,
           ARTICCYC_OT_import_rider)

SCENE_PROPS = {
    "articcyc_model_path": lambda: StringProperty(name="Model", subtype="FILE_PATH", default=""),
    "articcyc_out_dir": lambda: StringProperty(name="Bike folder", subtype="DIR_PATH", default=""),
    "articcyc_wheel_diameter": lambda: FloatProperty(name="Wheel diameter (m)", default=0.0, min=0.0, max=3.0,
                                                     description="tyre outer diameter; 0 = automatic"),
    "articcyc_theta_s_deg": lambda: FloatProperty(name="θs steering (deg)", default=0.0, min=-90, max=90,
                                                  update=preview_update),
    "articcyc_theta_p_deg": lambda: FloatProperty(name="θp pedals (deg)", default=0.0, min=-360, max=360,
                                                  update=preview_update),
    "articcyc_problems": lambda: bpy.props.CollectionProperty(type=ARTICCYC_Problem),
    "articcyc_validated": lambda: BoolProperty(default=False),
    "articcyc_rider_model": lambda: StringProperty(name="Rigged human", subtype="FILE_PATH", default="",
                                                   description=".glb/.fbx/.blend; empty = the armature in this scene"),
    "articcyc_rider_id": lambda: StringProperty(name="Rider id", default="my_rider"),
    "articcyc_rider_dir": lambda: StringProperty(name="Riders folder", subtype="DIR_PATH", default="",
                                                 description="the project's data/imported_riders"),
    "articcyc_rider_height": lambda: FloatProperty(name="Height (m)", default=0.0, min=0.0, max=2.6,
                                                   description="scale to this height; 0 = the model's own size"),
}


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)
    for k, make in SCENE_PROPS.items():
        setattr(bpy.types.Scene, k, make())


def unregister():
    for k in SCENE_PROPS:
        if hasattr(bpy.types.Scene, k):
            delattr(bpy.types.Scene, k)
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
