"""The annotator's sidebar tab (3D viewport, N panel): Curate, Keypoints, Parts, Render, Rider.

Every button is an operator from operators.py; nothing here changes data by itself.
"""
import sys

import bpy

CATEGORY = "ArticCyclists"


def _requirements_problem():
    from .requirements import requirements_problem
    return requirements_problem()


class _Panel:
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = CATEGORY


class ARTICCYC_PT_requirements(_Panel, bpy.types.Panel):
    """Shown first, and only when the add-on cannot work: what is missing and how to install it."""
    bl_label = "Missing Python package: numpy"
    bl_idname = "ARTICCYC_PT_requirements"

    @classmethod
    def poll(cls, context):
        return _requirements_problem() is not None

    def draw(self, context):
        box = self.layout.box()
        box.alert = True
        # A sidebar label does not wrap: one short line per fact.
        box.label(text="The add-on needs numpy; this Blender's Python lacks it.", icon="ERROR")
        box.label(text="Debian/Ubuntu: sudo apt install python3-numpy")
        box.label(text=f"Other Blenders: {sys.executable} -m pip install numpy")
        box.label(text="Then restart Blender. Every button refuses until then.")


class ARTICCYC_PT_curate(_Panel, bpy.types.Panel):
    bl_label = "Curate"
    bl_idname = "ARTICCYC_PT_curate"

    def draw(self, context):
        sc, col = context.scene, self.layout.column(align=True)
        col.prop(sc, "articcyc_model_path", text="")
        col.operator("articcyc.import_model", icon="IMPORT")
        col.separator()
        col.prop(sc, "articcyc_wheel_diameter")
        col.operator("articcyc.auto_curate", icon="MODIFIER")
        col.separator()
        col.operator("articcyc.place_wheels", icon="EMPTY_AXIS")
        col.operator("articcyc.curate_from_wheels", icon="FILE_REFRESH")
        col.operator("articcyc.resume", icon="RECOVER_LAST")


class ARTICCYC_PT_keypoints(_Panel, bpy.types.Panel):
    bl_label = "Keypoints"
    bl_idname = "ARTICCYC_PT_keypoints"

    def draw(self, context):
        sc, col = context.scene, self.layout.column(align=True)
        col.operator("articcyc.load_keypoints", icon="FILE")
        col.operator("articcyc.snap_keypoints", icon="SNAP_FACE")
        col.operator("articcyc.validate", icon="CHECKMARK")
        if sc.articcyc_validated:
            box = self.layout.box()
            if len(sc.articcyc_problems) == 0:
                box.label(text="Keypoints valid", icon="CHECKMARK")
            for p in sc.articcyc_problems:
                box.label(text=p.name, icon="ERROR")


class ARTICCYC_PT_parts(_Panel, bpy.types.Panel):
    bl_label = "Parts"
    bl_idname = "ARTICCYC_PT_parts"

    def draw(self, context):
        col = self.layout.column(align=True)
        col.operator("articcyc.edit_parts", icon="EDITMODE_HLT")
        row = col.row(align=True)
        for part in ("frame", "steering", "crank", "junk"):
            row.operator("articcyc.paint_part", text=part.capitalize()).part = part
        col.operator("articcyc.split_parts", icon="MOD_EXPLODE")


class ARTICCYC_PT_render(_Panel, bpy.types.Panel):
    bl_label = "Render"
    bl_idname = "ARTICCYC_PT_render"

    def draw(self, context):
        sc, col = context.scene, self.layout.column(align=True)
        col.operator("articcyc.build_rig", icon="ARMATURE_DATA")
        col.label(text="Preview")
        col.prop(sc, "articcyc_theta_s_deg", slider=True)
        col.prop(sc, "articcyc_theta_p_deg", slider=True)
        col.separator()
        col.prop(sc, "articcyc_out_dir", text="")
        col.operator("articcyc.save_bike", icon="FILE_TICK")
        col.operator("articcyc.render_views", icon="RENDER_STILL")


class ARTICCYC_PT_rider(_Panel, bpy.types.Panel):
    """A user's rigged human -> a rider for the generator (the same import as `python -m splatting rider import`)."""
    bl_label = "Rider"
    bl_idname = "ARTICCYC_PT_rider"

    def draw(self, context):
        sc, col = context.scene, self.layout.column(align=True)
        col.prop(sc, "articcyc_rider_model", text="")
        col.prop(sc, "articcyc_rider_id")
        col.prop(sc, "articcyc_rider_height")
        col.prop(sc, "articcyc_rider_dir", text="")
        col.operator("articcyc.import_rider", icon="ARMATURE_DATA")


CLASSES = (ARTICCYC_PT_requirements, ARTICCYC_PT_curate, ARTICCYC_PT_keypoints, ARTICCYC_PT_parts, ARTICCYC_PT_render,
           ARTICCYC_PT_rider)


def register():
    for c in CLASSES:
        bpy.utils.register_class(c)


def unregister():
    for c in reversed(CLASSES):
        bpy.utils.unregister_class(c)
