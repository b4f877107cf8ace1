"""Independent NumPy evaluation of a nerfstudio nerfacto run (written from DESIGN §4 and
nerfstudio's field definitions; no torch).

Usage: python3 nerfacto_reference.py RUN_DIR POINTS_IN OUT

POINTS_IN holds float32 rows (px, py, pz, dx, dy, dz) in nerfstudio's normalised frame.
OUT receives float32 rows (sigma, r, g, b): the density (no occupancy mask) and linear RGB.
The checkpoint is unpickled with pickle.Unpickler, find_class and persistent_load
overridden, so nothing from torch is imported or called.
"""

import os
import pickle
import sys
import zipfile

import numpy as np

F32 = np.float32


# ---- config.yml: the few model keys, by indentation ----

def model_settings(path):
    wanted = {
        "num_levels": 16, "features_per_level": 2, "log2_hashmap_size": 19,
        "base_res": 16, "max_res": 2048, "hidden_dim": 64, "hidden_dim_color": 64,
        "average_init_density": 1.0, "far_plane": 1000.0,
    }
    out = dict(wanted)
    model_indent = None
    for line in open(path).read().splitlines():
        stripped = line.lstrip()
        indent = len(line) - len(stripped)
        if model_indent is not None and stripped and indent <= model_indent:
            model_indent = None
        if stripped.startswith("model:") and indent == 2:
            model_indent = indent
            continue
        if model_indent is not None and indent == model_indent + 2 and ":" in stripped:
            key, value = stripped.split(":", 1)
            if key in wanted:
                out[key] = type(wanted[key])(value.strip())
    return out


# ---- the checkpoint ----

class OrderedDict(dict):
    """Stands in for collections.OrderedDict: a dict with attributes (BUILD sets
    `_metadata` on torch state dicts)."""


class Storage:
    def __init__(self, array):
        self.array = array


def rebuild_tensor(storage, offset, size, stride, *_rest):
    a = storage.array
    item = a.itemsize
    view = np.lib.stride_tricks.as_strided(
        a[offset:], shape=tuple(size), strides=tuple(s * item for s in stride))
    return np.array(view)


class Loader(pickle.Unpickler):
    def __init__(self, f, archive, prefix):
        super().__init__(f)
        self.archive = archive
        self.prefix = prefix

    def find_class(self, module, name):
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return rebuild_tensor
        if (module, name) == ("collections", "OrderedDict"):
            return OrderedDict
        if module == "torch" and name.endswith("Storage"):
            return {"FloatStorage": np.float32, "HalfStorage": np.float16}[name]
        raise pickle.UnpicklingError(f"unexpected global {module}.{name}")

    def persistent_load(self, pid):
        tag, dtype, key, _location, numel = pid
        assert tag == "storage"
        raw = self.archive.read(f"{self.prefix}data/{key}")
        return Storage(np.frombuffer(raw, dtype=dtype, count=numel).astype(F32))


def load_state(run):
    models = os.path.join(run, "nerfstudio_models")
    steps = []
    for name in os.listdir(models):
        if name.startswith("step-") and name.endswith(".ckpt"):
            steps.append((int(name[5:-5]), name))
    path = os.path.join(models, max(steps)[1])
    with zipfile.ZipFile(path) as z:
        pkl = [n for n in z.namelist() if n.endswith("/data.pkl")][0]
        prefix = pkl[: -len("data.pkl")]
        with z.open(pkl) as f:
            ckpt = Loader(f, z, prefix).load()
    return ckpt["pipeline"]


# ---- the networks ----

def growth(cfg):
    return np.exp((np.log(cfg["max_res"]) - np.log(cfg["base_res"])) / (cfg["num_levels"] - 1))


PRIMES = (np.uint64(1), np.uint64(2654435761), np.uint64(805459861))


def spatial_hash(g, size):
    g = [gi.astype(np.uint64) for gi in g]
    h = (g[0] * PRIMES[0]) ^ (g[1] * PRIMES[1]) ^ (g[2] * PRIMES[2])
    return (h % np.uint64(size)).astype(np.int64)


