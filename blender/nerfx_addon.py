# SPDX-License-Identifier: Apache-2.0
"""nerfx Blender add-on: writes nerfx shot files and nerfstudio camera paths, and imports
nerfstudio camera paths as an animated camera.

A shot file (JSON, schema version 1, read by nerfx's `camera::Shot`) holds per frame the
camera's `matrix_world` and intrinsics and the NeRF object's `matrix_world` (read at every
frame: it may be animated). nerfx aligns the field itself (`C_t = N^-1 C_o`) and keeps lens
shift, pixel aspect and every sensor fit, which a nerfstudio camera path cannot hold. A
perspective camera's depth of field (`Camera.dof`) is written per frame, a focus object as the
depth of its origin along the camera's view axis at that frame, as Cycles measures it.

Works in Blender 3.4, 4.x and 5.x (tested in 3.4, 4.5 LTS and 5.0). The panel is in Output Properties > nerfx. Every operator can be
called from a script, e.g.

    bpy.ops.nerfx.export_shot(filepath="/tmp/shot.json", frame_start=1, frame_end=24,
                              nerf_object="NeRF")
    bpy.ops.nerfx.export_camera_path(filepath="/tmp/camera_path.json", nerf_object="NeRF")
    bpy.ops.nerfx.import_camera_path(filepath="/tmp/camera_path.json", nerf_object="NeRF")
    bpy.ops.nerfx.render_environment(scene_file="/shots/scene.json", at_object="Chair")
    bpy.ops.nerfx.load_environment(filepath="/tmp/envmap.exr")
    bpy.ops.nerfx.import_splats(filepath="/captures/scan.ply")
    bpy.ops.nerfx.import_splats(filepath="/captures/scan.spz", executable="/opt/nerfx/nerfx")

Environment maps: `nerfx envmap` renders the field as a 2:1 equirectangular image laid out as
the World's Environment Texture reads it (image centre +X, top +Z), so loading it as the
World's colour with no Mapping node lights the Blender scene as the field would.

Splat stand-ins: a Gaussian-splat file imports as a point cloud, one vertex per splat mean
with its DC colour (`0.5 + 0.2821·f_dc`, clamped), in the splats' own frame (the frame nerfx
renders them in), so it can serve as the NeRF object the artist places. An INRIA-layout PLY is
read here with NumPy; every other format nerfx reads (SuperSplat's compressed PLY, `.splat`,
`.spz`, `.sog`, a SOG folder's `meta.json`) goes through `nerfx export-standin`, so the stand-in
comes from the very reader that renders the splats (its colours in 8 bits).
"""

bl_info = {
    "name": "nerfx shot export",
    "description": "Write nerfx shot files and nerfstudio camera paths; import nerfstudio paths",
    "author": "nerfx",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "Properties > Output > nerfx",
    "category": "Import-Export",
}

import json
import math
import os
import subprocess
import tempfile

import bpy
from bpy.props import IntProperty, PointerProperty, StringProperty
from mathutils import Matrix

SHOT_VERSION = 1


# --- Blender-version differences -------------------------------------------------------------


def _pano_settings(cam):
    """Where the panorama settings live: `Camera` itself in 4.x, `Camera.cycles` in 3.x."""
    return cam if hasattr(cam, "panorama_type") else cam.cycles


def panorama_type(cam):
    """The camera's panorama type (e.g. EQUIRECTANGULAR)."""
    return _pano_settings(cam).panorama_type


def set_panorama_type(cam, value):
    """Sets the panorama type on the place this Blender keeps it."""
    _pano_settings(cam).panorama_type = value


def _is_full_sphere(cam):
    p = _pano_settings(cam)
    return (
        abs(p.longitude_min + math.pi) < 1e-6
        and abs(p.longitude_max - math.pi) < 1e-6
        and abs(p.latitude_min + math.pi / 2) < 1e-6
        and abs(p.latitude_max - math.pi / 2) < 1e-6
    )


def _is_front_half(cam):
    p = _pano_settings(cam)
    return abs(p.longitude_min + math.pi / 2) < 1e-6 and abs(p.longitude_max - math.pi / 2) < 1e-6


