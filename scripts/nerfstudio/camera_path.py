"""Writes the evaluation cameras: a nerfstudio camera_path.json and the same cameras as a shot.

    python camera_path.py RUN OUT

RUN is a trained run (its dataparser_transforms.json maps the dataset's frame into
nerfstudio's normalised frame: `x_ns = scale · (T · x + t)`, camera rotations `T₃ₓ₃ · R`).
OUT receives
- camera_path.json: 3 cameras in nerfstudio's normalised frame, as the viewer writes a path
  (`camera_to_world` 16 floats row-major, `fov` the vertical field of view in degrees,
  96×72), none of them a training view;
- truth_shot.json: the same cameras in the dataset's frame as a nerfx shot (frames 1–3), for
  rendering the analytic scene the run was trained on (make_dataset.py's scene.json).
"""

import argparse
import json
import math
from pathlib import Path

import numpy as np

from make_dataset import LENS_MM, SENSOR_MM, look_at

WIDTH, HEIGHT = 96, 72

# (azimuth °, elevation °, distance, look-at point) in the dataset's frame.
CAMERAS = [
    (200.0, 15.0, 3.6, (0.0, 0.0, -0.3)),  # between training views, walls behind
    (70.0, 35.0, 3.0, (0.0, 0.0, -0.3)),  # closer than any training view
    (315.0, 6.0, 4.0, (0.0, 0.0, 0.6)),  # farther and looking up: walls and sky
]


def data_frame_cameras():
    out = []
    for azim, elev, dist, target in CAMERAS:
        a, e = math.radians(azim), math.radians(elev)
        eye = dist * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        out.append(look_at(eye, target))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args()
    dp = json.loads((args.run / "dataparser_transforms.json").read_text())
    t = np.eye(4)
    t[:3, :] = np.array(dp["transform"])
    scale = float(dp["scale"])
    cams = data_frame_cameras()
    f = LENS_MM / SENSOR_MM * WIDTH  # the shot's horizontal-fit focal length in pixels
    fov = math.degrees(2.0 * math.atan(HEIGHT / 2 / f))
    path = []
    for c in cams:
        ns = t @ c
        ns[:3, 3] *= scale
        path.append({"camera_to_world": ns.reshape(-1).tolist(), "fov": fov,
                     "aspect": WIDTH / HEIGHT})
    camera_path = {"camera_type": "perspective", "render_height": HEIGHT,
                   "render_width": WIDTH, "camera_path": path, "fps": 1, "seconds": len(path),
                   "smoothness_value": 0, "is_cycle": False, "crop": None}
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "camera_path.json").write_text(json.dumps(camera_path, indent=1))
    ident = np.eye(4).tolist()
    shot = {"version": 1, "fps": 1, "resolution_x": WIDTH, "resolution_y": HEIGHT,
            "nerf_object": "NeRF",
            "frames": [{"frame": k + 1,
                        "camera": {"matrix_world": c.tolist(), "type": "PERSP",
                                   "lens": LENS_MM, "sensor_width": SENSOR_MM,
                                   "sensor_height": 24.0, "sensor_fit": "AUTO",
                                   "clip_start": 0.01, "clip_end": 1000.0},
                        "objects": {"NeRF": ident}} for k, c in enumerate(cams)]}
    (args.out / "truth_shot.json").write_text(json.dumps(shot, indent=1))
    print(f"{len(path)} cameras, {WIDTH}×{HEIGHT}, vertical fov {fov:.4f}° → {args.out}")


if __name__ == "__main__":
    main()
