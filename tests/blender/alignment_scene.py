# SPDX-License-Identifier: Apache-2.0
"""Builds the alignment scenes in headless Blender, exports them with the nerfx add-on, and
writes what Blender itself says: projections of world points (world_to_camera_view) and
Cycles renders of a sphere mesh (alpha and Z).

Run: blender -b --factory-startup --python alignment_scene.py -- ADDON_DIR OUT_DIR
 or: python alignment_scene.py -- ADDON_DIR OUT_DIR   (Blender as a Python module, bpy)

OUT_DIR/reference.json lists the cases; each case names its shot file and holds either
`points` (NeRF-local point, frame, Blender's pixel position and depth) or `render` (frame,
width, height, top-down rows of alpha and Z, the sphere's local centre and radius).
"""

import json
import math
import os
import random
import sys

import bpy
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Euler, Vector

ADDON_DIR, OUT = sys.argv[sys.argv.index("--") + 1 :][:2]
sys.path.insert(0, ADDON_DIR)
import nerfx_addon  # noqa: E402

nerfx_addon.register()

SPHERE_CENTER = (0.2, -0.1, 0.3)
SPHERE_RADIUS = 0.8

scene = bpy.context.scene
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)

# The NeRF object: animated, rotated, non-uniformly scaled.
nerf = bpy.data.objects.new("NeRF", None)
scene.collection.objects.link(nerf)
for f, (loc, rot) in enumerate(
    [((0.5, 1.0, 0.2), (0.3, -0.2, 0.5)), ((0.3, 0.8, 0.4), (0.4, -0.1, 0.9)), ((0.1, 0.9, 0.3), (0.2, 0.1, 1.2))],
    start=1,
):
    nerf.location = loc
    nerf.rotation_euler = Euler(rot)
    nerf.scale = (1.3, 0.7, 1.0 + 0.1 * f)
    for path in ("location", "rotation_euler", "scale"):
        nerf.keyframe_insert(path, frame=f)

# The stand-in sphere mesh, in the NeRF object's frame.
bpy.ops.mesh.primitive_uv_sphere_add(segments=256, ring_count=128, radius=SPHERE_RADIUS)
sphere = bpy.context.active_object
for v in sphere.data.vertices:
    v.co += Vector(SPHERE_CENTER)
sphere.location = (0.0, 0.0, 0.0)
sphere.parent = nerf
mat = bpy.data.materials.new("glow")
mat.use_nodes = True
nodes = mat.node_tree.nodes
nodes.clear()
emit = nodes.new("ShaderNodeEmission")
out = nodes.new("ShaderNodeOutputMaterial")
mat.node_tree.links.new(emit.outputs[0], out.inputs[0])
sphere.data.materials.append(mat)

# The camera: animated placement and focal length, aimed near the sphere.
cam_data = bpy.data.cameras.new("Cam")
cam = bpy.data.objects.new("Cam", cam_data)
scene.collection.objects.link(cam)
scene.camera = cam
for f, (loc, aim, lens) in enumerate(
    [((5.0, -4.0, 2.5), (0.6, 0.9, 0.4), 35.0), ((5.5, -3.0, 1.5), (0.3, 0.8, 0.6), 42.0), ((4.5, -4.5, 3.0), (0.2, 1.0, 0.2), 50.0)],
    start=1,
):
    cam.location = loc
    direction = Vector(aim) - Vector(loc)
    cam.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    cam.rotation_euler.rotate_axis("Z", 0.15 * f)  # some roll
    cam_data.lens = lens
    cam.keyframe_insert("location", frame=f)
    cam.keyframe_insert("rotation_euler", frame=f)
    cam_data.keyframe_insert("lens", frame=f)
scene.frame_start, scene.frame_end = 1, 3