# --- reading the scene ------------------------------------------------------------------------


def rows(m):
    """A 4x4 matrix as four rows of floats."""
    return [[float(m[r][c]) for c in range(4)] for r in range(4)]


def _frame_range(op, scene):
    props = op.properties
    start = op.frame_start if props.is_property_set("frame_start") else scene.frame_start
    end = op.frame_end if props.is_property_set("frame_end") else scene.frame_end
    return start, end


def _resolve(op, context):
    """The scene camera and the NeRF object, or an error message."""
    scene = context.scene
    name = op.nerf_object
    nerf = scene.objects.get(name) if name else scene.nerfx_nerf_object
    if nerf is None:
        return None, None, "pick the NeRF object (its stand-in mesh or point cloud)"
    cam = scene.camera
    if cam is None or cam.type != "CAMERA":
        return None, None, "the scene has no active camera"
    return cam, nerf, None


def camera_record(cam_obj, scene):
    """The shot file's `camera` entry for the current frame; raises ValueError for a camera
    nerfx cannot render."""
    cam = cam_obj.data
    rec = {
        "matrix_world": rows(cam_obj.matrix_world),
        "lens": cam.lens,
        "sensor_width": cam.sensor_width,
        "sensor_height": cam.sensor_height,
        "sensor_fit": cam.sensor_fit,
        "shift_x": cam.shift_x,
        "shift_y": cam.shift_y,
        "clip_start": cam.clip_start,
        "clip_end": cam.clip_end,
        "stereo": None,
    }
    if cam.type == "PERSP":
        rec["type"] = "PERSP"
        rec["dof"] = depth_of_field(cam_obj)
    elif cam.type == "PANO" and panorama_type(cam) == "EQUIRECTANGULAR":
        rec["type"] = "PANO"
        rec["panorama_type"] = "EQUIRECTANGULAR"
        if scene.render.use_multiview and scene.render.views_format == "STEREO_3D":
            if _is_front_half(cam):
                mode = "VR180"
            elif _is_full_sphere(cam):
                mode = "ODS"
            else:
                raise ValueError("stereo panoramas must span 360 (ODS) or 180 (VR180) degrees")
            rec["stereo"] = {"mode": mode, "eye": "both", "ipd": cam.stereo.interocular_distance}
        elif not _is_full_sphere(cam):
            raise ValueError("equirectangular cameras must cover the full sphere")
    else:
        raise ValueError("only perspective and equirectangular cameras are supported")
    return rec


def _focus_point(dof):
    """The world position a focus object (or the bone named by `focus_subtarget` of an
    armature) puts the focus at."""
    target = dof.focus_object
    bone = getattr(dof, "focus_subtarget", "")
    if bone and target.pose and bone in target.pose.bones:
        return (target.matrix_world @ target.pose.bones[bone].matrix).translation
    return target.matrix_world.translation


def depth_of_field(cam_obj):
    """The shot file's `dof` entry of a perspective camera at the current frame, or None when
    its depth of field is off. The focus distance is Cycles': a focus object's depth along the
    camera's view axis (the camera's scale cleared), else `focus_distance`."""
    dof = cam_obj.data.dof
    if not dof.use_dof:
        return None
    if dof.focus_object is not None:
        m = cam_obj.matrix_world
        view = m.col[2].xyz.normalized()
        distance = abs(view.dot(m.translation - _focus_point(dof)))
    else:
        distance = dof.focus_distance
    return {
        "focus_distance": float(distance),
        "fstop": float(dof.aperture_fstop),
        "blades": int(dof.aperture_blades),
        "rotation": float(dof.aperture_rotation),
        "ratio": float(dof.aperture_ratio),
    }


def motion_blur(scene):
    """Blender's motion blur as the shot file holds it, or None when it is off."""
    render = scene.render
    if not render.use_motion_blur:
        return None
    # Blender 5 keeps the shutter position in the render settings; before, Cycles kept it.
    if hasattr(render, "motion_blur_position"):
        position = render.motion_blur_position
    elif hasattr(scene, "cycles"):
        position = getattr(scene.cycles, "motion_blur_position", "CENTER")
    else:
        position = "CENTER"
    return {"shutter": render.motion_blur_shutter, "position": position.lower()}


