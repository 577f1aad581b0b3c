"""Our DDIM (``schedule.DDIM``, no diffusers import) steps as diffusers' DDIMScheduler, bit for bit."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from physmotion.diffusion.schedule import DDIM, DiffusionConfig, sampling_scheduler


@pytest.mark.parametrize("beta_schedule", ["squaredcos_cap_v2", "linear"])
@pytest.mark.parametrize("steps", [7, 10, 50])
@pytest.mark.parametrize("eta", [0.0, 0.5])
def test_same_as_diffusers(beta_schedule: str, steps: int, eta: float) -> None:
    from diffusers import DDIMScheduler

    ref = DDIMScheduler(num_train_timesteps=1000, beta_schedule=beta_schedule, prediction_type="sample",
                        clip_sample=False, set_alpha_to_one=True, timestep_spacing="trailing")  # fmt: skip
    ref.set_timesteps(steps)
    ours = sampling_scheduler("ddim", steps, DiffusionConfig(beta_schedule=beta_schedule))
    assert isinstance(ours, DDIM)
    assert torch.equal(ref.timesteps, ours.timesteps) and torch.equal(ref.alphas_cumprod, ours.alphas_cumprod)
    x = y = torch.randn(2, 5, 3, generator=torch.Generator().manual_seed(0))
    ga, gb = torch.Generator().manual_seed(1), torch.Generator().manual_seed(1)
    for t in ref.timesteps:
        x = ref.step(torch.tanh(1.3 * x), t, x, eta=eta, generator=ga).prev_sample
        y = ours.step(torch.tanh(1.3 * y), t, y, eta=eta, generator=gb).prev_sample
        assert torch.equal(x, y)


def test_ddim_sampling_does_not_import_diffusers() -> None:
    code = ("import sys\nfrom physmotion.diffusion.schedule import DiffusionConfig, sampling_scheduler\n"
            "sampling_scheduler('ddim', 50, DiffusionConfig())\nprint('diffusers' in sys.modules)")  # fmt: skip
    res = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True
    )
    assert res.stdout.strip() == "False"