# Cycles, small and exact: point-like pixel filter, no denoiser, transparent film.
scene.render.engine = "CYCLES"
scene.cycles.device = "CPU"
scene.cycles.samples = 4
scene.cycles.use_adaptive_sampling = False
scene.cycles.use_denoising = False
scene.cycles.max_bounces = 0
scene.cycles.filter_width = 0.01
scene.render.film_transparent = True
view_layer = scene.view_layers[0]
view_layer.cycles.use_denoising = False
view_layer.use_pass_z = True

# Compositor: alpha in R, Z in G of the written image (a float EXR, bottom row first).
if hasattr(scene, "compositing_node_group"):
    # Blender 5: the compositor is a node group whose output is the image written.
    tree = bpy.data.node_groups.new("nerfx alignment", "CompositorNodeTree")
    tree.interface.new_socket(name="Image", in_out="OUTPUT", socket_type="NodeSocketColor")
    scene.compositing_node_group = tree
    composite = tree.nodes.new("NodeGroupOutput")
else:
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    composite = tree.nodes.new("CompositorNodeComposite")
    composite.use_alpha = False
rl = tree.nodes.new("CompositorNodeRLayers")
try:  # Blender 3.3+; older ones have CombineRGBA
    comb = tree.nodes.new("CompositorNodeCombineColor")
except RuntimeError:
    comb = tree.nodes.new("CompositorNodeCombineRGBA")
tree.links.new(rl.outputs["Alpha"], comb.inputs[0])
tree.links.new(rl.outputs["Depth"], comb.inputs[1])
tree.links.new(comb.outputs[0], composite.inputs[0])
settings = scene.render.image_settings
settings.file_format = "OPEN_EXR"
settings.color_depth = "32"
settings.color_mode = "RGBA"
scene.render.use_compositing = True


def fcurves(obj):
    """The object's F-curves: Blender 5 keeps them in the action's channel bag of the
    object's slot (`Action.fcurves` is gone)."""
    action = obj.animation_data.action
    if hasattr(action, "fcurves"):
        return action.fcurves
    from bpy_extras import anim_utils

    return anim_utils.action_get_channelbag_for_slot(action, obj.animation_data.action_slot).fcurves


def set_format(w, h, pct, pa):
    r = scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = w, h, pct
    r.pixel_aspect_x, r.pixel_aspect_y = pa


def export(name):
    path = "%s/%s.json" % (OUT, name)
    res = bpy.ops.nerfx.export_shot(filepath=path, frame_start=1, frame_end=3, nerf_object="NeRF")
    assert res == {"FINISHED"}, res
    return path


def project_points(rng, n_per_frame):
    r = scene.render
    w = r.resolution_x * r.resolution_percentage // 100
    h = r.resolution_y * r.resolution_percentage // 100
    points = []
    for f in (1, 2, 3):
        scene.frame_set(f)
        kept = 0
        while kept < n_per_frame:
            local = Vector([rng.uniform(-2.0, 2.0) for _ in range(3)])
            world = nerf.matrix_world @ local
            p = world_to_camera_view(scene, cam, world)
            if p.z <= cam_data.clip_start:
                continue
            points.append({"frame": f, "local": list(local), "x": p.x * w, "y": (1.0 - p.y) * h, "depth": p.z})
            kept += 1
    return points


def render_frame(name, frame):
    scene.frame_set(frame)
    scene.render.filepath = "%s/%s.exr" % (OUT, name)
    bpy.ops.render.render(write_still=True)
    img = bpy.data.images.load(scene.render.filepath)
    img.colorspace_settings.name = "Non-Color"
    w, h = img.size
    px = list(img.pixels)
    alpha, depth = [], []
    for y in range(h - 1, -1, -1):  # top row first
        row = px[y * w * 4 : (y + 1) * w * 4]
        alpha.append(row[0::4])
        depth.append(row[1::4])
    bpy.data.images.remove(img)
    return {"frame": frame, "width": w, "height": h, "alpha": alpha, "z": depth}


