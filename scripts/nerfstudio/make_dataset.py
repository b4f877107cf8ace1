"""Writes a small synthetic nerfstudio dataset rendered by nerfx from an analytic scene.

    python make_dataset.py OUT [--nerfx target/release/nerfx]

OUT receives:
- scene.json: the analytic scene (Blender-style world, Z up, linear colours): a few objects
  near the origin inside an opaque room (checkered ground, four walls, a sky-blue ceiling),
  so that every ray ends on something opaque (no background question in training) and the
  walls, at 2.5–3 times the camera distance, land in nerfacto's contracted far field;
- shot.json: a nerfx shot of the training cameras (frames 1..N) on a sphere around the
  objects, looking at the origin;
- exr/####.exr, exr/####.png: nerfx's renders (`--colour linear`: the scene is linear, and
  the PNG preview sRGB-encodes it, so the PNGs are what a camera would write);
- images/frame_####.png: the same pixels as opaque RGB PNGs (alpha is checked to be 255
  everywhere and dropped, so nerfstudio never composites a background into them);
- transforms.json: nerfstudio's data format (OpenGL camera-to-world `transform_matrix`, the
  pinhole intrinsics of the shot's Blender camera: square pixels, centred principal point).

Needs numpy and Pillow (both in nerfstudio's environment).
"""

import argparse
import json
import math
import subprocess
from pathlib import Path

import numpy as np
from PIL import Image

WIDTH, HEIGHT = 128, 96
LENS_MM, SENSOR_MM = 30.0, 36.0  # horizontal sensor fit (landscape, AUTO)
N_CAMERAS = 40
RADIUS = 3.6


def box(lo, hi, rgb, density=60.0):
    return {"shape": {"box": {"min": lo, "max": hi}}, "density": density, "color": {"rgb": rgb}}


def scene():
    """The analytic scene: objects within about 1.2 of the origin inside a 20 × 20 × 9 room."""
    prims = [
        # Objects.
        {"shape": {"sphere": {"center": [-0.35, 0.1, -0.3], "radius": 0.6}}, "density": 40.0,
         "color": {"sh": [[2.2, 0.8, 0.5], [0.0, 0.25, 0.25], [0.3, 0.15, 0.05],
                          [-0.3, 0.0, 0.2]]}},
        box([0.25, -0.95, -1.0], [1.05, -0.15, -0.2], [0.15, 0.35, 0.8], 30.0),
        box([0.3, 0.3, -1.0], [0.7, 0.7, 0.6], [0.85, 0.75, 0.2], 50.0),
        {"shape": {"sphere": {"center": [-0.2, -0.75, -0.7], "radius": 0.3}}, "density": 40.0,
         "color": {"rgb": [0.2, 0.7, 0.25]}},
        {"shape": {"gaussian": {"center": [0.0, 0.5, 0.7], "sigma": 0.2}}, "density": 15.0,
         "color": {"rgb": [0.9, 0.3, 0.7]}},
        # Room: walls, ceiling (sky).
        box([-10.0, 9.5, -1.0], [10.0, 10.0, 8.0], [0.7, 0.45, 0.3]),
        box([-10.0, -10.0, -1.0], [10.0, -9.5, 8.0], [0.3, 0.55, 0.35]),
        box([9.5, -9.5, -1.0], [10.0, 9.5, 8.0], [0.55, 0.5, 0.65]),
        box([-10.0, -9.5, -1.0], [-9.5, 9.5, 8.0], [0.75, 0.7, 0.55]),
        box([-10.0, -10.0, 8.0], [10.0, 10.0, 8.5], [0.45, 0.65, 0.9]),
        # Pillars between the objects and the walls.
        box([-5.2, 3.8, -1.0], [-4.4, 4.6, 4.0], [0.9, 0.9, 0.85]),
        box([4.4, -5.2, -1.0], [5.2, -4.4, 4.0], [0.25, 0.25, 0.3]),
    ]
    # Ground: a checkerboard of 2.5-unit tiles in two colours, 0.5 thick below z = -1.
    for i in range(8):
        for j in range(8):
            x0, y0 = -10.0 + 2.5 * i, -10.0 + 2.5 * j
            rgb = [0.55, 0.52, 0.48] if (i + j) % 2 == 0 else [0.2, 0.22, 0.25]
            prims.append(box([x0, y0, -1.5], [x0 + 2.5, y0 + 2.5, -1.0], rgb))
    return {"instances": [{"name": "scene", "field": {"analytic": {"primitives": prims}}}]}


