"""Independent rasterisation of 3D Gaussian splats, written from the published conventions
(gsplat's classic mode, as DESIGN.md §4 states them) and Blender's camera facts (DESIGN.md §3),
not from nerfx's Rust.

    python3 splat_reference.py JOB.json OUT.bin

JOB.json: {"ply": path, "world_from_splats": 4x4 row-major, "antialiased": bool,
"camera": {"matrix_world": 4x4 row-major, "lens", "sensor_width", "sensor_height",
"sensor_fit": "AUTO"|"HORIZONTAL"|"VERTICAL", "shift_x", "shift_y", "resolution_x",
"resolution_y", "pixel_aspect_x", "pixel_aspect_y"}}

OUT.bin: float32 little-endian, rows top to bottom, 5 values per pixel: premultiplied R G B in
the trained (sRGB-encoded) space, alpha, expected camera depth (inf where alpha is 0).

This one transforms the Gaussians into the world first (mean N·mu, covariance A·Sigma·A^T)
and projects them from there; SH are still evaluated in the splats' own frame.
"""

import json
import sys

import numpy as np

TILE = 16
SH_C0 = 0.28209479177387814
SH_C1 = 0.4886025119029199
SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005,
         -1.0925484305920792, 0.5462742152960396)
SH_C3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658,
         0.3731763325901154, -0.4570457994644658, 1.445305721320277,
         -0.5900435899266435)


def read_ply(path):
    data = open(path, "rb").read()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode().splitlines()
    assert "format binary_little_endian 1.0" in header
    names, count = [], None
    for line in header:
        words = line.split()
        if words[:2] == ["element", "vertex"]:
            count = int(words[2])
        elif words[:1] == ["property"]:
            assert words[1] == "float", line
            names.append(words[2])
    table = np.frombuffer(data[end:end + count * 4 * len(names)], dtype="<f4")
    table = table.reshape(count, len(names)).astype(np.float64)
    col = {n: table[:, i] for i, n in enumerate(names)}
    rest = sorted((n for n in names if n.startswith("f_rest_")), key=lambda n: int(n[7:]))
    k = len(rest) // 3
    sh = np.zeros((count, k + 1, 3))
    for c in range(3):
        sh[:, 0, c] = col[f"f_dc_{c}"]
        for j in range(k):
            sh[:, j + 1, c] = col[f"f_rest_{c * k + j}"]
    q = np.stack([col[f"rot_{i}"] for i in range(4)], axis=1)
    return {
        "mean": np.stack([col["x"], col["y"], col["z"]], axis=1),
        "scale": np.exp(np.stack([col[f"scale_{i}"] for i in range(3)], axis=1)),
        "quat": q / np.linalg.norm(q, axis=1, keepdims=True),
        "opacity": 1.0 / (1.0 + np.exp(-col["opacity"])),
        "sh": sh,
    }


def rotation(q):
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
    ], axis=1)


def sh_colour(sh, d):
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    basis = [np.full_like(x, SH_C0)]
    if sh.shape[1] > 1:
        basis += [-SH_C1 * y, SH_C1 * z, -SH_C1 * x]
    if sh.shape[1] > 4:
        xx, yy, zz = x * x, y * y, z * z
        basis += [SH_C2[0] * x * y, SH_C2[1] * y * z, SH_C2[2] * (2 * zz - xx - yy),
                  SH_C2[3] * x * z, SH_C2[4] * (xx - yy)]
    if sh.shape[1] > 9:
        basis += [SH_C3[0] * y * (3 * xx - yy), SH_C3[1] * x * y * z,
                  SH_C3[2] * y * (4 * zz - xx - yy), SH_C3[3] * z * (2 * zz - 3 * xx - 3 * yy),
                  SH_C3[4] * x * (4 * zz - xx - yy), SH_C3[5] * z * (xx - yy),
                  SH_C3[6] * x * (xx - 3 * yy)]
    basis = np.stack(basis, axis=1)
    return np.maximum(np.einsum("nk,nkc->nc", basis, sh) + 0.5, 0.0)


def blender_pinhole(cam):
    """fx, fy, cx, cy (raster y down, pixel centres at +0.5) from Blender's camera data."""
    rx, ry = cam["resolution_x"], cam["resolution_y"]
    pax, pay = max(cam["pixel_aspect_x"], 1.0), max(cam["pixel_aspect_y"], 1.0)
    fit = cam["sensor_fit"]
    horizontal = fit == "HORIZONTAL" or (fit == "AUTO" and rx * pax >= ry * pay)
    sensor = cam["sensor_height"] if fit == "VERTICAL" else cam["sensor_width"]
    ycor = pay / pax
    viewfac = rx if horizontal else ycor * ry
    s = sensor / (cam["lens"] * viewfac)
    # At depth 1 the image spans x in [-rx/2 + shift_x*viewfac, ...]*s and y likewise with
    # ycor*ry; raster x runs left to right over rx pixels, raster y top to bottom over ry.
    x_min = (-rx / 2 + cam["shift_x"] * viewfac) * s
    y_max = (ycor * ry / 2 + cam["shift_y"] * viewfac) * s
    fx = 1.0 / s
    fy = 1.0 / (ycor * s)
    return fx, fy, -x_min * fx, y_max * fy, rx, ry


