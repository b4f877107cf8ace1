"""Reads an EXR with OpenEXR's own library (its Python bindings), for tests/outputs/exr_openexr.rs.

    python3 read_channels.py FILE.exr OUT_DIR

Writes OUT_DIR/header.json (compression, size, pixel aspect, each channel's name and sample
type) and each channel's samples as little-endian float32, rows top to bottom, to
OUT_DIR/<channel>.f32. Samples stored in another type are written as read, and their type is
named in the header, so that the test can refuse them.
"""

import json
import os
import sys

import numpy as np
import OpenEXR


def main(path, out):
    with OpenEXR.File(path, separate_channels=True) as f:
        header = f.header()
        (x0, y0), (x1, y1) = header["dataWindow"]
        facts = {
            "compression": header["compression"].name,
            "width": int(x1 - x0 + 1),
            "height": int(y1 - y0 + 1),
            "pixel_aspect": float(header["pixelAspectRatio"]),
            "channels": [],
        }
        for name, channel in f.channels().items():
            pixels = np.asarray(channel.pixels)
            facts["channels"].append({"name": name, "type": str(pixels.dtype)})
            pixels.astype(pixels.dtype.newbyteorder("<")).tofile(os.path.join(out, name + ".f32"))
    with open(os.path.join(out, "header.json"), "w") as f:
        json.dump(facts, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
