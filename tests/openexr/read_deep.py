"""Reads a deep EXR with OpenEXR's own library (its Python bindings) and flattens it, for
tests/outputs/deep_exr.rs.

    python3 read_deep.py FILE.exr OUT_DIR

Writes to OUT_DIR:
- header.json: the part's type, compression, size, deepImageState, each channel's name and
  sample type, and the header's other entries the test checks (as read_header.py writes
  them);
- counts.u32: samples per pixel, rows top to bottom, little-endian uint32;
- <channel>.f32: every pixel's samples one pixel after the other, little-endian float32;
- flat.f32: the deep pixels flattened, R G B A planes one after the other.

OpenEXR's Python bindings (3.5) refuse to open a file with a `deepImageState` attribute
("unsupported attribute type"), which nerfx writes: the file is read from a copy without that
attribute (its chunk offsets moved by the bytes removed), and the state the attribute held is
reported in header.json (3: DIS_TIDY).

Flattening follows OpenEXR's "Interpreting OpenEXR Deep Pixels": each pixel's samples sorted
by Z then ZBack are composited front to back with "over": C += (1 − A)·c, A += (1 − A)·a.
"""

import json
import os
import struct
import sys

import numpy as np
import OpenEXR

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from read_header import plain  # noqa: E402


def samples_of(pixels, h, w):
    """Per pixel (row-major) its samples as a float array (empty where none)."""
    out = []
    for y in range(h):
        for x in range(w):
            v = pixels[y, x] if pixels.ndim == 2 else pixels[y * w + x]
            out.append(np.zeros(0, np.float32) if v is None else np.asarray(v, np.float32))
    return out


def untagged(data):
    """The bytes of a single-part EXR without its deepImageState attribute, and the state it
    held (None without one). Header: magic and version (8 bytes), then attributes
    `name\\0 type\\0 size(int32) value` up to an empty name; the chunk offset table (uint64
    absolute offsets) follows."""
    at, state, cut = 8, None, None
    while data[at] != 0:
        name_end = data.index(b"\0", at)
        type_end = data.index(b"\0", name_end + 1)
        (size,) = struct.unpack_from("<i", data, type_end + 1)
        end = type_end + 5 + size
        if data[at:name_end] == b"deepImageState":
            state, cut = data[type_end + 5], (at, end)
        at = end
    table = at + 1
    if cut is None:
        return data, None
    removed = cut[1] - cut[0]
    (first,) = struct.unpack_from("<Q", data, table)
    count = (first - table) // 8
    offsets = struct.unpack_from(f"<{count}Q", data, table)
    moved = struct.pack(f"<{count}Q", *(o - removed for o in offsets))
    body = data[: cut[0]] + data[cut[1] : table] + moved + data[table + 8 * count :]
    return body, state


def main(path, out):
    with open(path, "rb") as f:
        body, state = untagged(f.read())
    copy = os.path.join(out, "untagged.exr")
    with open(copy, "wb") as f:
        f.write(body)
    with OpenEXR.File(copy, separate_channels=True) as f:
        header = f.header()
        (x0, y0), (x1, y1) = header["dataWindow"]
        w, h = int(x1 - x0 + 1), int(y1 - y0 + 1)
        facts = {
            "type": str(header.get("type")),
            "compression": header["compression"].name,
            "width": w,
            "height": h,
            "deepImageState": state,
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
                facts["entries"][key] = plain(value)
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
    os.remove(copy)
    with open(os.path.join(out, "header.json"), "w") as f:
        json.dump(facts, f)


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
