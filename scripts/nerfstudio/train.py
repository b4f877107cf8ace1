"""Trains nerfstudio's `nerfacto` on the CPU, small enough to commit as a test fixture.

    cd WORK && python train.py DATA OUTPUTS [--iterations 250] [--rays 1024] [--log2-hashmap 14]

DATA holds transforms.json (make_dataset.py); give DATA and OUTPUTS relative to the working
folder, so that config.yml records relative paths. The run lands in
OUTPUTS/synthetic/nerfacto/run/ (config.yml, dataparser_transforms.json,
nerfstudio_models/step-<last>.ckpt, TensorBoard events).

The config is nerfstudio's own `nerfacto` method config (method_configs["nerfacto"]), changed
only where a CPU fixture needs it:
- machine.device_type cpu (mixed precision is then off: nerfstudio turns it off on the CPU);
- pipeline.model.log2_hashmap_size 14 and each proposal network's 12 (defaults 19 and 17),
  so that the checkpoint (parameters plus Adam's two moments) stays a few MB;
- pipeline.model.camera_optimizer.mode off: the synthetic poses are exact, and pose tweaks
  would move the field away from the analytic scene it is compared with;
- pipeline.datamanager.train_num_rays_per_batch 1024 (default 4096), max_num_iterations,
  the latest checkpoint only (every 50 steps and the last), no evaluation during training,
  TensorBoard instead of the web viewer;
- pipeline.model.implementation stays "tcnn": tiny-cuda-nn is not installed, so nerfstudio
  falls back to its torch layout, as it does for any user without it.
"""

import stub  # noqa: F401  (first: before nerfstudio is imported)

import argparse  # noqa: E402
import copy  # noqa: E402
from pathlib import Path  # noqa: E402


def config_for(args):
    from nerfstudio.configs.method_configs import method_configs

    config = copy.deepcopy(method_configs["nerfacto"])
    config.data = Path(args.data)
    config.output_dir = Path(args.outputs)
    config.experiment_name = "synthetic"
    config.timestamp = "run"
    config.vis = "tensorboard"
    config.machine.device_type = "cpu"
    config.max_num_iterations = args.iterations
    config.steps_per_save = args.save_every
    config.save_only_latest_checkpoint = True
    config.steps_per_eval_batch = config.steps_per_eval_image = 10**9
    config.steps_per_eval_all_images = 10**9
    config.logging.steps_per_log = 10
    config.pipeline.datamanager.train_num_rays_per_batch = args.rays
    config.pipeline.datamanager.eval_num_rays_per_batch = args.rays
    model = config.pipeline.model
    model.log2_hashmap_size = args.log2_hashmap
    model.proposal_net_args_list = [
        {**a, "log2_hashmap_size": args.proposal_log2_hashmap} for a in model.proposal_net_args_list
    ]
    model.camera_optimizer.mode = "off"
    return config


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data")
    ap.add_argument("outputs")
    ap.add_argument("--iterations", type=int, default=250)
    ap.add_argument("--rays", type=int, default=1024)
    ap.add_argument("--save-every", type=int, default=50, help="keeps only the latest")
    ap.add_argument("--log2-hashmap", type=int, default=14)
    ap.add_argument("--proposal-log2-hashmap", type=int, default=12)
    args = ap.parse_args()

    from nerfstudio.scripts.train import main as ns_train

    ns_train(config_for(args))


if __name__ == "__main__":
    main()
