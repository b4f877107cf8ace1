"""Marches rays through a nerfstudio nerfacto run with NumPy, out to its far plane: the field
of nerfacto_reference.py, the sampling and compositing written out on their own.

Usage: nerfacto_render.py <run> <rays.bin> <out.bin>. rays.bin holds little-endian float32
rows of 6, two per ray: (origin xyz, unit direction xyz) in nerfstudio's normalised frame,
then (n, 0, 0, 0, 0, 0): the number of samples.

Each ray is integrated from its origin to `far_plane` (config.yml; nerfacto's default 1000),
a distance along it: nerfstudio's NearFarCollider starts rays at 0 at inference (its
`near_plane` applies in training). The samples are uniform in
s(t) = t (t < 1), 2 − 1/t (t >= 1): nerfstudio's spacing for unbounded scenes, uniform in
distance to 1 and in disparity beyond, which for a ray from near the centre is uniform in
the contracted coordinates where the field's detail lies. n bins of equal width in s; the
sample of a bin at its midpoint in s; δ its length in t. α = 1 − exp(−σδ),
T = Π(1 − α); colour Σ T α c (premultiplied, in the sRGB-encoded space the field was trained
in, not converted), alpha 1 − Π(1 − α), expected depth Σ T α t / alpha.
Output: float32 rows (r, g, b, alpha) then (depth, 0, 0, 0), per ray.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from nerfacto_reference import field  # noqa: E402

F32 = np.float32


def s_of_t(t):
    return np.where(t < 1.0, t, 2.0 - 1.0 / np.maximum(t, 1.0))


def t_of_s(s):
    return np.where(s < 1.0, s, 1.0 / np.maximum(2.0 - s, 1e-300))


def main():
    run, rays_path, out_path = sys.argv[1:4]
    evaluate = field(run)
    near, far = 0.0, float(evaluate.cfg["far_plane"])
    rows = np.fromfile(rays_path, dtype="<f4").reshape(-1, 2, 6)
    out = []
    for ray in rows:
        origin = ray[0, :3].astype(np.float64)
        direction = ray[0, 3:].astype(np.float64)
        n = int(ray[1, 0])
        edges = t_of_s(np.linspace(s_of_t(near), s_of_t(far), n + 1))
        edges[0], edges[-1] = near, far
        mids = t_of_s(0.5 * (s_of_t(edges[:-1]) + s_of_t(edges[1:])))
        delta = np.diff(edges)
        pts = (origin[None, :] + direction[None, :] * mids[:, None]).astype(F32)
        dirs = np.repeat(direction[None, :].astype(F32), n, axis=0)
        # Nothing beyond the far plane's cube.
        inside = np.max(np.abs(pts), axis=1) <= far
        sigma, rgb = evaluate(pts, dirs)
        sigma = np.where(inside, sigma.astype(np.float64), 0.0)
        alpha = 1.0 - np.exp(-sigma * delta)
        transmittance = np.concatenate([[1.0], np.cumprod(1.0 - alpha)[:-1]])
        weight = transmittance * alpha
        colour = (weight[:, None] * rgb.astype(np.float64)).sum(axis=0)
        acc = weight.sum()
        depth = (weight * mids).sum() / acc if acc > 0 else 0.0
        out.append([colour[0], colour[1], colour[2], acc])
        out.append([depth, 0.0, 0.0, 0.0])
    np.asarray(out, dtype="<f4").tofile(out_path)


if __name__ == "__main__":
    main()