def render(job):
    g = read_ply(job["ply"])
    n_mat = np.array(job["world_from_splats"], dtype=np.float64)
    a = n_mat[:3, :3]
    cam = job["camera"]
    world_from_camera = np.array(cam["matrix_world"], dtype=np.float64)
    fx, fy, cx, cy, w, h = blender_pinhole(cam)

    # Gaussians in the world.
    mean_w = g["mean"] @ a.T + n_mat[:3, 3]
    m = rotation(g["quat"]) * g["scale"][:, None, :]
    cov_w = a @ (m @ np.transpose(m, (0, 2, 1))) @ a.T
    # Colour: direction camera centre -> mean, in the splats' own frame.
    eye_splats = np.linalg.solve(n_mat, world_from_camera[:, 3])[:3]
    rgb = sh_colour(g["sh"], (g["mean"] - eye_splats) /
                    np.linalg.norm(g["mean"] - eye_splats, axis=1, keepdims=True))

    # Camera with x right, y down, z forward: Blender's camera axes with y and z negated.
    view = np.linalg.inv(world_from_camera)
    view[1] *= -1
    view[2] *= -1
    r, t = view[:3, :3], view[:3, 3]
    p = mean_w @ r.T + t
    cov_c = r @ cov_w @ r.T
    z = p[:, 2]
    keep = z > 0.01
    tan_x, tan_y = 0.5 * w / fx, 0.5 * h / fy
    lx = (-(cx / fx + 0.3 * tan_x), (w - cx) / fx + 0.3 * tan_x)
    ly = (-(cy / fy + 0.3 * tan_y), (h - cy) / fy + 0.3 * tan_y)
    zs = np.where(keep, z, 1.0)
    tx = zs * np.clip(p[:, 0] / zs, *lx)
    ty = zs * np.clip(p[:, 1] / zs, *ly)
    jac = np.zeros((len(z), 2, 3))
    jac[:, 0, 0] = fx / zs
    jac[:, 0, 2] = -fx * tx / zs ** 2
    jac[:, 1, 1] = fy / zs
    jac[:, 1, 2] = -fy * ty / zs ** 2
    cov2 = jac @ cov_c @ np.transpose(jac, (0, 2, 1))
    det0 = cov2[:, 0, 0] * cov2[:, 1, 1] - cov2[:, 0, 1] ** 2
    ca, cb, cc = cov2[:, 0, 0] + 0.3, cov2[:, 0, 1], cov2[:, 1, 1] + 0.3
    det = ca * cc - cb * cb
    keep &= det > 0
    det = np.where(keep, det, 1.0)
    conic = np.stack([cc / det, -cb / det, ca / det], axis=1)
    opacity = g["opacity"] * (np.sqrt(np.maximum(det0 / det, 0.0)) if job["antialiased"] else 1.0)
    mid = 0.5 * (ca + cc)
    radius = np.ceil(3.0 * np.sqrt(mid + np.sqrt(np.maximum(mid * mid - det, 0.01))))
    u = fx * p[:, 0] / zs + cx
    v = fy * p[:, 1] / zs + cy
    keep &= (u + radius > 0) & (u - radius < w) & (v + radius > 0) & (v - radius < h)

    out = np.zeros((h, w, 5))
    out[:, :, 4] = np.inf
    order = np.argsort(np.where(keep, z, np.inf), kind="stable")
    order = order[keep[order]]
    for ty0 in range(0, h, TILE):
        for tx0 in range(0, w, TILE):
            # Splats whose bounding square, in tile units, reaches this tile.
            t_lo_x = np.floor(u[order] / TILE - radius[order] / TILE)
            t_hi_x = np.ceil(u[order] / TILE + radius[order] / TILE)
            t_lo_y = np.floor(v[order] / TILE - radius[order] / TILE)
            t_hi_y = np.ceil(v[order] / TILE + radius[order] / TILE)
            i, j = tx0 // TILE, ty0 // TILE
            ids = order[(t_lo_x <= i) & (i < t_hi_x) & (t_lo_y <= j) & (j < t_hi_y)]
            ys, xs = np.mgrid[ty0:min(ty0 + TILE, h), tx0:min(tx0 + TILE, w)]
            px, py = xs.ravel() + 0.5, ys.ravel() + 0.5
            trans = np.ones(px.shape)
            colour = np.zeros((px.size, 3))
            depth = np.zeros(px.shape)
            live = np.ones(px.shape, dtype=bool)
            for k in ids:
                dx, dy = u[k] - px, v[k] - py
                sigma = 0.5 * (conic[k, 0] * dx * dx + conic[k, 2] * dy * dy) \
                    + conic[k, 1] * dx * dy
                alpha = np.minimum(0.999, opacity[k] * np.exp(-sigma))
                hit = live & (sigma >= 0) & (alpha >= 1.0 / 255.0)
                nxt = trans * (1.0 - alpha)
                stop = hit & (nxt <= 1e-4)
                live &= ~stop
                hit &= ~stop
                wgt = np.where(hit, alpha * trans, 0.0)
                colour += wgt[:, None] * rgb[k]
                depth += wgt * z[k]
                trans = np.where(hit, nxt, trans)
                if not live.any():
                    break
            acc = 1.0 - trans
            block = out[ty0:ty0 + TILE, tx0:tx0 + TILE]
            block[:, :, :3] = colour.reshape(ys.shape + (3,))
            block[:, :, 3] = acc.reshape(ys.shape)
            with np.errstate(invalid="ignore", divide="ignore"):
                block[:, :, 4] = np.where(acc > 0, depth / acc, np.inf).reshape(ys.shape)
    return out


def main():
    job = json.load(open(sys.argv[1]))
    render(job).astype("<f4").tofile(sys.argv[2])


if __name__ == "__main__":
    main()