def _shot_frames(scene, start, end):
    """The frames a shot holds: start..end, scene.frame_step apart; with motion blur also
    every frame the shutter interval of those reaches into (nerfx interpolates between whole
    frames), so the shot's range grows by that margin at both ends."""
    step = max(1, scene.frame_step)
    frames = set(range(start, end + 1, step))
    blur = motion_blur(scene)
    if blur:
        reach = math.ceil(blur["shutter"])
        for f in list(frames):
            frames.update(range(f - reach, f + reach + 1))
    return sorted(frames)


def build_shot(scene, cam_obj, nerf_obj, start, end):
    """The shot dictionary for frames start..end (inclusive, scene.frame_step apart)."""
    render = scene.render
    frames = []
    current = scene.frame_current
    try:
        for f in _shot_frames(scene, start, end):
            scene.frame_set(f)
            frames.append(
                {
                    "frame": f,
                    "camera": camera_record(cam_obj, scene),
                    "objects": {nerf_obj.name: rows(nerf_obj.matrix_world)},
                }
            )
    finally:
        scene.frame_set(current)
    return {
        "version": SHOT_VERSION,
        "fps": render.fps,
        "fps_base": render.fps_base,
        "resolution_x": render.resolution_x,
        "resolution_y": render.resolution_y,
        "resolution_percentage": render.resolution_percentage,
        "pixel_aspect_x": render.pixel_aspect_x,
        "pixel_aspect_y": render.pixel_aspect_y,
        "nerf_object": nerf_obj.name,
        "frames": frames,
        **({"motion_blur": motion_blur(scene)} if motion_blur(scene) else {}),
    }


def vertical_fov(cam, render):
    """Blender's exact vertical field of view (radians) of a perspective camera, from the
    same sensor-fit rules nerfx uses (shift and pixel aspect cannot be expressed)."""
    w = render.resolution_x * render.resolution_percentage // 100
    h = render.resolution_y * render.resolution_percentage // 100
    pa_x, pa_y = max(render.pixel_aspect_x, 1.0), max(render.pixel_aspect_y, 1.0)
    fit = cam.sensor_fit
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and w * pa_x >= h * pa_y)
    sensor = cam.sensor_height if fit == "VERTICAL" else cam.sensor_width
    ycor = pa_y / pa_x
    viewfac = w if horizontal else ycor * h
    s = sensor / (cam.lens * viewfac)
    return 2.0 * math.atan(ycor * h / 2.0 * s)


def build_camera_path(scene, cam_obj, nerf_obj, start, end):
    """A nerfstudio camera path (as the nerfstudio add-on writes it) for frames start..end."""
    render = scene.render
    cam = cam_obj.data
    if cam.type == "PERSP":
        cam_type = "perspective"
    elif cam.type == "PANO" and panorama_type(cam) == "EQUIRECTANGULAR":
        cam_type = "equirectangular"
    else:
        raise ValueError("only perspective and equirectangular cameras are supported")
    path, keyframes = [], []
    current = scene.frame_current
    step = max(1, scene.frame_step)
    fps = render.fps / render.fps_base
    try:
        for i, f in enumerate(range(start, end + 1, step)):
            scene.frame_set(f)
            c2w = nerf_obj.matrix_world.inverted() @ cam_obj.matrix_world
            fov = math.degrees(vertical_fov(cam, render)) if cam_type == "perspective" else 180.0
            flat_rows = [float(x) for r in range(4) for x in c2w.row[r]]
            flat_cols = [float(x) for c in range(4) for x in c2w.col[c]]
            path.append({"camera_to_world": flat_rows, "fov": fov, "aspect": 1})
            props = [["FOV", fov], ["NAME", "Camera %d" % i], ["TIME", i / fps]]
            keyframes.append(
                {
                    "matrix": json.dumps(flat_cols),
                    "fov": fov,
                    "aspect": 1,
                    "properties": json.dumps(props),
                }
            )
    finally:
        scene.frame_set(current)
    return {
        "keyframes": keyframes,
        "camera_type": cam_type,
        "render_height": render.resolution_y * render.resolution_percentage // 100,
        "render_width": render.resolution_x * render.resolution_percentage // 100,
        "camera_path": path,
        "fps": fps,
        "seconds": len(path) / fps,
        "smoothness_value": 0,
        "is_cycle": False,
    }


