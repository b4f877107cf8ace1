"""A Cryptomatte decoder written from the specification (Psyop, Cryptomatte 1.2), reading
with OpenEXR's own library and hashing with mmh3, for tests/outputs/cryptomatte.rs.

    python3 decode.py FILE.exr LAYER

Checks the header entries of LAYER (key: the first 7 hex digits of MurmurHash3_32 of the
layer name; hash, conversion, manifest), that each manifest ID is the name's MurmurHash3_32
with the exponent fix (an exponent of 0 or 255 has its lowest bit flipped), and that every
pixel's ranks are in order of coverage. Prints JSON: "errors" (a list, empty when all is
well), "names", and each name's coverage per pixel (row by row) under "coverage".
"""

import json
import struct
import sys

import mmh3
import numpy as np
import OpenEXR


def spec_id(name):
    h = mmh3.hash(name.encode("utf-8"), seed=0, signed=False)
    exponent = (h >> 23) & 255
    if exponent == 0 or exponent == 255:
        h ^= 1 << 23
    return h


def main(path, layer):
    errors = []
    with OpenEXR.File(path) as f:
        header = dict(f.header())
    key = "%08x" % mmh3.hash(layer.encode("utf-8"), seed=0, signed=False)
    prefix = "cryptomatte/%s/" % key[:7]
    get = lambda k: header.get(prefix + k)
    if get("name") != layer:
        errors.append("no %sname = %s (keys: %s)" % (prefix, layer, sorted(header)))
    if get("hash") != "MurmurHash3_32":
        errors.append("hash is %r" % get("hash"))
    if get("conversion") != "uint32_to_float32":
        errors.append("conversion is %r" % get("conversion"))
    manifest = json.loads(get("manifest") or "{}")
    by_bits = {}
    for name, hex_id in manifest.items():
        if int(hex_id, 16) != spec_id(name):
            errors.append("manifest %s: %s, the specification gives %08x" % (name, hex_id, spec_id(name)))
        by_bits[int(hex_id, 16)] = name
    with OpenEXR.File(path, separate_channels=True) as f:
        channels = {n: np.asarray(c.pixels, dtype=np.float32) for n, c in f.channels().items()}
    ranks = []
    level = 0
    while "%s%02d.R" % (layer, level) in channels:
        base = "%s%02d." % (layer, level)
        ranks.append((channels[base + "R"], channels[base + "G"]))
        ranks.append((channels[base + "B"], channels[base + "A"]))
        level += 1
    if not ranks:
        errors.append("no %s00 layer" % layer)
        print(json.dumps({"errors": errors}))
        return
    shape = ranks[0][0].shape
    coverage = {name: np.zeros(shape, dtype=np.float64) for name in manifest}
    previous = np.full(shape, np.inf)
    for ids, cov in ranks:
        if np.any(cov > previous + 1e-7):
            errors.append("ranks out of order of coverage")
        previous = cov
        bits = ids.view(np.uint32)
        for (y, x) in zip(*np.nonzero(cov)):
            name = by_bits.get(int(bits[y, x]))
            if name is None:
                errors.append("pixel (%d, %d): ID %08x not in the manifest" % (x, y, bits[y, x]))
                continue
            coverage[name][y, x] += float(cov[y, x])
    print(json.dumps({
        "errors": errors[:20],
        "names": sorted(manifest),
        "coverage": {n: c.ravel().tolist() for n, c in coverage.items()},
    }))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
