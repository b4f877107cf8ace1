"""instant-ngp's inference marcher in NumPy, written from instant-ngp's conventions
(nerf_device.cuh: stepping space, calc_dt, mip_from_pos, cascaded_grid_idx_at,
distance_to_next_voxel, advance_to_next_voxel, if_unoccupied_advance_to_next_occupied_voxel;
testbed_nerf.cu: grid_to_bitfield, bitfield_max_pool; render_nerf.cuh: compositing and the
early stop). The field itself is ingp_reference.py's.

Usage: ingp_marcher_reference.py <snapshot> <rays.bin> <out.bin> [max_steps]

rays.bin: float64 rows (ox, oy, oz, dx, dy, dz, near, far): rays in the field's frame (NeRF
world), unit directions, the span inside the field's box in field units from the origin.
out.bin: float64 rows (r, g, b, a, depth, samples, t_first, t_last): the composite in the
trained space (premultiplied), its expected depth (field units from the origin, weights
renormalised as the colour), the samples the march took, and the first and last composited
sample positions.
"""
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from ingp_reference import field, load  # noqa: E402

SQRT3 = np.sqrt(3.0)
STEP_MIN = SQRT3 / 1024.0            # STEPSIZE(): NERF_STEPS = 1024 steps per sqrt(3)
STEP_MAX = STEP_MIN * 128 * 1024 / 128  # MAX_CONE_STEPSIZE(): a cell of cascade 7, sqrt(3)
MAX_DEPTH = 16384.0
MIN_TRANSMITTANCE = 0.01
GRID = 128


def marching_grids(snap):
    """Per cascade a boolean [z, y, x] grid: value > min(0.01, mean of max(v, 0) over cascade
    0), then each cascade's central half OR-ed with the 2x2x2 max of the one inside it."""
    values = np.frombuffer(snap["density_grid_binary"], dtype="<f2").astype(np.float32)
    n3 = GRID ** 3
    n = len(values) // n3
    thr = np.float32(min(0.01, float(np.mean(np.maximum(values[:n3].astype(np.float64), 0)))))
    r = np.arange(GRID)
    z, y, x = np.meshgrid(r, r, r, indexing="ij")
    code = np.zeros_like(x)
    for k in range(7):
        code |= ((x >> k) & 1) << (3 * k) | ((y >> k) & 1) << (3 * k + 1) | ((z >> k) & 1) << (3 * k + 2)
    grids = np.stack([values[c * n3:(c + 1) * n3][code] > thr for c in range(n)])
    for c in range(1, n):
        h = GRID // 2
        pooled = grids[c - 1].reshape(h, 2, h, 2, h, 2).any(axis=(1, 3, 5))
        q = GRID // 4
        grids[c, q:q + h, q:q + h, q:q + h] |= pooled
    return grids


class Steps:
    """Stepping space: n(t) linear in t (finest step) near the camera, logarithmic (steps
    t*cone) in between, linear again (sqrt(3) steps) far away."""

    def __init__(self, cone):
        self.cone = cone
        if cone > 1e-5:
            self.l = np.log1p(cone)
            self.a = (np.log(STEP_MIN) - np.log(self.l)) / self.l
            self.b = (np.log(STEP_MAX) - np.log(self.l)) / self.l
            self.ta = np.exp(self.a * self.l)
            self.tb = np.exp(self.b * self.l)

    def n(self, t):
        if self.cone <= 1e-5:
            return t / STEP_MIN
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(t <= self.ta, (t - self.ta) / STEP_MIN + self.a,
                            np.where(t <= self.tb, np.log(t) / self.l,
                                     (t - self.tb) / STEP_MAX + self.b))

    def t(self, n):
        if self.cone <= 1e-5:
            return n * STEP_MIN
        with np.errstate(over="ignore"):
            return np.where(n <= self.a, (n - self.a) * STEP_MIN + self.ta,
                            np.where(n <= self.b, np.exp(n * self.l),
                                     (n - self.b) * STEP_MAX + self.tb))

    def dt(self, t):
        return self.t(self.n(t) + 1.0) - t


def occupied(grids, pos, mip):
    u = ((pos - 0.5) * np.exp2(-mip.astype(np.float64))[:, None] + 0.5) * GRID
    i = np.trunc(u)
    ok = np.all((i >= 0) & (i < GRID), axis=1) & (mip < len(grids))
    i = np.where(ok[:, None], i, 0).astype(np.int64)
    m = np.minimum(mip, len(grids) - 1)
    return ok & grids[m, i[:, 2], i[:, 1], i[:, 0]]


