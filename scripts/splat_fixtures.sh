#!/usr/bin/env bash
# Regenerates the compact-splat fixtures in tests/data/splats/ (about 0.8 MB in all).
#
# Needs Python 3 with NumPy and PlayCanvas's splat-transform from npm
# (`npm i -g @playcanvas/splat-transform@2.7.1`): an encoder and decoder written by another
# project, so the tests compare nerfx's readers with a decoding nobody here wrote.
#
# - subset_sh3.ply: the 512 splats of tests/data/splat_plane_sh3.ply nearest its densest
#   point (INRIA layout, SH degree 3), the source of the encodings below;
# - subset_sh3.{compressed.ply,sog,spz,v3.spz}: splat-transform's encodings of it (SPZ in
#   versions 4 and 3);
# - *.decoded.ply (FILE.decoded.ply): splat-transform's decoding of each encoding back to an INRIA PLY;
# - sjeongab_512.splat, guitar_512.compressed.ply: the first 512 splats of the real captures
#   in /work/shared/data (an antimatter15 .splat and a SuperSplat compressed PLY written by
#   their apps), with their splat-transform decodings.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
shared="${NERFX_SHARED_DATA:-$root/../shared/data}"
out="$root/tests/data/splats"
mkdir -p "$out"
python3 - "$root/tests/data/splat_plane_sh3.ply" "$shared" "$out" <<'PY'
import sys, numpy as np
src, shared, out = sys.argv[1:]

def read_ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode()
    names, count = [], 0
    for line in header.splitlines():
        w = line.split()
        if w[:2] == ["element", "vertex"]:
            count = int(w[2])
        elif w[:1] == ["property"]:
            names.append(w[2])
    dt = np.dtype([(n, "<f4") for n in names])
    return np.frombuffer(data, dt, count, end)

def write_ply(path, table):
    names = table.dtype.names
    head = "ply\nformat binary_little_endian 1.0\nelement vertex %d\n" % len(table)
    head += "".join("property float %s\n" % n for n in names) + "end_header\n"
    open(path, "wb").write(head.encode() + table.tobytes())

t = read_ply(src)
keep = [n for n in t.dtype.names if n not in ("nx", "ny", "nz")]
xyz = np.stack([t["x"], t["y"], t["z"]], 1).astype(np.float64)
opaque = t["opacity"] > 0
centre = np.median(xyz[opaque], 0)
order = np.argsort(((xyz - centre) ** 2).sum(1))[:512]
sub = np.sort(order)
table = np.empty(512, np.dtype([(n, "<f4") for n in keep]))
for n in keep:
    table[n] = t[n][sub]
write_ply(out + "/subset_sh3.ply", table)

# The first 512 records of the real .splat.
open(out + "/sjeongab_512.splat", "wb").write(open(shared + "/object_sjeongab.splat", "rb").read()[: 512 * 32])

# The first two chunks (512 splats) of the real compressed PLY.
data = open(shared + "/guitar.compressed.ply", "rb").read()
end = data.index(b"end_header\n") + len(b"end_header\n")
lines = data[:end].decode().splitlines(True)
sizes = {"float": 4, "uint": 4, "uchar": 1}
elements = []
for line in lines:
    w = line.split()
    if w[:1] == ["element"]:
        elements.append([w[1], int(w[2]), 0])
    elif w[:1] == ["property"]:
        elements[-1][2] += sizes[w[1]]
want = {"chunk": 2, "vertex": 512, "sh": 512}
body, at = b"", end
for name, count, size in elements:
    body += data[at : at + want[name] * size]
    at += count * size
head = "".join(
    ("element %s %d\n" % (line.split()[1], want[line.split()[1]])) if line.startswith("element") else line
    for line in lines
)
open(out + "/guitar_512.compressed.ply", "wb").write(head.encode() + body)
PY
cd "$out"
st() { splat-transform -q -w "$@"; }
st subset_sh3.ply subset_sh3.compressed.ply
st -g cpu subset_sh3.ply subset_sh3.sog
st subset_sh3.ply subset_sh3.spz
st subset_sh3.ply --spz-version 3 subset_sh3.v3.spz
for f in subset_sh3.compressed.ply subset_sh3.sog subset_sh3.spz subset_sh3.v3.spz \
         sjeongab_512.splat guitar_512.compressed.ply; do
    st "$f" "$f.decoded.ply"
done
ls -l "$out"