def look_at(eye, target=(0.0, 0.0, -0.3), up=(0.0, 0.0, 1.0)):
    """Camera-to-world (OpenGL/Blender: the camera looks down −Z, +Y up) as a 4×4 array."""
    eye = np.asarray(eye, float)
    back = eye - np.asarray(target, float)
    back /= np.linalg.norm(back)
    right = np.cross(up, back)
    right /= np.linalg.norm(right)
    cam_up = np.cross(back, right)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = right, cam_up, back, eye
    return m


def training_cameras():
    """N cameras on a sphere of radius RADIUS: a golden-angle spiral over elevations 8°–55°."""
    golden = math.pi * (3.0 - math.sqrt(5.0))
    out = []
    for k in range(N_CAMERAS):
        elev = math.radians(8.0 + 47.0 * (k + 0.5) / N_CAMERAS)
        azim = k * golden
        eye = RADIUS * np.array([math.cos(elev) * math.cos(azim),
                                 math.cos(elev) * math.sin(azim), math.sin(elev)])
        out.append(look_at(eye))
    return out


def focal_px():
    """Blender's horizontal-fit focal length in pixels (square pixels, no shift)."""
    return LENS_MM / SENSOR_MM * WIDTH


def shot(cameras):
    ident = np.eye(4).tolist()
    return {
        "version": 1, "fps": 24, "fps_base": 1.0, "resolution_x": WIDTH, "resolution_y": HEIGHT,
        "resolution_percentage": 100, "pixel_aspect_x": 1, "pixel_aspect_y": 1,
        "nerf_object": "NeRF",
        "frames": [{"frame": k + 1,
                    "camera": {"matrix_world": c.tolist(), "type": "PERSP", "lens": LENS_MM,
                               "sensor_width": SENSOR_MM, "sensor_height": 24.0,
                               "sensor_fit": "AUTO", "clip_start": 0.01, "clip_end": 1000.0},
                    "objects": {"NeRF": ident}}
                   for k, c in enumerate(cameras)],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--nerfx", default="target/release/nerfx")
    args = ap.parse_args()
    out = args.out
    out.mkdir(parents=True, exist_ok=True)
    (out / "scene.json").write_text(json.dumps(scene(), indent=1))
    cameras = training_cameras()
    (out / "shot.json").write_text(json.dumps(shot(cameras), indent=1))
    subprocess.run([args.nerfx, "render", str(out / "scene.json"), str(out / "shot.json"),
                    "--frames", f"1-{len(cameras)}", "-o", str(out / "exr" / "####.exr"),
                    "--png", "--colour", "linear", "--quality", "final"], check=True)
    (out / "images").mkdir(exist_ok=True)
    f = focal_px()
    frames = []
    for k, c2w in enumerate(cameras):
        rgba = np.asarray(Image.open(out / "exr" / f"{k + 1:04d}.png"))
        if rgba.shape != (HEIGHT, WIDTH, 4) or rgba[..., 3].min() != 255:
            raise SystemExit(f"frame {k + 1}: expected an opaque {WIDTH}×{HEIGHT} RGBA render, "
                             f"got shape {rgba.shape}, alpha min {rgba[..., 3].min()}")
        name = f"images/frame_{k + 1:04d}.png"
        Image.fromarray(rgba[..., :3]).save(out / name)
        frames.append({"file_path": name, "transform_matrix": c2w.tolist()})
    transforms = {"camera_model": "OPENCV", "fl_x": f, "fl_y": f, "cx": WIDTH / 2,
                  "cy": HEIGHT / 2, "w": WIDTH, "h": HEIGHT,
                  "k1": 0.0, "k2": 0.0, "p1": 0.0, "p2": 0.0, "frames": frames}
    (out / "transforms.json").write_text(json.dumps(transforms, indent=1))
    print(f"{len(frames)} images, {WIDTH}×{HEIGHT}, f = {f:.3f} px → {out}/transforms.json")


if __name__ == "__main__":
    main()
