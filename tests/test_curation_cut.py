"""Parts cut by geometry inside one fused mesh (bpy 5.0 module): a synthetic city bike made one
connected mesh is curated by the add-on's operator; the faces of the fused piece are cut along
the part boundaries (bmesh bisect), so every face of the frame, the steering and the crank lies
on its own side of every cut (its corners, pulled 5 % towards its centre, are in its part's
region), not just its centroid."""
import json

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from curation_synth import fuse_with_slivers, synth_bike, transform  # noqa: E402


def test_fused_bike_is_cut_into_clean_parts(fresh_scene):
    import addon
    from addon.core.curation import mesh, scene_state, split
    from addon.core.curation.keypoint_empties import read_keypoint_empties
    from addon.core.frames import to_canonical
    if not hasattr(bpy.types.Scene, "articcyc_wheel_diameter"):
        addon.register()
    V, T, lab, _ = synth_bike(nseg=16)
    V, T, lab = fuse_with_slivers(V, T, lab)
    assert len(mesh.Soup(V, T).comps) == 1
    Vm, _ = transform(V, 21, 10.0, np.array([4.0, -2.0, 1.0]))
    me = bpy.data.meshes.new("model")
    me.from_pydata(Vm.tolist(), [], T.tolist())
    obj = bpy.data.objects.new("model", me)
    bpy.context.scene.collection.objects.link(obj)
    assert bpy.ops.articcyc.auto_curate(wheel_diameter=0.7) == {"FINISHED"}
    rec = json.loads(bpy.context.scene[scene_state.RECORD])
    assert rec["faces_cut"] > 0 and rec["faces_added_by_cuts"] > 0
    src = bpy.data.objects[scene_state.SOURCE]
    sa = rec["split_args"]
    args = (sa["head_radius"], sa["wheel_radius"], sa["head_span"])
    kp = read_keypoint_empties()
    bad, total = {}, {}
    for k, name in enumerate(scene_state.PARTS):
        o = bpy.data.objects[name]
        Vp = np.array([v.co[:] for v in o.data.vertices])
        for p in o.data.polygons:
            c = Vp[list(p.vertices)]
            c = to_canonical(c + 0.05 * (c.mean(0) - c))
            r = split.regions(c, kp, *args)
            total[name] = total.get(name, 0) + p.area
            if not np.all(r == k):
                bad[name] = bad.get(name, 0) + p.area
    assert src is not None and all(total.get(n, 0) > 0 for n in scene_state.PARTS), total
    # the regions' cylinders are the same regular polygons the cuts follow: no face is left across
    assert not bad, {n: bad[n] / total[n] for n in bad}
