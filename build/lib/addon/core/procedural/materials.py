"""Principled-BSDF materials for a bike (Blender 3.4 and 5.0: only inputs present in both,
or checked by name before use)."""
import bpy


def _principled(name, colour, metallic, roughness, coat=0.0, emission=None):
    mat = bpy.data.materials.new(name)
    if mat.node_tree is None:  # 3.4 creates the tree on demand; 5.0 always has one
        mat.use_nodes = True
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    rgba = list(colour)[:3] + [1.0]
    bsdf.inputs["Base Color"].default_value = rgba
    bsdf.inputs["Metallic"].default_value = metallic
    bsdf.inputs["Roughness"].default_value = roughness
    for key in ("Coat Weight", "Clearcoat"):  # 4.0 renamed Clearcoat
        if coat and key in bsdf.inputs:
            bsdf.inputs[key].default_value = coat
    if emission is not None:
        for key in ("Emission Color", "Emission"):
            if key in bsdf.inputs:
                bsdf.inputs[key].default_value = list(emission) + [1.0]
                break
        if "Emission Strength" in bsdf.inputs:
            bsdf.inputs["Emission Strength"].default_value = 2.0
    mat.diffuse_color = rgba  # solid-view colour
    return mat


def make_materials(spec):
    """{material key used by the mesh builders: bpy material}."""
    dark = spec.get("accent_dark", True)
    paint = spec["frame_colour"]
    return {
        "paint": _principled("bike_paint", paint, 0.25, 0.32, coat=0.6),
        "metal": _principled("bike_metal", (0.72, 0.72, 0.74), 1.0, 0.22),
        "rim": _principled("bike_rim", (0.025, 0.025, 0.025) if dark else (0.7, 0.7, 0.72), 0.7, 0.3),
        "dark": _principled("bike_dark", (0.02, 0.02, 0.022), 0.4, 0.4),
        "rubber": _principled("bike_rubber", (0.018, 0.018, 0.018), 0.0, 0.85),
        "grip": _principled("bike_grip", (0.03, 0.03, 0.03), 0.0, 0.75),
        "tape": _principled("bike_tape", (0.02, 0.02, 0.02) if dark else (0.8, 0.8, 0.78), 0.0, 0.6),
        "saddle": _principled("bike_saddle", spec.get("saddle_colour", (0.012, 0.012, 0.012)), 0.0, 0.55),
        "stanchion": _principled("bike_stanchion", (0.85, 0.55, 0.18) if dark else (0.05, 0.05, 0.05), 1.0, 0.25),
        "taillight": _principled("bike_taillight", (0.8, 0.02, 0.02), 0.0, 0.2, emission=(0.8, 0.0, 0.0)),
        "lamp": _principled("bike_lamp", (0.95, 0.95, 0.9), 0.0, 0.05),
    }