def _row_major(values):
    """A 4x4 Matrix from 16 row-major floats or nested rows (3x4 gets 0 0 0 1)."""
    if values and isinstance(values[0], (list, tuple)):
        values = [x for row in values for x in row]
    if len(values) == 12:
        values = list(values) + [0.0, 0.0, 0.0, 1.0]
    if len(values) != 16:
        raise ValueError("camera_to_world must hold 16 numbers")
    return Matrix([values[0:4], values[4:8], values[8:12], values[12:16]])


def import_camera_path(context, data, nerf_obj, frame_start, name="NerfstudioCamera"):
    """Creates one animated camera (one camera data block) from a camera-path dictionary."""
    scene = context.scene
    cam_type = data.get("camera_type", "perspective").lower()
    if cam_type not in ("perspective", "equirectangular"):
        raise ValueError("camera_type %r cannot be shown as a Blender camera" % cam_type)
    cam_data = bpy.data.cameras.new(name)
    cam_obj = bpy.data.objects.new(name, cam_data)
    scene.collection.objects.link(cam_obj)
    scene.render.resolution_x = int(data["render_width"])
    scene.render.resolution_y = int(data["render_height"])
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    if cam_type == "equirectangular":
        cam_data.type = "PANO"
        scene.render.engine = "CYCLES"
        set_panorama_type(cam_data, "EQUIRECTANGULAR")
    cam_data.sensor_fit = "VERTICAL"
    n_mat = nerf_obj.matrix_world.copy() if nerf_obj is not None else Matrix.Identity(4)
    previous = None
    path = data["camera_path"]
    for i, entry in enumerate(path):
        f = frame_start + i
        cam_obj.matrix_world = n_mat @ _row_major(entry["camera_to_world"])
        cam_obj.scale = (1.0, 1.0, 1.0)
        if previous is not None:
            cam_obj.rotation_euler.make_compatible(previous)
        previous = cam_obj.rotation_euler.copy()
        cam_obj.keyframe_insert("location", frame=f)
        cam_obj.keyframe_insert("rotation_euler", frame=f)
        if cam_type == "perspective":
            fov = math.radians(float(entry["fov"]))
            cam_data.lens = (cam_data.sensor_height / 2.0) / math.tan(fov / 2.0)
            cam_data.keyframe_insert("lens", frame=f)
    scene.frame_start = frame_start
    scene.frame_end = frame_start + len(path) - 1
    seconds = float(data.get("seconds", 0) or 0)
    if seconds > 0:
        rate = len(path) / seconds
        scene.render.fps = max(1, round(rate))
        scene.render.fps_base = scene.render.fps / rate
    scene.camera = cam_obj
    return cam_obj


# --- operators --------------------------------------------------------------------------------


class _ExportBase:
    filepath: StringProperty(name="File", subtype="FILE_PATH")
    frame_start: IntProperty(name="Start", description="First frame (default: the scene's)")
    frame_end: IntProperty(name="End", description="Last frame (default: the scene's)")
    nerf_object: StringProperty(
        name="NeRF object", description="Name of the NeRF stand-in (default: the panel's pick)"
    )

    def invoke(self, context, event):
        if not self.filepath:
            self.filepath = bpy.path.abspath(context.scene.nerfx_output_dir or "//") + self.default_name
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        cam, nerf, problem = _resolve(self, context)
        if problem:
            self.report({"ERROR"}, "nerfx: " + problem)
            return {"CANCELLED"}
        if not self.filepath:
            self.report({"ERROR"}, "nerfx: no output file given")
            return {"CANCELLED"}
        start, end = _frame_range(self, context.scene)
        if end < start:
            self.report({"ERROR"}, "nerfx: the frame range runs backwards")
            return {"CANCELLED"}
        try:
            data = self.build(context.scene, cam, nerf, start, end)
        except ValueError as e:
            self.report({"ERROR"}, "nerfx: %s" % e)
            return {"CANCELLED"}
        path = bpy.path.abspath(self.filepath)
        with open(path, "w", encoding="utf8") as f:
            json.dump(data, f, indent=1, allow_nan=False)
        self.report({"INFO"}, "nerfx: wrote %s" % path)
        return {"FINISHED"}


