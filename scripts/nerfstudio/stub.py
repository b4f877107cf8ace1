"""What nerfstudio needs to run offline on a CPU; import this before anything of nerfstudio.

- LPIPS (torchmetrics) downloads pretrained weights when nerfacto's model is built: it is
  replaced by a stub that reports 0 (it is only an evaluation metric; training never uses it).
- torch ≥ 2.6 loads checkpoints with `weights_only=True` by default, which refuses
  nerfstudio's (they hold optimizer and scheduler state): the old default is restored.
- torch is limited to THREADS threads (default 2; the machine is shared).
"""

import os

os.environ.setdefault("TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD", "1")

import torch  # noqa: E402
import torchmetrics.image.lpip  # noqa: E402

torch.set_num_threads(int(os.environ.get("THREADS", "2")))


class NoLpips(torch.nn.Module):
    """Stands in for LearnedPerceptualImagePatchSimilarity without its pretrained weights."""

    def __init__(self, *args, **kwargs):
        super().__init__()

    def forward(self, *args, **kwargs):
        return torch.zeros(())


torchmetrics.image.lpip.LearnedPerceptualImagePatchSimilarity = NoLpips