rng = random.Random(7)
cases = []
cam_data.type = "PERSP"
# Projections: every sensor fit on landscape, portrait and square, with shift and pixel aspect.
fits = ("AUTO", "HORIZONTAL", "VERTICAL")
formats = (("landscape", 192, 108), ("portrait", 90, 160), ("square", 128, 128))
for i, fit in enumerate(fits):
    for j, (orient, w, h) in enumerate(formats):
        name = "proj_%s_%s" % (fit.lower(), orient)
        cam_data.sensor_fit = fit
        cam_data.sensor_width, cam_data.sensor_height = 36.0, 24.0
        cam_data.shift_x, cam_data.shift_y = (0.08 * (i - 1), -0.05 * (j - 1))
        pa = ((1.0, 1.0), (2.0, 1.0), (1.0, 1.5))[(i + j) % 3]
        set_format(w, h, 100 if (i + j) % 2 else 50, pa)
        cases.append({"name": name, "shot": export(name), "points": project_points(rng, 15)})

# nerfstudio camera path from the add-on (no shift, square pixels: what a path can hold).
cam_data.sensor_fit = "AUTO"
cam_data.shift_x = cam_data.shift_y = 0.0
set_format(192, 108, 100, (1.0, 1.0))
ns_path = "%s/camera_path.json" % OUT
res = bpy.ops.nerfx.export_camera_path(filepath=ns_path, frame_start=1, frame_end=3, nerf_object="NeRF")
assert res == {"FINISHED"}, res
cases.append({"name": "camera_path_auto_landscape", "camera_path": ns_path, "points": project_points(rng, 15)})
# ... and imported back: one new camera object and data block, keyed on frames 1..3.
cameras_before = len(bpy.data.cameras)
original = scene.camera
res = bpy.ops.nerfx.import_camera_path(filepath=ns_path, nerf_object="", frame_start=1)
assert res == {"FINISHED"}, res
imported = scene.camera
assert imported is not original and len(bpy.data.cameras) == cameras_before + 1
keyed = sorted({int(k.co.x) for fc in fcurves(imported) for k in fc.keyframe_points})
assert keyed == [1, 2, 3], keyed
bpy.data.objects.remove(imported)
bpy.data.cameras.remove(bpy.data.cameras["NerfstudioCamera"])
scene.camera = original

# Renders: a few formats of the same shot, then an equirectangular panorama.
renders = (
    ("render_landscape_shift", "AUTO", (0.1, -0.05), 160, 120, (1.0, 1.0), 2),
    ("render_portrait_vertical_aspect", "VERTICAL", (0.0, 0.08), 96, 128, (1.0, 1.25), 3),
    ("render_square_horizontal", "HORIZONTAL", (-0.05, 0.0), 112, 112, (1.0, 1.0), 1),
)
for name, fit, shift, w, h, pa, frame in renders:
    cam_data.sensor_fit = fit
    cam_data.shift_x, cam_data.shift_y = shift
    set_format(w, h, 100, pa)
    case = {"name": name, "shot": export(name), "render": render_frame(name, frame)}
    cases.append(case)

cam_data.type = "PANO"
nerfx_addon.set_panorama_type(cam_data, "EQUIRECTANGULAR")
cam_data.shift_x = cam_data.shift_y = 0.0
set_format(320, 160, 100, (1.0, 1.0))
cases.append({"name": "render_equirect", "shot": export("render_equirect"), "render": render_frame("render_equirect", 2)})

with open("%s/reference.json" % OUT, "w") as f:
    json.dump(
        {"sphere": {"center": SPHERE_CENTER, "radius": SPHERE_RADIUS}, "cases": cases, "blender": bpy.app.version_string},
        f,
    )
print("nerfx alignment: wrote %d cases" % len(cases))
# Blender as a Python module (bpy 4.5) can hang in its exit handlers after a Cycles render:
# everything is written, so leave at once.
sys.stdout.flush()
os._exit(0)