class NERFX_OT_export_shot(_ExportBase, bpy.types.Operator):
    """Write a nerfx shot file: camera and NeRF object per frame, with full intrinsics"""

    bl_idname = "nerfx.export_shot"
    bl_label = "Export nerfx Shot"
    default_name = "shot.json"

    def build(self, scene, cam, nerf, start, end):
        return build_shot(scene, cam, nerf, start, end)


class NERFX_OT_export_camera_path(_ExportBase, bpy.types.Operator):
    """Write a nerfstudio camera_path.json (camera relative to the NeRF object) for ns-render"""

    bl_idname = "nerfx.export_camera_path"
    bl_label = "Export nerfstudio Camera Path"
    default_name = "camera_path.json"

    def build(self, scene, cam, nerf, start, end):
        c = cam.data
        if c.type == "PERSP" and (c.shift_x or c.shift_y):
            self.report({"WARNING"}, "nerfx: nerfstudio camera paths cannot hold lens shift")
        r = scene.render
        if r.pixel_aspect_x != r.pixel_aspect_y:
            self.report({"WARNING"}, "nerfx: nerfstudio camera paths cannot hold pixel aspect")
        return build_camera_path(scene, cam, nerf, start, end)


class NERFX_OT_import_camera_path(bpy.types.Operator):
    """Create an animated camera from a nerfstudio camera_path.json"""

    bl_idname = "nerfx.import_camera_path"
    bl_label = "Import nerfstudio Camera Path"

    filepath: StringProperty(name="File", subtype="FILE_PATH")
    nerf_object: StringProperty(name="NeRF object")
    frame_start: IntProperty(name="First frame", default=1)

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        scene = context.scene
        nerf = scene.objects.get(self.nerf_object) if self.nerf_object else scene.nerfx_nerf_object
        try:
            with open(bpy.path.abspath(self.filepath), encoding="utf8") as f:
                data = json.load(f)
            import_camera_path(context, data, nerf, self.frame_start)
        except (OSError, ValueError, KeyError, TypeError) as e:
            self.report({"ERROR"}, "nerfx: cannot import %s: %s" % (self.filepath, e))
            return {"CANCELLED"}
        return {"FINISHED"}


SH_C0 = 0.28209479177387814
PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}


