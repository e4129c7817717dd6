"""Procedural bike library: spec sampling (spec.py), layout (layout.py), numpy mesh builders
(meshkit, wheels, tubes, cockpit, drivetrain, extras) and the bpy assembly (build.py)."""
