"""Riders in Blender: a rigged human saved as a rider (rider_rig, with its colours and helper-face
rules) and a rider's coloured points imported for the renders (rider_import)."""