def read_splat_means(path):
    """Means (N, 3) and DC colours (N, 3) of a binary Gaussian-splat PLY, with NumPy."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply") or end < 0:
        raise ValueError("not a PLY file (no 'ply' / 'end_header')")
    order, count, fields, vertex = "<", None, [], False
    for line in data[:end].decode("ascii", "replace").splitlines()[1:]:
        words = line.split()
        if words[:1] == ["format"]:
            if words[1] == "ascii":
                raise ValueError("ASCII PLY is not read; save the splats as binary PLY")
            order = ">" if words[1] == "binary_big_endian" else "<"
        elif words[:1] == ["element"]:
            if count is not None and vertex:
                break
            vertex = words[1] == "vertex"
            if vertex:
                count = int(words[2])
            elif count is None:
                raise ValueError("an element '%s' comes before 'vertex'" % words[1])
        elif words[:1] == ["property"] and vertex:
            if words[1] == "list" or words[1] not in PLY_TYPES:
                raise ValueError("vertex property '%s' is not a scalar" % words[-1])
            fields.append((words[2], order + PLY_TYPES[words[1]]))
    names = [n for n, _ in fields]
    for need in ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"):
        if need not in names:
            raise ValueError("no vertex property '%s': not a Gaussian-splat PLY" % need)
    dtype = np.dtype(fields)
    body = data[end + len(b"end_header\n"):]
    if count is None or len(body) < count * dtype.itemsize:
        raise ValueError("truncated: the header declares more splats than the file holds")
    table = np.frombuffer(body, dtype=dtype, count=count)
    means = np.stack([table[a].astype(np.float64) for a in "xyz"], axis=1)
    dc = np.stack([table["f_dc_%d" % c].astype(np.float64) for c in range(3)], axis=1)
    finite = np.isfinite(means).all(axis=1) & np.isfinite(dc).all(axis=1)
    return means[finite], np.clip(0.5 + SH_C0 * dc[finite], 0.0, 1.0)


def is_inria_ply(path):
    """Whether `path` is a PLY whose header has no `chunk` element (SuperSplat's compressed
    layout has one): the layout read here with NumPy."""
    with open(path, "rb") as f:
        head = f.read(1 << 16)
    if not head.startswith(b"ply"):
        return False
    end = head.find(b"end_header")
    header = head[: end if end >= 0 else len(head)]
    return b"\nelement chunk " not in header


def read_standin_points(path):
    """Means (N, 3) and colours (N, 3) of a stand-in PLY written by `nerfx export-standin`
    (float x y z, uchar red green blue)."""
    import numpy as np

    with open(path, "rb") as f:
        data = f.read()
    end = data.find(b"end_header\n")
    if end < 0:
        raise ValueError("nerfx wrote no stand-in PLY")
    count = None
    for line in data[:end].decode("ascii", "replace").splitlines():
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("r", "u1"), ("g", "u1"), ("b", "u1")])
    table = np.frombuffer(data, dtype=dtype, count=count or 0, offset=end + len(b"end_header\n"))
    means = np.stack([table[a].astype(np.float64) for a in "xyz"], axis=1)
    colours = np.stack([table[c].astype(np.float64) / 255.0 for c in "rgb"], axis=1)
    return means, colours


def nerfx_splat_means(path, executable):
    """Means and DC colours of any splat file nerfx reads, through `nerfx export-standin`
    (every splat kept: no opacity threshold, no point budget)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = os.path.join(tmp, "standin.ply")
        command = [
            executable, "export-standin", path, "-o", out,
            "--threshold=-1", "--points", str(2**62),
        ]
        try:
            done = subprocess.run(command, capture_output=True, text=True)
        except OSError as e:
            raise ValueError("cannot run %s (set the panel's nerfx program): %s" % (executable, e))
        if done.returncode != 0:
            raise ValueError(done.stderr.strip() or "nerfx export-standin failed")
        return read_standin_points(out)