def march(grids, steps, origin, direction, near, far, max_steps):
    """All rays at once; returns per-ray lists of (t, dt) in instant-ngp units."""
    n_rays = len(origin)
    max_mip = len(grids) - 1
    t = np.maximum(near, 0.0) + 1e-6
    alive = t <= far
    taken = np.zeros(n_rays, dtype=np.int64)
    samples = [[] for _ in range(n_rays)]
    with np.errstate(divide="ignore"):
        inv = 1.0 / direction
    while alive.any():
        idx = np.nonzero(alive)[0]
        tt = t[idx]
        pos = origin[idx] + direction[idx] * tt[:, None]
        gone = (tt >= MAX_DEPTH) | (tt > far[idx]) | (taken[idx] >= max_steps)
        _, e = np.frexp(np.max(np.abs(pos - 0.5), axis=1))
        mip = np.clip(e + 1, 0, max_mip)
        occ = occupied(grids, pos, mip) & ~gone
        empty = ~occ & ~gone
        # An occupied cell: a sample, one step.
        dt = steps.dt(tt)
        for k in np.nonzero(occ)[0]:
            samples[idx[k]].append((tt[k], dt[k]))
        taken[idx[occ]] += 1
        new_t = np.where(occ, tt + dt, tt)
        # An empty one: the coarsest empty cell around, a whole number of steps past it.
        if empty.any():
            e_idx = np.nonzero(empty)[0]
            p, m = pos[e_idx], mip[e_idx].copy()
            while True:
                up = (m < max_mip)
                up[up] = ~occupied(grids, p[up], m[up] + 1)
                if not up.any():
                    break
                m[up] += 1
            res = GRID / np.exp2(m.astype(np.float64))
            q = res[:, None] * (p - 0.5)
            d = direction[idx[e_idx]]
            with np.errstate(invalid="ignore"):
                planes = (np.floor(q + 0.5 + 0.5 * np.sign(d)) - q) * inv[idx[e_idx]]
            planes = np.where(d == 0.0, np.inf, planes)
            dist = np.maximum(planes.min(axis=1) / res, 0.0)
            n0, n1 = steps.n(tt[e_idx]), steps.n(tt[e_idx] + dist)
            new_t[e_idx] = steps.t(n0 + np.ceil(np.maximum(n1 - n0, 0.5)))
        t[idx] = new_t
        alive[idx[gone]] = False
    return samples, taken


def main():
    snap_path, rays_path, out_path = sys.argv[1:4]
    max_steps = int(sys.argv[4]) if len(sys.argv) > 4 else 10000
    doc = load(snap_path)
    snap = doc["snapshot"]
    nerf = snap["nerf"]
    ds = nerf.get("dataset", {})
    s = float(np.float32(ds.get("scale", 0.33)))
    o = np.array(ds.get("offset", [0.5, 0.5, 0.5]), dtype=np.float32).astype(np.float64)
    cone = 0.0 if float(nerf["aabb_scale"]) <= 1 else 1.0 / 256.0
    grids = marching_grids(snap)
    evaluate = field(snap_path)

    rays = np.fromfile(rays_path, dtype="<f8").reshape(-1, 8)
    of, df = rays[:, 0:3], rays[:, 3:6]
    # NeRF world -> instant-ngp: scale, offset, axes cycled (x, y, z) <- (y, z, x).
    origin = np.stack([of[:, 1] * s + o[1], of[:, 2] * s + o[2], of[:, 0] * s + o[0]], axis=1)
    direction = np.stack([df[:, 1], df[:, 2], df[:, 0]], axis=1)
    samples, taken = march(grids, Steps(cone), origin, direction, rays[:, 6] * s,
                           rays[:, 7] * s, max_steps)

    owner = np.concatenate([np.full(len(x), i) for i, x in enumerate(samples)] + [np.zeros(0, int)])
    flat = np.array([p for x in samples for p in x], dtype=np.float64).reshape(-1, 2)
    t_field = flat[:, 0] / s
    pts = (of[owner] + df[owner] * t_field[:, None]).astype(np.float32)
    sigma = np.zeros(len(flat), dtype=np.float32)
    rgb = np.zeros((len(flat), 3), dtype=np.float32)
    for a in range(0, len(flat), 65536):
        b = a + 65536
        sigma[a:b], rgb[a:b] = evaluate(pts[a:b], df[owner[a:b]].astype(np.float32), masked=False)
    # alpha = 1 - exp(-sigma_ngp dt_ngp); the field's sigma is per field unit (s times ngp's).
    alpha = 1.0 - np.exp(-(sigma.astype(np.float64) / s) * flat[:, 1])

    out = np.zeros((len(rays), 8))
    start = 0
    for i, x in enumerate(samples):
        a_i = alpha[start:start + len(x)]
        c_i = rgb[start:start + len(x)].astype(np.float64)
        t_i = t_field[start:start + len(x)]
        start += len(x)
        colour, acc, depth, last = np.zeros(3), 0.0, 0.0, -1
        for j in range(len(x)):
            w = a_i[j] * (1.0 - acc)
            colour += w * c_i[j]
            depth += w * t_i[j]
            acc += w
            last = j
            if acc > 1.0 - MIN_TRANSMITTANCE:
                colour, depth, acc = colour / acc, depth / acc, 1.0
                break
        d = depth / acc if acc > 0 else 0.0
        first = t_i[0] if len(x) else 0.0
        out[i] = [*colour, acc, d, taken[i], first, t_i[last] if last >= 0 else 0.0]
    out.astype("<f8").tofile(out_path)


if __name__ == "__main__":
    main()
