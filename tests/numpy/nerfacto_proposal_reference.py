"""Independent NumPy implementation of nerfacto's inference sampling and render, written from
nerfstudio's conventions (models/nerfacto.py, model_components/ray_samplers.py,
fields/density_fields.py, cameras/rays.py get_weights, renderers.py); no torch, no nerfx code.

Usage: python3 nerfacto_proposal_reference.py RUN_DIR RAYS_IN OUT

RAYS_IN holds float64 rows (ox, oy, oz, dx, dy, dz, near, far) in nerfstudio's normalised
frame (unit directions). OUT receives float64 rows per ray: the main field's sample edges
(num_nerf_samples_per_ray + 1 distances), then r, g, b (sRGB, black background: nerfstudio's
rgb before the last_sample fill), accumulation, expected depth (sum w t_mid / sum w).
Sampling arithmetic is float64 (exact reference); the networks run in float32.
"""

import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import nerfacto_reference as ref  # noqa: E402

F32 = np.float32


# ---- config.yml: the sampler's keys under pipeline.model ----

def model_lines(path):
    """(indent, text) of the lines inside pipeline.model."""
    out, inside = [], False
    for line in open(path).read().splitlines():
        text = line.strip()
        indent = len(line) - len(line.lstrip())
        if not text:
            continue
        if indent == 2 and text.startswith("model:"):
            inside = True
            continue
        if inside and indent <= 2:
            break
        if inside:
            out.append((indent, text))
    return out


def sampler_settings(path):
    lines = model_lines(path)
    scalars, lists = {}, {}
    i = 0
    while i < len(lines):
        indent, text = lines[i]
        key, _, value = text.partition(":")
        value = value.strip()
        i += 1
        if indent != 4 or text.startswith("-"):
            continue
        items = []
        while i < len(lines) and lines[i][1].startswith("-") and lines[i][0] == 4:
            head = lines[i][1][1:].strip()
            i += 1
            if ":" in head:
                item = {}
                k, _, v = head.partition(":")
                item[k.strip()] = v.strip()
                while i < len(lines) and lines[i][0] == 6 and not lines[i][1].startswith("-"):
                    k, _, v = lines[i][1].partition(":")
                    item[k.strip()] = v.strip()
                    i += 1
                items.append(item)
            else:
                items.append(head)
        if items:
            lists[key] = items
        else:
            scalars[key] = value
    iterations = int(scalars.get("num_proposal_iterations", 2))
    same = scalars.get("use_same_proposal_network", "false") == "true"
    args = lists.get("proposal_net_args_list")
    nets = []
    for n in range(1 if same else iterations):
        a = args[min(n, len(args) - 1)]
        nets.append({
            "num_levels": int(a.get("num_levels", 8)),
            "features_per_level": int(a.get("features_per_level", 2)),
            "log2_hashmap_size": int(a.get("log2_hashmap_size", 18)),
            "base_res": int(a.get("base_res", 16)),
            "max_res": int(a.get("max_res", 1024)),
            "hidden_dim": int(a.get("hidden_dim", 64)),
            "num_layers": int(a.get("num_layers", 2)),
        })
    return {
        "far": float(scalars.get("far_plane", 1000.0)),
        "proposal": [int(v) for v in lists.get("num_proposal_samples_per_ray", [256, 96])][:iterations],
        "nerf": int(scalars.get("num_nerf_samples_per_ray", 48)),
        "uniform": scalars.get("proposal_initial_sampler", "piecewise") == "uniform",
        "same": same,
        "nets": nets,
    }


# ---- the proposal density fields (HashMLPDensityField) ----

def unit_and_selector(p):
    u = ((ref.contract(p) + F32(2)) / F32(4)).astype(F32)
    sel = np.all((u > 0) & (u < 1), axis=1)
    return (u * sel[:, None]).astype(F32), sel


def proposal_density(state, index, net, density_scale, p):
    pre = f"_model.proposal_networks.{index}."
    u, sel = unit_and_selector(p)
    n_in = net["num_levels"] * net["features_per_level"]
    if pre + "mlp_base.0.tcnn_encoding.params" in state:
        enc = ref.tcnn_grid(u, net, state[pre + "mlp_base.0.tcnn_encoding.params"])
        raw = ref.tcnn_mlp(enc, state[pre + "mlp_base.1.tcnn_encoding.params"], n_in,
                           net["hidden_dim"], net["num_layers"] - 1, 1)
    else:
        enc = ref.torch_grid(u, net, state[pre + "mlp_base.0.hash_table"])
        layers = [(state[f"{pre}mlp_base.1.layers.{k}.weight"], state[f"{pre}mlp_base.1.layers.{k}.bias"])
                  for k in range(16) if f"{pre}mlp_base.1.layers.{k}.weight" in state]
        raw = ref.torch_mlp(enc, layers)
    return (F32(density_scale) * np.exp(raw[:, 0]) * sel).astype(F32)


