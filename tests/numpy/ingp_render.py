"""Marches rays through an instant-ngp snapshot with NumPy: the field from
ingp_reference.py, the compositing written out on its own.

Usage: ingp_render.py <snapshot> <rays.bin> <out.bin>. rays.bin holds little-endian float32
rows of 6, two per ray: (origin xyz, unit direction xyz) in the field's frame (NeRF world),
then (step, field units per world unit k, sample count n, 0, 0, 0). Sample j (< n) lies at
world distance (j + 1/2)·step past the ray's entry, field point origin + dir·((j + 1/2)·step·k).
With σ_j in world units (σ_field·k), α_j = 1 − exp(−σ_j·step), T_j = Π_{i<j} (1 − α_i):
colour Σ T_j α_j c_j (premultiplied), alpha 1 − Π (1 − α_j). The colours are composited in
the space the snapshot was trained in; an sRGB-trained snapshot's composite is then converted
to linear (unpremultiplied, decoded by the sRGB standard's curve, premultiplied again), as the
trainer's viewer shows it. Output: float32 r g b a per ray.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ingp_reference import field  # noqa: E402

F32 = np.float32


def main():
    snap_path, rays_path, out_path = sys.argv[1:4]
    evaluate = field(snap_path)
    rows = np.fromfile(rays_path, dtype="<f4").reshape(-1, 2, 6)
    out = []
    for ray in rows:
        origin, direction = ray[0, :3].astype(F32), ray[0, 3:].astype(F32)
        step, k, n = float(ray[1, 0]), F32(ray[1, 1]), int(ray[1, 2])
        if n == 0:
            out.append([0.0, 0.0, 0.0, 0.0])
            continue
        along = ((np.arange(n, dtype=np.float64) + 0.5) * step).astype(F32) * k
        pts = (origin[None, :] + direction[None, :] * along[:, None]).astype(F32)
        dirs = np.repeat(direction[None, :], n, axis=0)
        sigma, rgb = evaluate(pts, dirs)
        sigma_world = sigma.astype(np.float64) * float(k)
        alpha = 1.0 - np.exp(-sigma_world * step)
        transmittance = np.concatenate([[1.0], np.cumprod(1.0 - alpha)[:-1]])
        weight = transmittance * alpha
        colour = (weight[:, None] * rgb.astype(np.float64)).sum(axis=0)
        acc = 1.0 - np.prod(1.0 - alpha)
        if not evaluate.is_hdr and acc > 0.0:
            straight = np.clip(colour / acc, 0.0, 1.0)
            colour = acc * np.where(straight <= 0.04045, straight / 12.92,
                                    ((straight + 0.055) / 1.055) ** 2.4)
        out.append([colour[0], colour[1], colour[2], acc])
    np.asarray(out, dtype="<f4").tofile(out_path)


if __name__ == "__main__":
    main()
