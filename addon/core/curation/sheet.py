"""Contact sheet of curated bike folders: each bike's whole-bike side and three-quarter views
with its parts coloured and its keypoints drawn (docs/img/curated_real.png).

    .venv/bin/python -m addon.core.curation.sheet OUT/bikes/a OUT/bikes/b ... -o sheet.png [--titles "A" "B" ...]

Reads bike.blend (bpy) and keypoints.json of each folder; draws with a painter's algorithm
(numpy + Pillow), so it needs no render engine and shows exactly the saved geometry.
"""
import argparse
import json
import os

import numpy as np

PART_RGB = {"frame": (150, 160, 180), "steering": (235, 150, 60), "crank": (90, 190, 110)}
TILE = (420, 280)


def load_bike(folder):
    """{part: (V canonical (n,3), T (m,3))}, keypoints {name: (3,)} of a saved bike folder."""
    import bpy

    from ..frames import to_canonical
    from ..script import UserError
    blend = os.path.join(folder, "bike.blend")
    if not os.path.isfile(blend):
        raise UserError(f"{folder}: no bike.blend (not a bike folder)")
    bpy.ops.wm.open_mainfile(filepath=blend)
    dg = bpy.context.evaluated_depsgraph_get()
    parts = {}
    for name in PART_RGB:
        o = bpy.data.objects.get(name)
        if o is None:
            continue
        from ..scene import world_mesh_arrays
        V, T = world_mesh_arrays(o, dg)
        parts[name] = (to_canonical(V), T)
    with open(os.path.join(folder, "keypoints.json")) as f:
        kp = {k: np.asarray(v, float) for k, v in json.load(f)["keypoints"].items()}
    return parts, kp


def _rot(yaw_deg, pitch_deg):
    y, p = np.radians(yaw_deg), np.radians(pitch_deg)
    Ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    Rx = np.array([[1, 0, 0], [0, np.cos(p), -np.sin(p)], [0, np.sin(p), np.cos(p)]])
    return Rx @ Ry


def draw_view(parts, kp, yaw, pitch, size=TILE, title=""):
    """One tile: the bike seen from its left side (yaw 0: front wheel on the image's left, as
    the 36-view ring's view 0), rotated by yaw about the vertical, tilted by pitch."""
    from PIL import Image, ImageDraw
    R = _rot(yaw, pitch)
    W, H = size
    allV = np.concatenate([v for v, _ in parts.values()] + [np.array(list(kp.values()))])
    Q = allV @ R.T
    lo, hi = Q.min(0), Q.max(0)
    s = 0.86 * min(W / max(hi[0] - lo[0], 1e-9), (H - 24) / max(hi[1] - lo[1], 1e-9))
    cx, cy = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])

    def proj(P):  # camera on -Z looking +Z: image u = -x, v = -y
        q = P @ R.T
        return np.stack([W / 2 - (q[:, 0] - cx) * s, (H + 18) / 2 - (q[:, 1] - cy) * s], 1), q[:, 2]

    img = Image.new("RGB", (W, H), (255, 255, 255))
    dr = ImageDraw.Draw(img)
    tris, depth, cols = [], [], []
    light = np.array([0.3, 0.6, -0.75])
    light /= np.linalg.norm(light)
    for name, (V, T) in parts.items():
        if len(T) == 0:
            continue
        uv, z = proj(V)
        n = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]) @ R.T
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        shade = 0.45 + 0.55 * np.abs(n @ light)
        base = np.array(PART_RGB[name], float)
        tris.append(uv[T])
        depth.append(z[T].mean(1))
        cols.append((shade[:, None] * base).astype(int))
    tris, depth, cols = np.concatenate(tris), np.concatenate(depth), np.concatenate(cols)
    for i in np.argsort(-depth):   # far first (camera looks along +z from -z: larger z is farther)
        dr.polygon([tuple(p) for p in tris[i]], fill=tuple(cols[i]))
    names = list(kp)
    uv, z = proj(np.array([kp[k] for k in names]))
    for (u, v), k in zip(uv, names):
        dr.ellipse([u - 3.5, v - 3.5, u + 3.5, v + 3.5], fill=(220, 20, 60), outline=(0, 0, 0))
    if title:
        dr.text((6, 4), title, fill=(0, 0, 0))
    return img


def contact_sheet(folders, titles, out, per_row=2):
    import tempfile

    from PIL import Image
    blocks = []
    for folder, title in zip(folders, titles):
        parts, kp = load_bike(folder)
        a = draw_view(parts, kp, 0, 0, title=title)
        b = draw_view(parts, kp, -35, 20, title="three-quarter")
        blk = Image.new("RGB", (2 * TILE[0], TILE[1]), (255, 255, 255))
        blk.paste(a, (0, 0))
        blk.paste(b, (TILE[0], 0))
        blocks.append(blk)
    rows = (len(blocks) + per_row - 1) // per_row
    sheet = Image.new("RGB", (per_row * 2 * TILE[0], rows * TILE[1]), (255, 255, 255))
    for i, blk in enumerate(blocks):
        sheet.paste(blk, ((i % per_row) * 2 * TILE[0], (i // per_row) * TILE[1]))
    d = os.path.dirname(os.path.abspath(out))
    os.makedirs(d, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=".sheet.", suffix=".png", dir=d)
    os.close(fd)
    try:
        sheet.save(tmp, format="PNG")
        os.replace(tmp, out)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)
    return out


def main(argv=None):
    from ..script import UserError
    p = argparse.ArgumentParser(prog="python -m addon.core.curation.sheet", description=__doc__.split("\n\n")[0])
    p.add_argument("folders", nargs="+", help="curated bike folders")
    p.add_argument("-o", "--out", required=True, help="PNG to write")
    p.add_argument("--titles", nargs="*", default=None, help="one title per folder (credit the authors)")
    a = p.parse_args(argv)
    titles = a.titles or [os.path.basename(os.path.normpath(f)) for f in a.folders]
    if len(titles) != len(a.folders):
        raise UserError(f"{len(titles)} titles for {len(a.folders)} folders")
    for f in a.folders:
        if not os.path.isfile(os.path.join(f, "bike.blend")):
            raise UserError(f"{f}: no bike.blend (not a bike folder)")
    contact_sheet(a.folders, titles, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    from ..script import run_main
    run_main(main, "sheet")