def tcnn_grid(u, cfg, params):
    """tiny-cuda-nn: +0.5 offset, dense coarse levels, hashed fine ones (uint32 arithmetic
    reduced modulo the level size)."""
    nf = cfg["features_per_level"]
    b = F32(growth(cfg))
    log2_b = F32(np.log2(np.float64(b)))
    offset = 0
    outs = []
    for lvl in range(cfg["num_levels"]):
        scale = F32(np.exp2(np.float64(F32(lvl) * log2_b))) * F32(cfg["base_res"]) - F32(1)
        res = int(np.ceil(scale)) + 1
        entries = min(-(-res ** 3 // 8) * 8, 2 ** cfg["log2_hashmap_size"])
        table = params[offset * nf:(offset + entries) * nf].reshape(entries, nf)
        offset += entries
        pos = (u * scale + F32(0.5)).astype(F32)
        cell = np.floor(pos)
        frac = (pos - cell).astype(F32)
        cell = cell.astype(np.int64)
        acc = np.zeros((u.shape[0], nf), F32)
        for corner in range(8):
            bits = [(corner >> a) & 1 for a in range(3)]
            g = [cell[:, a] + bits[a] for a in range(3)]
            w = np.ones(u.shape[0], F32)
            for a in range(3):
                w = w * (frac[:, a] if bits[a] else F32(1) - frac[:, a])
            if res ** 3 <= entries:
                idx = (g[0] + g[1] * res + g[2] * res * res) % entries
            else:
                idx = spatial_hash([(gi % 2 ** 32) for gi in g], 2 ** 32) % entries
            acc = acc + w[:, None] * table[idx]
        outs.append(acc)
    return np.concatenate(outs, axis=1)


def torch_grid(u, cfg, table):
    """nerfstudio's torch HashEncoding: scale floor(N_min·g^l) in float32, no offset, every
    level hashed into its own 2^log2T rows, weight frac on the ceiling corner."""
    size = 2 ** cfg["log2_hashmap_size"]
    g32 = F32(growth(cfg))
    outs = []
    for lvl in range(cfg["num_levels"]):
        scale = np.floor(F32(cfg["base_res"]) * F32(np.float64(g32) ** lvl))
        p = (u * F32(scale)).astype(F32)
        lo = np.floor(p).astype(np.int64)
        hi = np.ceil(p).astype(np.int64)
        frac = (p - np.floor(p)).astype(F32)
        acc = np.zeros((u.shape[0], table.shape[1]), F32)
        for corner in range(8):
            bits = [(corner >> a) & 1 for a in range(3)]
            g = [hi[:, a] if bits[a] else lo[:, a] for a in range(3)]
            w = np.ones(u.shape[0], F32)
            for a in range(3):
                w = w * (frac[:, a] if bits[a] else F32(1) - frac[:, a])
            idx = spatial_hash(g, size) + lvl * size
            acc = acc + w[:, None] * table[idx]
        outs.append(acc)
    return np.concatenate(outs, axis=1)


def tcnn_mlp(x, params, n_in, width, hidden, n_out):
    """Bias-free, input padded to 16, output padded to 16, row-major [out][in]."""
    pad_in = -(-n_in // 16) * 16
    pad_out = -(-n_out // 16) * 16
    shapes = [(width, pad_in)] + [(width, width)] * (hidden - 1) + [(pad_out, width)]
    h = np.concatenate([x, np.zeros((x.shape[0], pad_in - n_in), F32)], axis=1)
    at = 0
    for k, (o, i) in enumerate(shapes):
        m = params[at:at + o * i].reshape(o, i)
        at += o * i
        h = (h @ m.T).astype(F32)
        if k + 1 < len(shapes):
            h = np.maximum(h, F32(0))
    assert at == params.size, (at, params.size)
    return h[:, :n_out]


def torch_mlp(x, layers):
    h = x
    for k, (w, b) in enumerate(layers):
        h = (h @ w.T + b).astype(F32)
        if k + 1 < len(layers):
            h = np.maximum(h, F32(0))
    return h


def sh_tcnn(d):
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    xx, yy, zz = x * x, y * y, z * z
    return np.stack([
        np.full_like(x, 0.28209479177387814), -0.48860251190291987 * y,
        0.48860251190291987 * z, -0.48860251190291987 * x,
        1.0925484305920792 * x * y, -1.0925484305920792 * y * z,
        0.94617469575756008 * zz - 0.31539156525252005, -1.0925484305920792 * x * z,
        0.54627421529603959 * xx - 0.54627421529603959 * yy,
        0.59004358992664352 * y * (-3 * xx + yy), 2.8906114426405538 * x * y * z,
        0.45704579946446572 * y * (1 - 5 * zz), 0.3731763325901154 * z * (5 * zz - 3),
        0.45704579946446572 * x * (1 - 5 * zz), 1.4453057213202769 * z * (xx - yy),
        0.59004358992664352 * x * (-xx + 3 * yy),
    ], axis=1).astype(F32)


def sh_torch(v):
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    xx, yy, zz = x * x, y * y, z * z
    return np.stack([
        np.full_like(x, 0.28209479177387814), 0.4886025119029199 * y,
        0.4886025119029199 * z, 0.4886025119029199 * x,
        1.0925484305920792 * x * y, 1.0925484305920792 * y * z,
        0.9461746957575601 * zz - 0.31539156525252005, 1.0925484305920792 * x * z,
        0.5462742152960396 * (xx - yy), 0.5900435899266435 * y * (3 * xx - yy),
        2.890611442640554 * x * y * z, 0.4570457994644658 * y * (5 * zz - 1),
        0.3731763325901154 * z * (5 * zz - 3), 0.4570457994644658 * x * (5 * zz - 1),
        1.445305721320277 * z * (xx - yy), 0.5900435899266435 * x * (xx - 3 * yy),
    ], axis=1).astype(F32)


def contract(p):
    mag = np.max(np.abs(p), axis=1, keepdims=True)
    safe = np.maximum(mag, F32(1))
    outer = ((p / safe) * (F32(2) - F32(1) / safe)).astype(F32)
    return np.where(mag < 1, p, outer).astype(F32)


def field(run):
    """The run's field: a function (points, unit directions) -> (sigma, sRGB colour), float32,
    with the run's settings as its `cfg` attribute."""
    cfg = model_settings(os.path.join(run, "config.yml"))
    state = load_state(run)
    f = "_model.field."
    emb = state[f + "embedding_appearance.embedding.weight"]
    appearance = emb.astype(np.float64).mean(axis=0).astype(F32)
    n_grid = cfg["num_levels"] * cfg["features_per_level"]

    def evaluate(p, d):
        u = ((contract(p) + F32(2)) / F32(4)).astype(F32)
        dirs01 = ((d + F32(1)) / F32(2)).astype(F32)
        if f + "mlp_head.tcnn_encoding.params" in state:
            flat = state[f + "mlp_base.model.params"]
            n_mlp = cfg["hidden_dim"] * (-(-n_grid // 16) * 16) + 16 * cfg["hidden_dim"]
            enc = tcnn_grid(u, cfg, flat[n_mlp:])
            base = tcnn_mlp(enc, flat[:n_mlp], n_grid, cfg["hidden_dim"], 1, 16)
            sh = sh_tcnn((dirs01 * F32(2) - F32(1)).astype(F32))
            head_in = np.concatenate(
                [sh, base[:, 1:], np.broadcast_to(appearance, (u.shape[0], appearance.size))],
                axis=1)
            out = tcnn_mlp(head_in, state[f + "mlp_head.tcnn_encoding.params"],
                           head_in.shape[1], cfg["hidden_dim_color"], 2, 3)
        else:
            enc = torch_grid(u, cfg, state[f + "mlp_base.model.0.hash_table"])
            layers = lambda pre: [(state[f"{f}{pre}.{k}.weight"], state[f"{f}{pre}.{k}.bias"])
                                  for k in range(10) if f"{f}{pre}.{k}.weight" in state]
            base = torch_mlp(enc, layers("mlp_base.model.1.layers"))
            sh = sh_torch(dirs01)
            head_in = np.concatenate(
                [sh, base[:, 1:], np.broadcast_to(appearance, (u.shape[0], appearance.size))],
                axis=1)
            out = torch_mlp(head_in, layers("mlp_head.layers"))
        sigma = (F32(cfg["average_init_density"]) * np.exp(base[:, 0])).astype(F32)
        srgb = (F32(1) / (F32(1) + np.exp(-out))).astype(F32)
        return sigma, srgb

    evaluate.cfg = cfg
    return evaluate


def main():
    run, points_in, out_path = sys.argv[1:4]
    rows = np.fromfile(points_in, dtype=F32).reshape(-1, 6)
    sigma, srgb = field(run)(rows[:, :3], rows[:, 3:])
    np.concatenate([sigma[:, None], srgb], axis=1).astype(F32).tofile(out_path)


if __name__ == "__main__":
    main()
