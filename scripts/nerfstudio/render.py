"""Renders a nerfacto run with nerfstudio's own model, for exact comparison: float32 `.npy`.

    python render.py RUN DATA CAMERA_PATH OUT

RUN is the run folder (config.yml, nerfstudio_models/); DATA the dataset it was trained on
(transforms.json and images: the model's scene box and appearance table come from it);
CAMERA_PATH a nerfstudio camera_path.json (read by nerfstudio's own get_path_from_json).

The run is loaded with nerfstudio's eval_setup (inference mode) and each camera rendered with
`get_outputs_for_camera`, the call ns-render makes, with the background overridden to black
(nerfacto's "last_sample" background would fill `1 − accumulation` with the last sample's
colour). Per camera k (0-based), OUT receives, each (H, W) or (H, W, 3), float32:
- camK_rgb.npy: `Σ wᵢ cᵢ` (black background), in the trained (sRGB-encoded) space, clamped
  to [0, 1] per sample as nerfstudio does at inference;
- camK_accumulation.npy: `Σ wᵢ` over the 48 samples of the main field;
- camK_depth_median.npy: nerfacto's "depth" (DepthRenderer "median"): the midpoint of the
  first sample where the cumulative weight reaches 0.5 (the last sample when it never does);
- camK_depth_expected.npy: "expected_depth": `Σ wᵢ tᵢ / (Σ wᵢ + 1e-10)`, tᵢ the sample
  midpoints, clipped to the samples' range;
- camK_prop_depth_0.npy, camK_prop_depth_1.npy: the proposal networks' median depths.
Depths are distances along the unit ray direction in nerfstudio's normalised frame (the
frame of the camera path); camera-space Z is `t / |((x−cx)/fx, (y−cy)/fy, 1)|`.
And for the centre pixel (x = W//2, y = H//2, sampled at its centre, +0.5):
- camK_centre_ray.npy: origin (3) and unit direction (3), after the near/far collider;
- camK_centre_samples_{0,1,2}.npy: (n, 3) rows of [start, end, weight]: stage 0 the initial
  uniform/linear-in-disparity samples with proposal network 0's weights, stage 1 the
  resampled ones with proposal network 1's weights, stage 2 the main field's 48 samples
  with its weights (what rgb, accumulation and depth integrate).
"""

import stub  # noqa: F401  (first: before nerfstudio is imported)

import argparse  # noqa: E402
import json  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402


def load(run: Path, data: Path):
    from nerfstudio.utils.eval_utils import eval_setup

    def relocate(config):
        config.data = data
        config.pipeline.datamanager.data = data
        config.get_checkpoint_dir = lambda: run / "nerfstudio_models"
        return config

    config, pipeline, ckpt, step = eval_setup(run / "config.yml", test_mode="inference",
                                              update_config_callback=relocate)
    return pipeline.model, ckpt, step


def centre_samples(model, cameras, k):
    """The centre pixel's samples at every stage of nerfacto's proposal sampler."""
    h, w = int(cameras.height[k]), int(cameras.width[k])
    coords = torch.tensor([[h // 2 + 0.5, w // 2 + 0.5]])  # (y, x) pixel centre
    bundle = cameras.generate_rays(camera_indices=k, coords=coords)
    bundle = model.collider(bundle)
    samples, weights_list, samples_list = model.proposal_sampler(
        bundle, density_fns=model.density_fns)
    field_outputs = model.field.forward(samples)
    from nerfstudio.field_components.field_heads import FieldHeadNames

    weights_list.append(samples.get_weights(field_outputs[FieldHeadNames.DENSITY]))
    samples_list.append(samples)
    stages = []
    for s, wts in zip(samples_list, weights_list):
        stages.append(torch.cat([s.frustums.starts[0], s.frustums.ends[0], wts[0]], dim=-1))
    ray = torch.cat([bundle.origins[0], bundle.directions[0]])
    return ray, stages


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("run", type=Path)
    ap.add_argument("data", type=Path)
    ap.add_argument("camera_path", type=Path)
    ap.add_argument("out", type=Path)
    args = ap.parse_args()

    from nerfstudio.cameras.camera_paths import get_path_from_json
    from nerfstudio.model_components.renderers import background_color_override_context

    model, ckpt, step = load(args.run, args.data)
    cameras = get_path_from_json(json.loads(args.camera_path.read_text()))
    args.out.mkdir(parents=True, exist_ok=True)

    def save(name, t):
        np.save(args.out / name, t.detach().cpu().numpy().astype(np.float32))

    names = {"rgb": "rgb", "accumulation": "accumulation", "depth": "depth_median",
             "expected_depth": "depth_expected", "prop_depth_0": "prop_depth_0",
             "prop_depth_1": "prop_depth_1"}
    with torch.no_grad(), background_color_override_context(torch.zeros(3)):
        for k in range(cameras.shape[0]):
            out = model.get_outputs_for_camera(cameras[k:k + 1])
            for key, name in names.items():
                v = out[key]
                save(f"cam{k}_{name}.npy", v[..., 0] if v.shape[-1] == 1 else v)
            ray, stages = centre_samples(model, cameras, k)
            save(f"cam{k}_centre_ray.npy", ray)
            for i, s in enumerate(stages):
                save(f"cam{k}_centre_samples_{i}.npy", s)
            acc = out["accumulation"]
            print(f"camera {k}: rgb {out['rgb'].min():.4f}..{out['rgb'].max():.4f}, "
                  f"accumulation mean {acc.mean():.4f}, depth (median) "
                  f"{out['depth'].min():.4f}..{out['depth'].max():.4f}, samples per stage "
                  f"{[len(s) for s in stages]}")
    print(f"{ckpt} (step {step}) → {args.out}")


if __name__ == "__main__":
    main()
