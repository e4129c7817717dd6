"""README picture: one posed rider under four suns, Blender (top) beside the relit avatar (bottom).

    python bench/relit_suns.py --avatar AVATAR_DIR --out docs/img/relit_suns.png

The avatar needs rider.relight.npz (bench/rider_relit.py or relight-fit fits it).  Blender renders
the LBS-posed mesh under each sun with bench/rider_relit.py's worker.
"""
import argparse
import json
import os
import subprocess
import sys

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SUNS = ((20.0, 40.0), (50.0, 150.0), (75.0, 260.0), (30.0, 320.0))  # (elevation, azimuth) degrees


def four_suns():
    """The picture's suns: SUNS with one slightly warm strength-3.5 sun and a grey sky."""
    from splatting.relight.shading import Light, sun_direction
    return [Light(sun_direction=sun_direction(el, az), sun_colour=(1.0, 0.95, 0.9), sun_strength=3.5,
                  sky=(0.28, 0.29, 0.3)) for el, az in SUNS]


def write_camera(cam, work):
    """cam as WORK/camera.json (the one-camera file the Blender workers read) -> its path."""
    from bench.rider import camera_json
    cj = os.path.join(work, "camera.json")
    with open(cj, "w") as f:
        json.dump({cam.name: camera_json(cam)}, f)
    return cj


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--avatar", required=True)
    ap.add_argument("--out", required=True, help="PNG to write")
    ap.add_argument("--work", default=os.path.join(ROOT, "out", "relit_suns"))
    a = ap.parse_args()
    if not os.path.isfile(os.path.join(a.avatar, "rider.relight.npz")):
        sys.exit(f"error: {a.avatar} has no rider.relight.npz (run bench/rider_relit.py or relight-fit first)")
    sys.path.insert(0, ROOT)
    import torch
    from PIL import Image

    from bench.relight import light_json
    from bench.rider import posed_batch
    from splatting.raster.camera import ring_camera
    from splatting.relight.avatar import RIDER_ROUGHNESS, RelightableAvatar
    from splatting.relight.render import render_relit
    from splatting.rider.body import export_rider, pose_vertices
    from splatting.rider.roster import load_rider

    torch.set_num_threads(1)
    ra = RelightableAvatar.load(a.avatar)
    rider = load_rider(ra.avatar.rider_id)
    rot, root = posed_batch(rider, np.array([70.0]), np.array([5.0]), np.array([0.0]))
    v = pose_vertices(rider, rot, root)[0]
    centre = (0.0, float((v[:, 1].min() + v[:, 1].max()) / 2), 0.0)
    cam = ring_camera(300.0, centre, name="camera0030")
    from bench.compare import renders_for
    from bench.provenance import RENDER_CODE, code_version

    lights = four_suns()
    # the worker skips a sun_<i>.png that exists: only keep those made for this rider, pose, camera,
    # suns and code (another rider's renders in the same --work folder were reused before)
    renders_for(a.work, {"rider": ra.avatar.rider_id, "pose": [70.0, 5.0, 0.0], "camera": [cam.name, list(centre), 300.0],
                         "suns": [light_json(l) for l in lights], "code": code_version(*RENDER_CODE, "splatting/rider")},
                prefix="sun_")
    mesh = os.path.join(a.work, "posed.ply")
    export_rider(rider, mesh, vertices=v)
    cj = write_camera(cam, a.work)
    jobs = [{"mesh": mesh, "camera": f"{cj}:{cam.name}", "out": os.path.join(a.work, f"sun_{i}.png"),
             "light": light_json(l)} for i, l in enumerate(lights)]
    jp = os.path.join(a.work, "jobs.json")
    with open(jp, "w") as f:
        json.dump(jobs, f)
    if subprocess.run([sys.executable, os.path.join(ROOT, "bench", "rider_relit.py"), "--worker", jp]).returncode:
        sys.exit("error: the Blender worker failed")
    (g, alb, nrm, gl), = ra.pose(rot.float(), root.float())
    top, bottom = [], []
    for job, light in zip(jobs, lights):
        gt = np.asarray(Image.open(job["out"]).convert("RGBA")).astype(np.float64) / 255
        top.append(gt[..., :3] * gt[..., 3:] + (1 - gt[..., 3:]))  # over white
        out = render_relit(g, alb, nrm, cam, light, gl, roughness=RIDER_ROUGHNESS, shadows=True, antialiased=False)
        bottom.append(out["rgb"].numpy() + (1 - out["alpha"].numpy()[..., None]))
    m = np.nonzero(np.asarray(Image.open(jobs[0]["out"]).convert("RGBA"))[..., 3] > 0)
    y0, y1, x0, x1 = max(0, m[0].min() - 10), m[0].max() + 11, max(0, m[1].min() - 10), m[1].max() + 11
    grid = np.concatenate([np.concatenate([t[y0:y1, x0:x1] for t in row], 1) for row in (top, bottom)], 0)
    Image.fromarray((grid.clip(0, 1) * 255).round().astype(np.uint8)).save(a.out)
    print(f"{a.out}: Blender (top) and the relit avatar (bottom) under {len(SUNS)} suns")


if __name__ == "__main__":
    main()
