#!/usr/bin/env bash
# The splat benchmark in every format nerfx reads: a generated capture-like scene of N splats
# (SH degree 3) written as an INRIA PLY by `nerfx bench`, converted to SuperSplat's compressed
# PLY, SPZ and SOG by PlayCanvas's splat-transform (npm, another project's encoder) and to
# antimatter15's .splat by a few lines of NumPy written from its layout, then each file loaded
# and rendered by `nerfx bench` (load time, decoded size, heap, frame stages).
#
#   scripts/splat_bench.sh 1000000 [OUT]     # OUT defaults to bench-out/splats
#
# Needs `splat-transform` (npm install -g @playcanvas/splat-transform) and python3 with NumPy.
set -euo pipefail
cd "$(dirname "$0")/.."
n=${1:?usage: scripts/splat_bench.sh N [OUT]}
out=${2:-bench-out/splats}
mkdir -p "$out"
cargo build --release --quiet
nerfx=target/release/nerfx
ply="$out/generated_$n.ply"
if [ ! -f "$ply" ]; then
    # A small frame: this run only writes the PLY.
    "$nerfx" bench --splats "$n" --width 64 --height 36 --repeats 1 -o "$out" >/dev/null
fi
base="$out/generated_$n"
for ext in compressed.ply spz sog; do
    [ -f "$base.$ext" ] || splat-transform -w "$ply" "$base.$ext" >/dev/null
done
[ -f "$base.splat" ] || python3 - "$ply" "$base.splat" <<'PY'
import sys
import numpy as np

src, dst = sys.argv[1:]
with open(src, "rb") as f:
    names, count = [], 0
    while (line := f.readline().decode().strip()) != "end_header":
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
        elif words[0] == "property":
            names.append(words[-1])
    rows = np.frombuffer(f.read(count * 4 * len(names)), "<f4").reshape(count, len(names))
col = {name: rows[:, i] for i, name in enumerate(names)}
out = np.zeros((count, 32), np.uint8)
position = np.stack([col[k] for k in ("x", "y", "z")], 1).astype("<f4")
scale = np.exp(np.stack([col[f"scale_{i}"] for i in range(3)], 1)).astype("<f4")
# Colour: the SH degree-0 term as sRGB-encoded bytes; alpha: the opacity's sigmoid.
dc = np.stack([col[f"f_dc_{i}"] for i in range(3)], 1)
rgb = np.clip((0.5 + 0.28209479177387814 * dc) * 255, 0, 255)
alpha = np.clip(255 / (1 + np.exp(-col["opacity"])), 0, 255)
q = np.stack([col[f"rot_{i}"] for i in range(4)], 1)
q = q / np.linalg.norm(q, axis=1, keepdims=True)
out[:, 0:12] = position.view(np.uint8).reshape(count, 12)
out[:, 12:24] = scale.view(np.uint8).reshape(count, 12)
out[:, 24:27] = rgb.round().astype(np.uint8)
out[:, 27] = alpha.round().astype(np.uint8)
out[:, 28:32] = np.clip(q * 128 + 128, 0, 255).round().astype(np.uint8)
out.tofile(dst)
PY
"$nerfx" bench --splats "$n" --ply "$base.compressed.ply" --ply "$base.spz" --ply "$base.sog" \
    --ply "$base.splat" -o "$out"