# ---- the sampler ----

def spacing(x, uniform):
    """UniformLinDispPiecewiseSampler's spacing_fn (identity for UniformSampler)."""
    if uniform:
        return x
    with np.errstate(divide="ignore"):
        return np.where(x < 1, x / 2, 1 - 1 / (2 * x))


def spacing_inv(s, uniform):
    if uniform:
        return s
    with np.errstate(divide="ignore"):
        return np.where(s < 0.5, 2 * s, 1 / (2 - 2 * s))


def get_weights(sigma, t):
    """cameras/rays.py get_weights: deltas are the bins' lengths, the last one too."""
    dd = sigma * (t[:, 1:] - t[:, :-1])
    before = np.concatenate([np.zeros((dd.shape[0], 1)), np.cumsum(dd, axis=1)[:, :-1]], axis=1)
    return (1 - np.exp(-dd)) * np.exp(-before)


def pdf_bins(bins, weights, num_samples):
    """PDFSampler at inference: padding 0.01, eps 1e-5, u at bin centres, include_original
    False."""
    b = num_samples + 1
    w = weights + 0.01
    total = w.sum(axis=1, keepdims=True)
    pad = np.maximum(1e-5 - total, 0)
    w = w + pad / w.shape[1]
    total = total + pad
    cdf = np.minimum(1, np.cumsum(w / total, axis=1))
    cdf = np.concatenate([np.zeros((cdf.shape[0], 1)), cdf], axis=1)
    u = np.linspace(0, 1 - 1 / b, b) + 1 / (2 * b)
    out = np.empty((bins.shape[0], b))
    last = bins.shape[1] - 1
    for r in range(bins.shape[0]):
        inds = np.searchsorted(cdf[r], u, side="right")
        below = np.clip(inds - 1, 0, last)
        above = np.clip(inds, 0, last)
        c0, c1 = cdf[r][below], cdf[r][above]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = np.nan_to_num((u - c0) / (c1 - c0), nan=0.0)
        t = np.clip(t, 0, 1)
        out[r] = bins[r][below] + t * (bins[r][above] - bins[r][below])
    return out


def main():
    run, rays_in, out_path = sys.argv[1:4]
    cfg = ref.model_settings(os.path.join(run, "config.yml"))
    sampler = sampler_settings(os.path.join(run, "config.yml"))
    state = ref.load_state(run)
    rays = np.fromfile(rays_in, dtype=np.float64).reshape(-1, 8)
    o, d, near, far = rays[:, 0:3], rays[:, 3:6], rays[:, 6:7], rays[:, 7:8]
    uniform = sampler["uniform"]
    s_near, s_far = spacing(near, uniform), spacing(far, uniform)

    def distances(bins):
        return spacing_inv(bins * s_far + (1 - bins) * s_near, uniform)

    def midpoints(t):
        mid = (t[:, :-1] + t[:, 1:]) / 2
        return (o[:, None, :] + d[:, None, :] * mid[:, :, None]).reshape(-1, 3).astype(F32)

    counts = sampler["proposal"] + [sampler["nerf"]]
    bins = np.broadcast_to(np.linspace(0, 1, counts[0] + 1), (rays.shape[0], counts[0] + 1))
    weights = None
    for level, n in enumerate(counts):
        if level > 0:
            bins = pdf_bins(bins, weights, n)
        t = distances(bins)
        if level < len(counts) - 1:
            index = 0 if sampler["same"] else level
            sigma = proposal_density(state, index, sampler["nets"][index],
                                     cfg["average_init_density"], midpoints(t))
            weights = get_weights(sigma.reshape(t.shape[0], -1).astype(np.float64), t)
    p = midpoints(t)
    _, sel = unit_and_selector(p)
    dirs = np.repeat(d, counts[-1], axis=0).astype(F32)
    sigma, srgb = ref.field(run)(p, dirs)
    sigma = (sigma * sel).astype(np.float64).reshape(t.shape[0], -1)
    w = get_weights(sigma, t)
    rgb = (w[:, :, None] * srgb.reshape(t.shape[0], -1, 3).astype(np.float64)).sum(axis=1)
    acc = w.sum(axis=1)
    mid = (t[:, :-1] + t[:, 1:]) / 2
    with np.errstate(divide="ignore", invalid="ignore"):
        depth = np.where(acc > 0, (w * mid).sum(axis=1) / acc, np.inf)
    np.concatenate([t, rgb, acc[:, None], depth[:, None]], axis=1).astype(np.float64).tofile(out_path)


if __name__ == "__main__":
    main()
