"""Per-vertex colours of an imported rider's meshes (bpy side; step 5 of rider_rig): per material, the
image texture feeding the Base Color (sampled bilinearly at each corner's UV, averaged per vertex), a
colour attribute, or the flat base colour.  A texture whose image file is gone is looked for by its file
name (any of the usual extensions) next to the model and in its texture folders (files move with the
model, their absolute paths do not); one found nowhere leaves its material the flat base colour, and is
listed in `missing` (the rider file's meta and a warning line), never a silent grey.  A texture node
with no image, or a textured material on a mesh without UVs, is an error."""
import os

import bpy
import numpy as np

from ..contract import UserError

DEFAULT_LINEAR = (0.8, 0.8, 0.8)


def srgb_from_linear(c):
    c = np.clip(np.asarray(c, np.float64), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)



def _upstream(node, seen=None):
    """Nodes feeding `node`, breadth first."""
    seen = seen if seen is not None else set()
    out, todo = [], [node]
    while todo:
        n = todo.pop(0)
        for inp in n.inputs:
            for link in inp.links:
                m = link.from_node
                if m.name not in seen:
                    seen.add(m.name)
                    out.append(m)
                    todo.append(m)
    return out


IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tga", ".tif", ".tiff", ".bmp", ".webp", ".exr")
TEXTURE_FOLDERS = ("", "textures", "Textures", "texture", "tex", "images", "maps", "..", "../textures")


def _find_moved(img, search_dirs):
    """Reload `img` from a file with its name (or its stem with another extension) in search_dirs."""
    name = os.path.basename((img.filepath or img.name).replace("\\", "/"))
    stem = os.path.splitext(name)[0].lower()
    for d in search_dirs:
        for sub in TEXTURE_FOLDERS:
            folder = os.path.normpath(os.path.join(d, sub))
            if not os.path.isdir(folder):
                continue
            for f in sorted(os.listdir(folder)):
                if os.path.splitext(f)[0].lower() == stem and f.lower().endswith(IMAGE_EXTENSIONS):
                    img.filepath = os.path.join(folder, f)
                    if _load(img):
                        return True
    return False


def colour_source(mat, what, search_dirs=(), missing=None):
    """('image', image, uv_map or None) | ('attribute', name) | ('flat', sRGB (3,)) for one material.
    A texture file found nowhere (not at its path, not by name in search_dirs) is appended to `missing`
    and the material is flat; with missing=None it is an error."""
    if mat is None:
        return ("flat", srgb_from_linear(DEFAULT_LINEAR))
    nt = mat.node_tree if getattr(mat, "node_tree", None) is not None else None
    if nt is None:
        return ("flat", srgb_from_linear(mat.diffuse_color[:3]))
    outs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]
    out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
    shader = None
    if out is not None and out.inputs["Surface"].links:
        shader = out.inputs["Surface"].links[0].from_node
    if shader is None:
        return ("flat", srgb_from_linear(mat.diffuse_color[:3]))
    sock = next((shader.inputs[k] for k in ("Base Color", "Color") if k in shader.inputs), None)
    if sock is None:
        sock_nodes = _upstream(shader)
        default = mat.diffuse_color[:3]
    else:
        default = sock.default_value[:3]
        sock_nodes = []
        for link in sock.links:
            sock_nodes.append(link.from_node)
            sock_nodes += _upstream(link.from_node)
    for n in sock_nodes:
        if n.type == "TEX_IMAGE":
            img = n.image
            if img is None:
                raise UserError(f"{what}: material '{mat.name}' has an image texture node with no image (missing texture)")
            if img.size[0] == 0 or img.size[1] == 0 or not img.has_data and not _load(img):
                src = bpy.path.abspath(img.filepath) if img.filepath else img.name
                if not _find_moved(img, search_dirs):
                    if missing is None:
                        raise UserError(f"{what}: material '{mat.name}' uses texture '{src}', which is missing "
                                        f"or unreadable (missing texture)")
                    missing.append(f"material '{mat.name}': {src}")
                    # a socket a texture fed is often left black: then the viewport colour, else neutral grey
                    flat = next((c for c in (default, mat.diffuse_color[:3]) if max(c) > 0.02), DEFAULT_LINEAR)
                    return ("flat", srgb_from_linear(flat))
            uv = None
            vec = n.inputs.get("Vector")
            if vec is not None and vec.links and vec.links[0].from_node.type == "UVMAP":
                uv = vec.links[0].from_node.uv_map or None
            return ("image", img, uv)
        if n.type in ("VERTEX_COLOR", "ATTRIBUTE"):
            name = getattr(n, "layer_name", None) or getattr(n, "attribute_name", None)
            return ("attribute", name)
    return ("flat", srgb_from_linear(default))


