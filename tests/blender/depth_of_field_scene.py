"""An emissive sphere in front of an emissive wall, rendered by Cycles with depth of field
focused on the wall (a focus object), and its shot exported by the add-on.

Usage: blender -b --factory-startup --python depth_of_field_scene.py -- ADDON_DIR OUT
   or: python depth_of_field_scene.py -- ADDON_DIR OUT   (Blender as a Python module, bpy)
Writes OUT/shot.json (the disk aperture), OUT/shot_polygon.json (five blades, turned,
anamorphic) and OUT/reference.json: {"blender", "width", "height", "frame", "ball", "wall",
"disk": [RGB rows, seed 1], "disk_again": [seed 2], "polygon": [seed 1], "sharp": [depth of
field off]}, rows top first, each pixel's R, G, B in turn.
"""
import json
import os
import sys

import bpy

ADDON_DIR, OUT = sys.argv[sys.argv.index("--") + 1 :][:2]
sys.path.insert(0, ADDON_DIR)
import nerfx_addon  # noqa: E402

nerfx_addon.register()
BALL = {"radius": 0.1, "color": [1.0, 0.6, 0.2]}
WALL = {"y": 2.0, "half_size": 5.0, "color": [0.1, 0.3, 0.9]}
WIDTH, HEIGHT = 96, 64
scene = bpy.context.scene
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
if scene.world is not None:
    scene.world.use_nodes = False
    scene.world.color = (0.0, 0.0, 0.0)


def emissive(name, color):
    mat = bpy.data.materials.new(name)
    mat.use_nodes = True
    nodes = mat.node_tree.nodes
    nodes.clear()
    emit = nodes.new("ShaderNodeEmission")
    emit.inputs["Color"].default_value = (*color, 1.0)
    emit.inputs["Strength"].default_value = 1.0
    out = nodes.new("ShaderNodeOutputMaterial")
    mat.node_tree.links.new(emit.outputs[0], out.inputs[0])
    return mat


bpy.ops.mesh.primitive_uv_sphere_add(segments=128, ring_count=64, radius=BALL["radius"])
ball = bpy.context.active_object
ball.name = "Ball"
ball.data.materials.append(emissive("ball", BALL["color"]))
# The wall faces the camera: a plane turned upright at y = 2.
bpy.ops.mesh.primitive_plane_add(size=2 * WALL["half_size"], location=(0.0, WALL["y"], 0.0),
                                 rotation=(1.5707963267948966, 0.0, 0.0))
wall = bpy.context.active_object
wall.name = "Wall"
wall.data.materials.append(emissive("wall", WALL["color"]))

cam_data = bpy.data.cameras.new("Cam")
cam = bpy.data.objects.new("Cam", cam_data)
scene.collection.objects.link(cam)
scene.camera = cam
# At (0, -2, 0) looking along +Y (up +Z): the ball 2 units away, the wall 4.
cam.location = (0.0, -2.0, 0.0)
cam.rotation_euler = (1.5707963267948966, 0.0, 0.0)
cam_data.lens = 100.0
cam_data.sensor_width = 36.0
cam_data.sensor_fit = "AUTO"
cam_data.shift_x = 0.05
dof = cam_data.dof
dof.use_dof = True
dof.focus_object = wall
dof.aperture_fstop = 1.4
dof.aperture_blades = 0

r = scene.render
r.engine = "CYCLES"
r.resolution_x, r.resolution_y, r.resolution_percentage = WIDTH, HEIGHT, 100
r.film_transparent = True
scene.cycles.device = "CPU"
scene.cycles.filter_width = 0.01
scene.cycles.samples = 256
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 0
scene.view_layers[0].cycles.use_denoising = False
r.image_settings.file_format = "OPEN_EXR"
scene.frame_start = scene.frame_end = 1


def export(name):
    res = bpy.ops.nerfx.export_shot(filepath="%s/%s" % (OUT, name), frame_start=1,
                                    frame_end=1, nerf_object="Ball")
    assert res == {"FINISHED"}, res


def rgb_rows(name, seed):
    scene.cycles.seed = seed
    scene.frame_set(1)
    r.filepath = "%s/%s.exr" % (OUT, name)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(r.filepath)
    w, h = img.size
    px = list(img.pixels)
    rows = []
    for y in range(h - 1, -1, -1):
        row = px[y * w * 4 : (y + 1) * w * 4]
        rows.append([v for i, v in enumerate(row) if i % 4 != 3])
    bpy.data.images.remove(img)
    return rows


reference = {"blender": bpy.app.version_string, "width": WIDTH, "height": HEIGHT, "frame": 1,
             "ball": BALL, "wall": WALL}
export("shot.json")
reference["disk"] = rgb_rows("disk", 1)
reference["disk_again"] = rgb_rows("disk_again", 2)
dof.aperture_blades = 5
dof.aperture_rotation = 0.4
dof.aperture_ratio = 1.6
export("shot_polygon.json")
reference["polygon"] = rgb_rows("polygon", 1)
dof.use_dof = False
reference["sharp"] = rgb_rows("sharp", 1)
with open(OUT + "/reference.json", "w") as f:
    json.dump(reference, f)
print("nerfx depth of field: wrote")
# Blender as a Python module (bpy 4.5) can hang in its exit handlers after a Cycles render:
# everything is written, so leave at once.
sys.stdout.flush()
os._exit(0)
