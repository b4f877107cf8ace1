"""Independent NumPy evaluation of an instant-ngp NeRF snapshot (written from DESIGN §4).

Usage: python3 ingp_reference.py SNAPSHOT POINTS_IN OUT

POINTS_IN holds float32 rows (px, py, pz, dx, dy, dz): points and unit directions in the
NeRF world frame. OUT receives float32 rows (sigma, r, g, b): density per world unit (zero
where the occupancy grid is empty) and linear RGB. Everything is computed in float32.
"""

import gzip
import sys

import msgpack
import numpy as np

F32 = np.float32
GRID = 128


def load(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    return msgpack.unpackb(data, raw=False, strict_map_key=False)


def level_geometry(n_levels, n_min, log2_t, b):
    """(scale, resolution, entries) per level; scale in float32 as on the GPU, its exp2 and
    log2 correctly rounded."""
    out = []
    for lvl in range(n_levels):
        log2_b = F32(np.log2(np.float64(b)))
        scale = F32(np.exp2(np.float64(F32(lvl) * log2_b))) * F32(n_min) - F32(1.0)
        res = int(np.ceil(scale)) + 1
        dense = res ** 3
        entries = min(-(-dense // 8) * 8, 2 ** log2_t)
        out.append((F32(scale), res, entries))
    return out


def encode(x, levels, table, n_feat):
    """Multi-resolution hash encoding of unit-cube points x (N x 3), output N x L*F."""
    outs = []
    offset = 0
    primes = [np.uint32(1), np.uint32(2654435761), np.uint32(805459861)]
    for scale, res, entries in levels:
        t = table[offset * n_feat:(offset + entries) * n_feat].reshape(entries, n_feat)
        offset += entries
        pos = x * scale + F32(0.5)
        cell = np.floor(pos)
        frac = (pos - cell).astype(F32)
        cell = cell.astype(np.int64)
        acc = np.zeros((x.shape[0], n_feat), dtype=F32)
        for corner in range(8):
            bits = [(corner >> a) & 1 for a in range(3)]
            g = [cell[:, a] + bits[a] for a in range(3)]
            w = np.ones(x.shape[0], dtype=F32)
            for a in range(3):
                w = w * (frac[:, a] if bits[a] else F32(1.0) - frac[:, a])
            if res ** 3 <= entries:
                idx = (g[0] + g[1] * res + g[2] * res * res) % entries
            else:
                gu = [(gi % (2 ** 32)).astype(np.uint32) for gi in g]
                h = (gu[0] * primes[0]) ^ (gu[1] * primes[1]) ^ (gu[2] * primes[2])
                idx = h.astype(np.int64) % entries
            acc = acc + w[:, None] * t[idx]
        outs.append(acc)
    return np.concatenate(outs, axis=1)


def mlp(x, mats):
    h = x
    for k, m in enumerate(mats):
        if h.shape[1] < m.shape[1]:
            h = np.concatenate([h, np.zeros((h.shape[0], m.shape[1] - h.shape[1]), F32)], axis=1)
        h = (h @ m.T).astype(F32)
        if k + 1 < len(mats):
            h = np.maximum(h, F32(0.0))
    return h


def split_mlp(p, at, n_in, width, hidden, n_out_padded):
    shapes = [(width, n_in)] + [(width, width)] * (hidden - 1) + [(n_out_padded, width)]
    mats = []
    for rows, cols in shapes:
        mats.append(p[at:at + rows * cols].reshape(rows, cols).astype(F32))
        at += rows * cols
    return mats, at


def sh16(d):
    """Real SH bands 0-3 with the Condon-Shortley sign, from their closed forms."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    rp = np.sqrt(np.pi)
    c = lambda v: F32(v)
    cols = [
        np.full_like(x, c(0.5 / rp)),
        c(-np.sqrt(3) / (2 * rp)) * y,
        c(np.sqrt(3) / (2 * rp)) * z,
        c(-np.sqrt(3) / (2 * rp)) * x,
        c(np.sqrt(15) / (2 * rp)) * x * y,
        c(-np.sqrt(15) / (2 * rp)) * y * z,
        c(np.sqrt(5) / (4 * rp)) * (F32(3) * z * z - F32(1)),
        c(-np.sqrt(15) / (2 * rp)) * x * z,
        c(np.sqrt(15) / (4 * rp)) * (x * x - y * y),
        c(-np.sqrt(70) / (8 * rp)) * y * (F32(3) * x * x - y * y),
        c(np.sqrt(105) / (2 * rp)) * x * y * z,
        c(-np.sqrt(42) / (8 * rp)) * y * (F32(5) * z * z - F32(1)),
        c(np.sqrt(7) / (4 * rp)) * z * (F32(5) * z * z - F32(3)),
        c(-np.sqrt(42) / (8 * rp)) * x * (F32(5) * z * z - F32(1)),
        c(np.sqrt(105) / (4 * rp)) * z * (x * x - y * y),
        c(-np.sqrt(70) / (8 * rp)) * x * (x * x - F32(3) * y * y),
    ]
    return np.stack(cols, axis=1).astype(F32)


def occupancy(values, n_cascades):
    """Per cascade a boolean [z, y, x] grid; values are in Morton order (x lowest bit)."""
    n3 = GRID ** 3
    # Unseen cells (negative) count as empty in the mean, as in instant-ngp.
    thr = F32(min(0.01, float(np.mean(np.maximum(values[:n3].astype(np.float64), 0.0)))))
    r = np.arange(GRID)
    z, y, x = np.meshgrid(r, r, r, indexing="ij")
    morton = np.zeros_like(x)
    for k in range(7):
        morton |= ((x >> k) & 1) << (3 * k)
        morton |= ((y >> k) & 1) << (3 * k + 1)
        morton |= ((z >> k) & 1) << (3 * k + 2)
    return [values[c * n3:(c + 1) * n3][morton] > thr for c in range(n_cascades)]


def occupied(q, grids):
    m = np.max(np.abs(q - F32(0.5)), axis=1)
    out = np.zeros(q.shape[0], dtype=bool)
    done = np.zeros(q.shape[0], dtype=bool)
    for c, g in enumerate(grids):
        here = (~done) & (m < F32(2.0 ** (c - 1)))
        u = ((q - F32(0.5)) / F32(2.0 ** c) + F32(0.5)) * F32(GRID)
        i = np.clip(np.floor(u).astype(np.int64), 0, GRID - 1)
        out[here] = g[i[here, 2], i[here, 1], i[here, 0]]
        done |= here
    return out


def field(snap_path):
    """The snapshot at `snap_path` as a function (points, directions) -> (sigma, rgb), NeRF
    world frame, float32; rgb in the space the snapshot was trained in (sRGB-encoded sigmoid
    outputs, or linear for an HDR snapshot: the function's `is_hdr`)."""
    doc = load(snap_path)
    snap = doc["snapshot"]
    enc = doc["encoding"]
    n_levels = enc.get("n_levels", 16)
    n_feat = enc.get("n_features_per_level", 2)
    log2_t = enc.get("log2_hashmap_size", 19)
    n_min = enc.get("base_resolution", 16)
    aabb_scale = float(snap["nerf"]["aabb_scale"])
    # float32 functions correctly rounded (evaluated in float64, rounded once).
    ln = F32(np.log(np.float64(F32(2048.0) * F32(aabb_scale) / F32(n_min))))
    b = F32(np.exp(np.float64(ln / F32(n_levels - 1))))
    levels = level_geometry(n_levels, n_min, log2_t, F32(b))
    grid_params = sum(e for _, _, e in levels) * n_feat

    dnet, rnet = doc["network"], doc["rgb_network"]
    width_d, hid_d = dnet.get("n_neurons", 64), dnet.get("n_hidden_layers", 1)
    width_r, hid_r = rnet.get("n_neurons", 64), rnet.get("n_hidden_layers", 2)
    n_in = -(-(n_levels * n_feat) // 16) * 16
    n_density = width_d * n_in + width_d * width_d * (hid_d - 1) + 16 * width_d
    raw = snap["params_binary"]
    found = None
    for pad in (16, 8):
        n_rgb = width_r * 32 + width_r * width_r * (hid_r - 1) + pad * width_r
        total = n_density + n_rgb + grid_params
        if "n_params" in snap and snap["n_params"] != total:
            continue
        for dtype in (np.float16, np.float32):
            if "params_type" in snap and snap["params_type"] != ("__half" if dtype == np.float16 else "float"):
                continue
            if len(raw) == total * np.dtype(dtype).itemsize:
                found = (pad, dtype)
    pad, dtype = found
    p = np.frombuffer(raw, dtype=np.dtype(dtype).newbyteorder("<")).astype(F32)
    dmats, at = split_mlp(p, 0, n_in, width_d, hid_d, 16)
    rmats, at = split_mlp(p, at, 32, width_r, hid_r, pad)
    table = p[at:at + grid_params]

    values = np.frombuffer(snap["density_grid_binary"], dtype="<f2").astype(F32)
    grids = occupancy(values, len(values) // GRID ** 3)

    ds = snap["nerf"].get("dataset", {})
    s = F32(ds.get("scale", 0.33))
    o = np.array(ds.get("offset", [0.5, 0.5, 0.5]), dtype=F32)
    hdr = bool(ds.get("is_hdr", False))

    def evaluate(pts, dirs, masked=True):
        return evaluate_at(pts, dirs, s, o, aabb_scale, levels, table, n_feat, dmats, rmats,
                           grids if masked else None, hdr)

    evaluate.is_hdr = hdr
    return evaluate


def evaluate_at(pts, dirs, s, o, aabb_scale, levels, table, n_feat, dmats, rmats, grids, hdr):
    """grids None: the density network's value everywhere, unmasked by occupancy."""
    # NeRF world -> instant-ngp: scale, offset, then cycle (x, y, z) <- (y, z, x).
    q = np.stack([pts[:, 1] * s + o[1], pts[:, 2] * s + o[2], pts[:, 0] * s + o[0]], axis=1).astype(F32)
    half = F32(0.5 * min(aabb_scale, 128.0))
    lo, hi = F32(0.5) - half, F32(0.5) + half
    x = ((q - lo) / (hi - lo)).astype(F32)

    dens_out = mlp(encode(x, levels, table, n_feat), dmats)
    keep = occupied(q, grids) if grids is not None else np.ones(q.shape[0], dtype=bool)
    sigma = np.where(keep, s * np.exp(dens_out[:, 0]), F32(0.0)).astype(F32)

    dn = np.stack([dirs[:, 1], dirs[:, 2], dirs[:, 0]], axis=1).astype(F32)
    dn = ((dn + F32(1)) / F32(2)) * F32(2) - F32(1)
    rgb_raw = mlp(np.concatenate([dens_out, sh16(dn)], axis=1), rmats)[:, :3]
    if hdr:
        rgb = np.exp(np.clip(rgb_raw, -10.0, 10.0))
    else:
        rgb = F32(1.0) / (F32(1.0) + np.exp(-rgb_raw))
    return sigma, rgb.astype(F32)


def main():
    snap_path, pts_path, out_path = sys.argv[1:4]
    evaluate = field(snap_path)
    rows = np.fromfile(pts_path, dtype="<f4").reshape(-1, 6)
    sigma, rgb = evaluate(rows[:, :3], rows[:, 3:])
    np.concatenate([sigma[:, None], rgb], axis=1).astype("<f4").tofile(out_path)


if __name__ == "__main__":
    main()
