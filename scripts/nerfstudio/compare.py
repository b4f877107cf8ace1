"""Compares nerfx's render of a nerfacto run with nerfstudio's, and both with the truth.

    python compare.py FIXTURE [--nerfx target/release/nerfx] [--quality final]
                              [--sampler proposal|occupancy]

FIXTURE is tests/data/nerfstudio/: run/, camera_path.json, truth_shot.json, scene.json (the
analytic scene the run was trained on, in the dataset's frame) and render/ (render.py's
output). nerfx renders, into a temporary folder (the run is copied there first: nerfx caches
an occupancy grid beside a run),
- the run through the camera path, scene `{"instances": [{"field": {"nerfacto": …},
  "object": "NeRF"}]}`, `--colour as-trained`: the composite in the trained (sRGB-encoded)
  space over black, what nerfstudio's rgb with a black background is;
- the analytic scene through truth_shot.json (the same cameras in the dataset's frame),
  `--colour linear`, sRGB-encoded here (its alpha is 1): what the training images hold.
Depths: nerfx's `depth.ray` (expected) and `depth.median` against nerfstudio's
expected_depth and depth (median), in the normalised frame; the truth's depths are scaled by
the dataparser scale. nerfx's median crosses half of the pixel's accumulation, nerfstudio's
crosses 0.5, so medians are compared where both accumulations exceed 0.99.
"""

import argparse
import json
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import OpenEXR


def read_exr(path):
    ch = OpenEXR.File(str(path), separate_channels=True).channels()
    return {k: v.pixels.astype(np.float64) for k, v in ch.items()}


def srgb_encode(x):
    x = np.clip(x, 0.0, None)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def psnr(a, b):
    mse = np.mean((np.clip(a, 0, 1) - np.clip(b, 0, 1)) ** 2)
    return 10 * np.log10(1.0 / mse) if mse > 0 else float("inf")


def stat(d):
    """Mean (median) of absolute differences, or n/a when no pixel qualifies."""
    return f"{d.mean():.4f} ({np.median(d):.4f})" if d.size else "n/a"


def render(nerfx, scene, shot, out, colour, quality):
    subprocess.run([nerfx, "render", str(scene), str(shot), "-o", str(out / "f.####.exr"),
                    "--colour", colour, "--quality", quality], check=True,
                   stdout=subprocess.DEVNULL)
    return [read_exr(p) for p in sorted(out.glob("f.*.exr"))]


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fixture", type=Path)
    ap.add_argument("--nerfx", default="target/release/nerfx")
    ap.add_argument("--quality", default="final", help="nerfx's preset for the run")
    ap.add_argument("--sampler", default="proposal", choices=["proposal", "occupancy"],
                    help="how nerfx samples the run: nerfacto's proposal networks, or its own "
                    "occupancy marcher")
    args = ap.parse_args()
    fx = args.fixture
    scale = json.loads((fx / "run" / "dataparser_transforms.json").read_text())["scale"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        shutil.copytree(fx / "run", tmp / "run")
        field = {"nerfacto": {"path": "run", "sampler": args.sampler}}
        scene = {"instances": [{"name": "run", "field": field, "object": "NeRF"}]}
        (tmp / "scene.json").write_text(json.dumps(scene))
        (tmp / "nerfx").mkdir()
        (tmp / "truth").mkdir()
        ours = render(args.nerfx, tmp / "scene.json", fx / "camera_path.json", tmp / "nerfx",
                      "as-trained", args.quality)
        truth = render(args.nerfx, fx / "scene.json", fx / "truth_shot.json", tmp / "truth",
                       "linear", "final")
    print("camera | nerfstudio: mean acc, rgb range, depth (median) range | PSNR ns–truth, "
          "nerfx–truth, nerfx–ns | mean |Δacc| | expected depth |Δ| mean (median) | "
          "median depth |Δ| mean (median) | ns expected depth − truth |Δ| mean (median)")
    for k, (o, t) in enumerate(zip(ours, truth)):
        ns = {n: np.load(fx / "render" / f"cam{k}_{n}.npy").astype(np.float64)
              for n in ("rgb", "accumulation", "depth_median", "depth_expected")}
        o_rgb = np.stack([o["R"], o["G"], o["B"]], -1)
        t_rgb = srgb_encode(np.stack([t["R"], t["G"], t["B"]], -1))
        acc = ns["accumulation"]
        both = (acc > 0.99) & (o["A"] > 0.99)
        d_exp = np.abs(o["depth.ray"] - ns["depth_expected"])[both]
        d_med = np.abs(o["depth.median"] - ns["depth_median"])[both]
        t_exp = np.abs(ns["depth_expected"] - scale * t["depth.ray"])[acc > 0.99]
        print(f"{k} | {acc.mean():.4f}, {ns['rgb'].min():.4f}..{ns['rgb'].max():.4f}, "
              f"{ns['depth_median'].min():.4f}..{ns['depth_median'].max():.4f} | "
              f"{psnr(ns['rgb'], t_rgb):.2f}, {psnr(o_rgb, t_rgb):.2f}, "
              f"{psnr(o_rgb, ns['rgb']):.2f} dB | {np.abs(o['A'] - acc).mean():.4f} | "
              f"{stat(d_exp)} | {stat(d_med)} | {stat(t_exp)} "
              f"[{both.sum()} of {acc.size} px both > 0.99; nerfx mean acc {o['A'].mean():.4f}]")


if __name__ == "__main__":
    main()