def import_splats(context, path, name=None, executable="nerfx"):
    """Creates a point-cloud object of the splats at `path` (their means, DC colour in a
    "Col" point attribute), in the splats' own frame, and returns it. An INRIA PLY is read
    here; any other splat file through the nerfx program `executable`."""
    import numpy as np

    if os.path.isfile(path) and is_inria_ply(path):
        means, colours = read_splat_means(path)
    else:
        means, colours = nerfx_splat_means(path, executable)
    stem = os.path.basename(os.path.normpath(path))
    if stem.lower() == "meta.json":
        stem = os.path.basename(os.path.dirname(os.path.abspath(path)))
    name = name or stem.split(".")[0]
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(means))
    mesh.vertices.foreach_set("co", means.astype(np.float32).ravel())
    attribute = mesh.attributes.new("Col", "FLOAT_COLOR", "POINT")
    rgba = np.ones((len(means), 4), dtype=np.float32)
    rgba[:, :3] = colours
    attribute.data.foreach_set("color", rgba.ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    context.collection.objects.link(obj)
    return obj


class NERFX_OT_import_splats(bpy.types.Operator):
    """Import Gaussian splats (.ply, .splat, .spz, .sog, SOG meta.json) as a point cloud (one
    vertex per splat) to place them"""

    bl_idname = "nerfx.import_splats"
    bl_label = "Import Splats"
    bl_options = {"REGISTER", "UNDO"}

    filepath: StringProperty(name="File", subtype="FILE_PATH")
    filter_glob: StringProperty(default="*.ply;*.splat;*.spz;*.sog;*.json", options={"HIDDEN"})
    executable: StringProperty(name="nerfx program", description="Default: the panel's")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        path = bpy.path.abspath(self.filepath)
        try:
            executable = bpy.path.abspath(self.executable or context.scene.nerfx_executable)
            obj = import_splats(context, path, executable=executable)
        except (OSError, ValueError) as e:
            self.report({"ERROR"}, "nerfx: cannot import %s: %s" % (path, e))
            return {"CANCELLED"}
        if context.scene.nerfx_nerf_object is None:
            context.scene.nerfx_nerf_object = obj
        self.report({"INFO"}, "nerfx: %d splats from %s" % (len(obj.data.vertices), path))
        return {"FINISHED"}


def _menu_import(self, context):
    self.layout.operator(NERFX_OT_import_splats.bl_idname, text="Gaussian Splats (.ply, .splat, .spz, .sog) as nerfx stand-in")


def load_environment(scene, path):
    """Makes the image at `path` the World's colour: Environment Texture → Background."""
    image = bpy.data.images.load(path, check_existing=True)
    image.reload()
    world = scene.world
    if world is None:
        world = bpy.data.worlds.new("nerfx environment")
        scene.world = world
    world.use_nodes = True
    nodes, links = world.node_tree.nodes, world.node_tree.links
    background = next((n for n in nodes if n.type == "BACKGROUND"), None)
    if background is None:
        background = nodes.new("ShaderNodeBackground")
    output = next((n for n in nodes if n.type == "OUTPUT_WORLD"), None)
    if output is None:
        output = nodes.new("ShaderNodeOutputWorld")
    texture = nodes.get("nerfx environment")
    if texture is None:
        texture = nodes.new("ShaderNodeTexEnvironment")
        texture.name = "nerfx environment"
        texture.location = (background.location.x - 300, background.location.y)
    texture.image = image
    texture.projection = "EQUIRECTANGULAR"
    links.new(texture.outputs["Color"], background.inputs["Color"])
    links.new(background.outputs["Background"], output.inputs["Surface"])
    return image


class NERFX_OT_load_environment(bpy.types.Operator):
    """Light the scene with a nerfx environment map: set it as the World's colour"""

    bl_idname = "nerfx.load_environment"
    bl_label = "Load Environment Map"

    filepath: StringProperty(name="File", subtype="FILE_PATH")

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {"RUNNING_MODAL"}

    def execute(self, context):
        path = bpy.path.abspath(self.filepath)
        try:
            load_environment(context.scene, path)
        except RuntimeError as e:
            self.report({"ERROR"}, "nerfx: cannot load %s: %s" % (path, e))
            return {"CANCELLED"}
        self.report({"INFO"}, "nerfx: World lit by %s" % path)
        return {"FINISHED"}


class NERFX_OT_render_environment(bpy.types.Operator):
    """Render the field around an object with nerfx and light the scene with it"""

    bl_idname = "nerfx.render_environment"
    bl_label = "Render Environment Map"

    scene_file: StringProperty(name="Scene file", subtype="FILE_PATH")
    at_object: StringProperty(name="At object", description="Default: the active object")
    filepath: StringProperty(name="Output", subtype="FILE_PATH")
    executable: StringProperty(name="nerfx program", description="Default: the panel's")
    height: IntProperty(name="Height", default=0, min=0, description="Default: the panel's")
    nerf_object: StringProperty(name="NeRF object")

    def execute(self, context):
        scene = context.scene
        cam, nerf, problem = _resolve(self, context)
        at = scene.objects.get(self.at_object) if self.at_object else context.active_object
        scene_file = bpy.path.abspath(self.scene_file or scene.nerfx_scene_file)
        if problem is None and at is None:
            problem = "pick the object to render the environment around"
        if problem is None and not os.path.isfile(scene_file):
            problem = "no nerfx scene file at %r" % scene_file
        if problem:
            self.report({"ERROR"}, "nerfx: " + problem)
            return {"CANCELLED"}
        out = bpy.path.abspath(
            self.filepath or os.path.join(scene.nerfx_output_dir or "//", "envmap.exr")
        )
        frame = scene.frame_current
        position = at.matrix_world.translation
        with tempfile.TemporaryDirectory() as tmp:
            shot = os.path.join(tmp, "shot.json")
            with open(shot, "w", encoding="utf8") as f:
                json.dump(build_shot(scene, cam, nerf, frame, frame), f, allow_nan=False)
            command = [
                bpy.path.abspath(self.executable or scene.nerfx_executable),
                "envmap", scene_file, shot, "--frame", str(frame),
                "--position", ",".join(repr(float(c)) for c in position),
                "--height", str(self.height or scene.nerfx_envmap_height),
                "-o", out,
            ]
            try:
                done = subprocess.run(command, capture_output=True, text=True)
            except OSError as e:
                self.report({"ERROR"}, "nerfx: cannot run %s: %s" % (command[0], e))
                return {"CANCELLED"}
        if done.returncode != 0:
            self.report({"ERROR"}, "nerfx envmap failed: %s" % done.stderr.strip())
            return {"CANCELLED"}
        load_environment(scene, out)
        self.report({"INFO"}, "nerfx: World lit by %s" % out)
        return {"FINISHED"}


class NERFX_PT_panel(bpy.types.Panel):
    """nerfx: shot export and nerfstudio camera paths"""

    bl_idname = "NERFX_PT_panel"
    bl_label = "nerfx"
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "output"

    def draw(self, context):
        layout = self.layout
        scene = context.scene
        layout.prop(scene, "nerfx_nerf_object")
        layout.prop(scene, "nerfx_output_dir")
        row = layout.row(align=True)
        row.prop(scene, "frame_start")
        row.prop(scene, "frame_end")
        layout.operator(NERFX_OT_export_shot.bl_idname, icon="EXPORT")
        layout.operator(NERFX_OT_export_camera_path.bl_idname, icon="EXPORT")
        layout.operator(NERFX_OT_import_camera_path.bl_idname, icon="IMPORT")
        layout.operator(NERFX_OT_import_splats.bl_idname, icon="POINTCLOUD_DATA")
        box = layout.box()
        box.label(text="Environment map")
        box.prop(scene, "nerfx_scene_file")
        box.prop(scene, "nerfx_executable")
        box.prop(scene, "nerfx_envmap_height")
        box.operator(NERFX_OT_render_environment.bl_idname, icon="WORLD")
        box.operator(NERFX_OT_load_environment.bl_idname, icon="IMAGE_DATA")


CLASSES = (
    NERFX_OT_export_shot,
    NERFX_OT_export_camera_path,
    NERFX_OT_import_camera_path,
    NERFX_OT_load_environment,
    NERFX_OT_render_environment,
    NERFX_OT_import_splats,
    NERFX_PT_panel,
)


def register():
    bpy.types.Scene.nerfx_nerf_object = PointerProperty(
        name="NeRF object", type=bpy.types.Object, description="The stand-in of the field"
    )
    bpy.types.Scene.nerfx_output_dir = StringProperty(
        name="Output folder", subtype="DIR_PATH", default="//"
    )
    bpy.types.Scene.nerfx_scene_file = StringProperty(
        name="Scene file", subtype="FILE_PATH", description="The nerfx scene the field is in"
    )
    bpy.types.Scene.nerfx_executable = StringProperty(
        name="nerfx program", subtype="FILE_PATH", default="nerfx"
    )
    bpy.types.Scene.nerfx_envmap_height = IntProperty(
        name="Height", default=1024, min=8, max=32768, description="Pixels; the width is twice"
    )
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.TOPBAR_MT_file_import.append(_menu_import)


def unregister():
    bpy.types.TOPBAR_MT_file_import.remove(_menu_import)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    del bpy.types.Scene.nerfx_envmap_height
    del bpy.types.Scene.nerfx_executable
    del bpy.types.Scene.nerfx_scene_file
    del bpy.types.Scene.nerfx_output_dir
    del bpy.types.Scene.nerfx_nerf_object


if __name__ == "__main__":
    register()
