"""A moving emissive sphere rendered by Cycles with motion blur, and its shot exported by the
add-on (which writes Blender's motion blur and the frames the shutter reaches).

Usage: blender -b --factory-startup --python motion_blur_scene.py -- ADDON_DIR OUT
   or: python motion_blur_scene.py -- ADDON_DIR OUT   (Blender as a Python module, bpy)
Writes OUT/shot.json and OUT/reference.json: {"radius", "width", "height", "frame",
"blurred": [alpha rows, seed 1], "blurred_again": [seed 2], "sharp": [motion blur off]}, rows
top first.
"""
import json
import os
import sys

import bpy
from mathutils import Vector

ADDON_DIR, OUT = sys.argv[sys.argv.index("--") + 1 :][:2]
sys.path.insert(0, ADDON_DIR)
import nerfx_addon  # noqa: E402

nerfx_addon.register()
RADIUS = 0.5
scene = bpy.context.scene
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)

# The ball: moves along +X at 1.5 units a frame and rises a little, linearly.
bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=RADIUS)
ball = bpy.context.active_object
ball.name = "Ball"
for f, x in ((1, -1.5), (2, 0.0), (3, 1.5)):
    ball.location = (x, 0.0, 0.1 * (f - 2))
    ball.keyframe_insert("location", frame=f)


def fcurves(obj):
    """The object's F-curves: Blender 5 keeps them in the action's channel bag of the
    object's slot (`Action.fcurves` is gone)."""
    action = obj.animation_data.action
    if hasattr(action, "fcurves"):
        return action.fcurves
    from bpy_extras import anim_utils

    return anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot).fcurves


for curve in fcurves(ball):
    for key in curve.keyframe_points:
        key.interpolation = "LINEAR"
mat = bpy.data.materials.new("glow")
mat.use_nodes = True
nodes = mat.node_tree.nodes
nodes.clear()
emit = nodes.new("ShaderNodeEmission")
out = nodes.new("ShaderNodeOutputMaterial")
mat.node_tree.links.new(emit.outputs[0], out.inputs[0])
ball.data.materials.append(mat)

cam_data = bpy.data.cameras.new("Cam")
cam = bpy.data.objects.new("Cam", cam_data)
scene.collection.objects.link(cam)
scene.camera = cam
cam.location = (0.3, -6.0, 0.4)
cam.rotation_euler = (Vector((0.0, 0.0, 0.0)) - cam.location).to_track_quat("-Z", "Y").to_euler()

r = scene.render
r.engine = "CYCLES"
r.resolution_x, r.resolution_y, r.resolution_percentage = 96, 48, 100
r.film_transparent = True
scene.cycles.filter_width = 0.01
r.use_motion_blur = True
r.motion_blur_shutter = 0.6
# Blender 5 moved the shutter position from Cycles' settings to the render settings.
settings = r if hasattr(r, "motion_blur_position") else scene.cycles
settings.motion_blur_position = "END"
scene.cycles.samples = 256
scene.cycles.use_denoising = False
scene.view_layers[0].cycles.use_denoising = False
r.image_settings.file_format = "OPEN_EXR"

res = bpy.ops.nerfx.export_shot(filepath=OUT + "/shot.json", frame_start=2, frame_end=2, nerf_object="Ball")
assert res == {"FINISHED"}, res


def alpha_rows(name, seed):
    scene.cycles.seed = seed
    scene.frame_set(2)
    r.filepath = "%s/%s.exr" % (OUT, name)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(r.filepath)
    w, h = img.size
    px = list(img.pixels)
    rows = [px[y * w * 4 : (y + 1) * w * 4][3::4] for y in range(h - 1, -1, -1)]
    bpy.data.images.remove(img)
    return rows


reference = {"radius": RADIUS, "width": 96, "height": 48, "frame": 2}
reference["blurred"] = alpha_rows("blurred", 1)
reference["blurred_again"] = alpha_rows("blurred_again", 2)
r.use_motion_blur = False
reference["sharp"] = alpha_rows("sharp", 1)
with open(OUT + "/reference.json", "w") as f:
    json.dump(reference, f)
print("nerfx motion blur: wrote")
# Blender as a Python module (bpy 4.5) can hang in its exit handlers after a Cycles render:
# everything is written, so leave at once.
sys.stdout.flush()
os._exit(0)
