"""Frames mode: cyclists inserted into the frames of a KITTI object folder (docs/kitti_insert.md).

    source     the folder (checked up front) and one frame: image, calib, labels, road plane, scan
    road       the frame's road plane as the street world (Y = 0) and camera 2 as the render camera
    placement  where the inserted instances stand (generate.draw)
    contact    both tyres on the road plane
    occlusion  the frame's depth (labelled boxes, LiDAR) hides inserted pixels; inserted cyclists
               raise the `occluded` of the labelled objects they cover
    look       light level and colour, blur and noise matched to the frame
    sample     the per-sample glue make_sample calls
    output     the KITTI files of a sample
    lidar      the LiDAR half: ground plane, support, depth image, insertion into the scan
"""
