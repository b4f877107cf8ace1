"""Imports a Gaussian-splat file through the add-on's operator and says what Blender made of it.

Usage: blender -b --factory-startup --python splat_import_check.py -- ADDON_DIR FILE OUT_JSON
[NERFX] (NERFX: the nerfx program the add-on runs for formats other than the INRIA PLY).
Writes {"vertices": N, "nerf_object": name, "points": [[x, y, z, r, g, b], ...]} for every
vertex, world coordinates (the object's matrix_world applied), colours from the "Col" point
attribute.
"""
import json
import os
import sys

import bpy

ARGS = sys.argv[sys.argv.index("--") + 1 :]
ADDON_DIR, PLY, OUT = ARGS[:3]
EXECUTABLE = ARGS[3] if len(ARGS) > 3 else ""
sys.path.insert(0, ADDON_DIR)
import nerfx_addon  # noqa: E402

nerfx_addon.register()
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
result = bpy.ops.nerfx.import_splats(filepath=PLY, executable=EXECUTABLE)
assert result == {"FINISHED"}, result
obj = bpy.context.scene.nerfx_nerf_object
mesh = obj.data
colours = mesh.attributes["Col"].data
points = []
for v, c in zip(mesh.vertices, colours):
    p = obj.matrix_world @ v.co
    points.append([p.x, p.y, p.z, c.color[0], c.color[1], c.color[2]])
with open(OUT, "w") as f:
    json.dump({"vertices": len(mesh.vertices), "nerf_object": obj.name, "points": points}, f)
# Blender as a Python module (bpy 4.5) can hang in its exit handlers: everything is written,
# so leave at once.
sys.stdout.flush()
os._exit(0)