def alpha_image(mat):
    """The image whose alpha feeds the material's shader Alpha (glTF/FBX cut-outs: MakeHuman's hidden
    helper geometry, hair cards), or None when the material is opaque."""
    nt = getattr(mat, "node_tree", None) if mat is not None else None
    if nt is None:
        return None
    for n in nt.nodes:
        a = n.inputs.get("Alpha") if n.type.startswith("BSDF") else None
        if a is None or not a.links:
            continue
        src = a.links[0].from_node
        for m in [src] + _upstream(src):
            if m.type == "TEX_IMAGE" and m.image is not None and m.image.has_data and m.image.channels == 4:
                return m.image
    return None


def _load(img):
    try:
        img.reload()
        return img.has_data and img.size[0] > 0
    except RuntimeError:
        return False


def _image_array(img):
    w, h = img.size
    px = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(px)
    px = px.reshape(h, w, img.channels)
    rgb = px[..., :3] if img.channels >= 3 else np.repeat(px[..., :1], 3, -1)
    if img.is_float:  # float buffers are scene linear; byte buffers hold the file's sRGB values
        rgb = srgb_from_linear(rgb)
    return np.clip(rgb.astype(np.float64), 0, 1)


def _sample_bilinear(rgb, uv):
    """Repeat-wrapped bilinear lookup; uv (N,2) with v up (Blender's convention, row 0 = bottom)."""
    h, w = rgb.shape[:2]
    x = np.mod(uv[:, 0], 1.0) * w - 0.5
    y = np.mod(uv[:, 1], 1.0) * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    x0, x1, y0, y1 = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
    return ((1 - fx) * (1 - fy) * rgb[y0, x0] + fx * (1 - fy) * rgb[y0, x1]
            + (1 - fx) * fy * rgb[y1, x0] + fx * fy * rgb[y1, x1])


def object_colors(obj, what, images, search_dirs=(), missing=None):
    """Per-vertex sRGB colours, and per loop the texture coordinate, the index into `images` (an
    ordered {name: sRGB array}) of the texture drawn there (-1: none) and the texture's alpha where an
    image's alpha feeds the shader's Alpha (1 elsewhere)."""
    me = obj.data
    nv, nl = len(me.vertices), len(me.loops)
    loop_vert = np.empty(nl, np.int64)
    me.loops.foreach_get("vertex_index", loop_vert)
    starts, totals, mats = (np.empty(len(me.polygons), np.int64) for _ in range(3))
    me.polygons.foreach_get("loop_start", starts)
    me.polygons.foreach_get("loop_total", totals)
    me.polygons.foreach_get("material_index", mats)
    loop_mat = np.repeat(mats, totals)
    loop_rgb = np.empty((nl, 3))
    loop_uv = np.zeros((nl, 2))
    loop_tex = np.full(nl, -1, np.int64)
    loop_alpha = np.ones(nl)
    for mi in np.unique(loop_mat):
        sel = loop_mat == mi
        mat = obj.material_slots[mi].material if mi < len(obj.material_slots) else None
        src = colour_source(mat, what, search_dirs, missing)
        if src[0] == "image":
            _, img, uv_name = src
            layer = me.uv_layers.get(uv_name) if uv_name else me.uv_layers.active
            if layer is None:
                raise UserError(f"{what}: object '{obj.name}' has material '{mat.name}' textured but no UV map")
            uv = np.empty(nl * 2)
            layer.data.foreach_get("uv", uv)
            if img.name not in images:
                images[img.name] = _image_array(img)
            loop_rgb[sel] = _sample_bilinear(images[img.name], uv.reshape(-1, 2)[sel])
            loop_uv[sel] = uv.reshape(-1, 2)[sel]
            loop_tex[sel] = list(images).index(img.name)
            a_img = alpha_image(mat)
            if a_img is not None:
                w, h = a_img.size
                px = np.empty(w * h * 4, np.float32)
                a_img.pixels.foreach_get(px)
                alpha = np.repeat(px.reshape(h, w, 4)[..., 3:].astype(np.float64), 3, -1)
                loop_alpha[sel] = _sample_bilinear(alpha, uv.reshape(-1, 2)[sel])[:, 0]
        elif src[0] == "attribute":
            loop_rgb[sel] = _attribute_colors(me, src[1], loop_vert)[sel]
        else:
            loop_rgb[sel] = src[1]
    out = np.zeros((nv, 3))
    cnt = np.zeros(nv)
    np.add.at(out, loop_vert, loop_rgb)
    np.add.at(cnt, loop_vert, 1)
    out[cnt == 0] = srgb_from_linear(DEFAULT_LINEAR)
    cnt[cnt == 0] = 1
    return out / cnt[:, None], loop_uv, loop_tex, loop_alpha


