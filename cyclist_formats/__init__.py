"""The file contract between the Blender side (`addon/`) and the torch side (`splatting/`).

One module per format, numpy only (no bpy, no torch), so that both worlds import the same code:
Blender 3.4's bundled Python, the bpy 5.0 module and the torch package.  `make addon` copies this
package into the add-on zip.  The conventions themselves (frames, rig, names, layouts) are in
docs/contract.md, the source of truth.

    errors       UserError: bad input, printed as one line by every command
    atomic       write-then-rename, so a killed run never leaves a truncated file
    ring         the 36-view camera ring and cameras.json
    pose         the 8-DoF bike pose: field names, parsing, validation
    instances    instance ids of the parts and the rider (masks, id channels)
    bike_folder  a bike's folder: bike.blend, keypoints.json, meta.json, views/<part>/
    ply          .ply files: 3DGS Gaussians (INRIA layout), point clouds, coloured meshes
    checks       up-front checks of command values and paths (impossible numbers, unusable outputs)
"""
