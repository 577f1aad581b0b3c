"""Our DPM-Solver++ (``schedule.DPMSolverPP``, the default sampler, no diffusers import) steps as diffusers'
DPMSolverMultistepScheduler configured as ``sampling_scheduler`` did before it, bit for bit."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from physmotion.diffusion.schedule import DiffusionConfig, DPMSolverPP, karras_timesteps, sampling_scheduler


@pytest.mark.parametrize("beta_schedule", ["squaredcos_cap_v2", "linear"])
@pytest.mark.parametrize("steps", [1, 2, 7, 10, 20, 50])
def test_same_as_diffusers(beta_schedule: str, steps: int) -> None:
    from diffusers import DPMSolverMultistepScheduler

    ref = DPMSolverMultistepScheduler(num_train_timesteps=1000, beta_schedule=beta_schedule, prediction_type="sample",
                                      algorithm_type="dpmsolver++", solver_order=2, final_sigmas_type="zero")  # fmt: skip
    ref.set_timesteps(timesteps=karras_timesteps(ref.alphas_cumprod.numpy(), steps))
    ref.set_begin_index(0)
    ours = sampling_scheduler("dpmpp", steps, DiffusionConfig(beta_schedule=beta_schedule))
    assert isinstance(ours, DPMSolverPP)
    assert torch.equal(ref.timesteps, ours.timesteps) and torch.equal(ref.sigmas, ours.sigmas)
    x = y = torch.randn(2, 5, 3, generator=torch.Generator().manual_seed(0))
    for t in ref.timesteps:
        x = ref.step(torch.tanh(1.3 * x), t, x).prev_sample
        y = ours.step(torch.tanh(1.3 * y), t, y).prev_sample
        assert torch.equal(x, y)


def test_default_sampling_does_not_import_diffusers() -> None:
    code = ("import sys\nfrom physmotion.diffusion.samplers import SamplerConfig\n"
            "from physmotion.diffusion.schedule import DiffusionConfig, sampling_scheduler\n"
            "c = SamplerConfig()\nsampling_scheduler(c.sampler, c.steps, DiffusionConfig())\n"
            "print(c.sampler, 'diffusers' in sys.modules)")  # fmt: skip
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert res.stdout.strip() == "dpmpp False"