def _attribute_colors(me, name, loop_vert):
    """A colour attribute per loop, sRGB."""
    attrs = getattr(me, "color_attributes", None)
    a = (attrs.get(name) if name else attrs.active_color) if attrs is not None else None
    if a is None:
        return np.tile(srgb_from_linear(DEFAULT_LINEAR), (len(loop_vert), 1))
    c = np.empty(len(a.data) * 4)
    a.data.foreach_get("color", c)  # scene linear for both FLOAT_COLOR and BYTE_COLOR
    c = srgb_from_linear(c.reshape(-1, 4)[:, :3])
    return c[loop_vert] if a.domain == "POINT" else c


NOT_A_SKIN = ("preview", "thumb", "screenshot", "icon", "render", "normal", "rough", "metal", "spec", "gloss",
              "_ao", "occlusion", "emiss", "height", "bump", "disp", "opacity", "alpha", "mask")


def lone_texture(meshes, model_dir):
    """A skin shipped beside a model that references none (Kenney's characters: material 'skin' with a flat
    colour, `casualMaleA.png` next to the .fbx).  When no material of the meshes draws an image or a colour
    attribute, every mesh has UVs, and exactly one image that is not a preview or a normal, roughness, ...
    map lies in the model's folder or its texture folders, it becomes the colour of every material (an
    Image Texture node on its Base Color / Color).  Returns that image's path, or None (nothing changed)."""
    if not model_dir or not meshes or any(o.data.uv_layers.active is None for o in meshes):
        return None
    mats = {m for o in meshes for m in o.data.materials if m is not None and getattr(m, "node_tree", None)}
    missing = []
    if not mats or any(colour_source(m, "", (), missing)[0] != "flat" for m in mats) or missing:
        return None
    found = set()
    for sub in TEXTURE_FOLDERS:
        folder = os.path.normpath(os.path.join(model_dir, sub))
        if sub.startswith("..") or not os.path.isdir(folder):
            continue
        for f in os.listdir(folder):
            if f.lower().endswith(IMAGE_EXTENSIONS) and not any(w in f.lower() for w in NOT_A_SKIN):
                found.add(os.path.realpath(os.path.join(folder, f)))
    if len(found) != 1:
        return None
    path = found.pop()
    try:
        img = bpy.data.images.load(path, check_existing=True)
    except RuntimeError:
        return None
    if img.size[0] == 0 or img.size[1] == 0:  # (reading the size loads the file)
        return None
    for m in mats:
        nt = m.node_tree
        outs = [n for n in nt.nodes if n.type == "OUTPUT_MATERIAL"]
        out = next((n for n in outs if n.is_active_output), outs[0] if outs else None)
        if out is None or not out.inputs["Surface"].links:
            continue
        shader = out.inputs["Surface"].links[0].from_node
        sock = next((shader.inputs[k] for k in ("Base Color", "Color") if k in shader.inputs), None)
        if sock is not None:
            tex = nt.nodes.new("ShaderNodeTexImage")
            tex.image = img
            nt.links.new(tex.outputs["Color"], sock)
    return path
