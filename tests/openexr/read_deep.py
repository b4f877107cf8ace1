"""Reads a deep EXR with OpenEXR's own library (its Python bindings) and flattens it, for
tests/deep_exr.rs.

    python3 read_deep.py FILE.exr OUT_DIR

Writes to OUT_DIR:
- header.json: the part's type, compression, size, deepImageState, each channel's name and
  sample type, and the header's other entries the test checks (as text);
- counts.u32: samples per pixel, rows top to bottom, little-endian uint32;
- <channel>.f32: every pixel's samples one pixel after the other, little-endian float32;
- flat.f32: the deep pixels flattened, R G B A planes one after the other.

Flattening follows OpenEXR's "Interpreting OpenEXR Deep Pixels": each pixel's samples sorted
by Z then ZBack are composited front to back with "over": C += (1 − A)·c, A += (1 − A)·a.
"""

import json
import os
import sys

import numpy as np
import OpenEXR


def samples_of(pixels, h, w):
    """Per pixel (row-major) its samples as a float array (empty where none)."""
    out = []
    for y in range(h):
        for x in range(w):
            v = pixels[y, x] if pixels.ndim == 2 else pixels[y * w + x]
            out.append(np.zeros(0, np.float32) if v is None else np.asarray(v, np.float32))
    return out


def main(path, out):
    with OpenEXR.File(path, separate_channels=True) as f:
        header = f.header()
        (x0, y0), (x1, y1) = header["dataWindow"]
        w, h = int(x1 - x0 + 1), int(y1 - y0 + 1)
        facts = {
            "type": str(header.get("type")),
            "compression": header["compression"].name,
            "width": w,
            "height": h,
            "deepImageState": str(header.get("deepImageState")),
            "channels": [],
            "entries": {},
        }
        for key, value in header.items():
            if key.startswith("nerfx/") or key in (
                "software",
                "chromaticities",
                "worldToCamera",
                "worldToNDC",
                "framesPerSecond",
                "pixelAspectRatio",
            ):
                facts["entries"][key] = str(value)
        per_channel = {}
        for name, channel in f.channels().items():
            pixels = channel.pixels
            samples = samples_of(pixels, h, w)
            kinds = {s.dtype.name for s in samples if len(s)}
            raw = [np.asarray(pixels[y, x]) for y in range(h) for x in range(w)
                   if pixels[y, x] is not None and len(pixels[y, x])]
            facts["channels"].append(
                {"name": name, "type": (raw[0].dtype.name if raw else "float32")}
            )
            per_channel[name] = samples
        counts = np.array([len(s) for s in per_channel["A"]], np.uint32)
        counts.astype("<u4").tofile(os.path.join(out, "counts.u32"))
        for name, samples in per_channel.items():
            joined = np.concatenate(samples) if samples else np.zeros(0, np.float32)
            joined.astype("<f4").tofile(os.path.join(out, name + ".f32"))
        flat = np.zeros((4, h * w), np.float64)
        for p in range(h * w):
            z = per_channel["Z"][p].astype(np.float64)
            zb = per_channel["ZBack"][p].astype(np.float64)
            order = np.lexsort((zb, z))
            acc = np.zeros(4)
            for i in order:
                a = float(per_channel["A"][p][i])
                c = [float(per_channel[k][p][i]) for k in ("R", "G", "B")] + [a]
                acc += (1.0 - acc[3]) * np.array(c)
            flat[:, p] = acc
        flat.astype("<f4").tofile(os.path.join(out, "flat.f32"))
    with open(os.path.join(out, "header.json"), "w") as f:
        json.dump(facts, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
