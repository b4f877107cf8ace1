"""Lights a Blender scene with a nerfx environment map through the add-on's button and says
what Cycles sees in given directions.

Usage: blender -b --factory-startup --python environment_check.py -- ADDON_DIR NERFX SCENE OUT
PROBES_JSON. Builds a scene with a camera and a NeRF object, puts an empty "Probe" at the
position PROBES_JSON names, presses Render Environment Map (nerfx envmap runs with the empty's
position), then renders one Cycles pixel along each direction with a camera at the probe and
writes {"colours": [[r, g, b], ...]} to OUT/environment.json.
"""
import json
import os
import sys

import bpy
from mathutils import Vector

ADDON_DIR, NERFX, SCENE_FILE, OUT, PROBES = sys.argv[sys.argv.index("--") + 1 :][:5]
sys.path.insert(0, ADDON_DIR)
import nerfx_addon  # noqa: E402

nerfx_addon.register()
probes = json.loads(PROBES)
scene = bpy.context.scene
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)

nerf = bpy.data.objects.new("NeRF", None)
scene.collection.objects.link(nerf)
cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
scene.collection.objects.link(cam)
scene.camera = cam
probe = bpy.data.objects.new("Probe", None)
probe.location = probes["position"]
scene.collection.objects.link(probe)
scene.nerfx_nerf_object = nerf

result = bpy.ops.nerfx.render_environment(
    scene_file=SCENE_FILE,
    at_object="Probe",
    filepath=os.path.join(OUT, "envmap.exr"),
    executable=NERFX,
    height=probes["height"],
)
assert result == {"FINISHED"}, result

# One pixel along each direction, seen from the probe: the World's colour there.
scene.render.engine = "CYCLES"
scene.cycles.samples = 1
scene.cycles.use_denoising = False
scene.view_layers[0].cycles.use_denoising = False
scene.render.resolution_x = scene.render.resolution_y = 1
scene.render.resolution_percentage = 100
scene.render.filter_size = 0.01
scene.render.image_settings.file_format = "OPEN_EXR"
cam.data.angle = 1e-3
cam.location = probes["position"]
colours = []
for i, d in enumerate(probes["directions"]):
    cam.rotation_euler = Vector(d).normalized().to_track_quat("-Z", "Y").to_euler()
    scene.render.filepath = os.path.join(OUT, "probe%d.exr" % i)
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(scene.render.filepath, check_existing=False)
    colours.append(list(image.pixels)[:3])
    bpy.data.images.remove(image)
with open(os.path.join(OUT, "environment.json"), "w") as f:
    json.dump({"colours": colours}, f)
print("nerfx environment: wrote")
# Blender as a Python module (bpy 4.5) can hang in its exit handlers: everything is written,
# so leave at once.
sys.stdout.flush()
os._exit(0)
