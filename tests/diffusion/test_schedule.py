"""Schedulers: the Karras spacing on the cosine schedule, and every sampler's loop runs to the end."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physmotion.diffusion.schedule import DiffusionConfig, karras_timesteps, sampling_scheduler


def test_diffusers_karras_on_cosine_repeats_timesteps() -> None:
    """The pitfall we work around: diffusers' own Karras sigmas on the cosine schedule repeat t=998."""
    from diffusers import DPMSolverMultistepScheduler

    s = DPMSolverMultistepScheduler(beta_schedule="squaredcos_cap_v2", prediction_type="sample",
                                    use_karras_sigmas=True)  # fmt: skip
    s.set_timesteps(10)
    assert len(set(s.timesteps.tolist())) < 10


@pytest.mark.parametrize("steps", [10, 20, 50])
def test_karras_timesteps_are_distinct_and_descending(steps: int) -> None:
    sched = sampling_scheduler("dpmpp", steps, DiffusionConfig())
    ts = sched.timesteps.tolist()
    assert ts == sorted(set(ts), reverse=True)
    assert len(ts) >= steps - 2 and ts[-1] <= 2
    # Karras et al.: sigma^(1/7) falls in equal steps (up to the rounding of t at the low-noise end)
    ac = sched.alphas_cumprod.numpy()
    root = [(((1 - ac[t]) / ac[t]) ** 0.5) ** (1 / 7) for t in ts[:-2]]
    diffs = np.diff(root)
    assert np.all(diffs < 0) and diffs.std() < 0.25 * abs(diffs.mean())


def test_karras_starts_at_sigma_max() -> None:
    sched = sampling_scheduler("ddim", 10, DiffusionConfig())
    ac = sched.alphas_cumprod.numpy()
    t0 = karras_timesteps(ac, 10)[0]
    sigma = ((1 - ac[t0]) / ac[t0]) ** 0.5
    assert 50 < sigma < 120


@pytest.mark.parametrize("name", ["ddpm", "ddim", "dpmpp"])
def test_plain_step_loop_runs_and_returns_x0(name: str) -> None:
    """Stepping on a constant x0 prediction must end at that x0, for every sampler."""
    sched = sampling_scheduler(name, 10, DiffusionConfig())
    target = torch.full((2, 8, 3), 0.7)
    x = torch.randn(2, 8, 3, generator=torch.Generator().manual_seed(0))
    for t in sched.timesteps:
        x = sched.step(target, t, x, generator=torch.Generator().manual_seed(1)).prev_sample
    assert torch.allclose(x, target, atol=2e-2 if name == "ddpm" else 1e-4)


def test_bad_sampler_and_steps() -> None:
    with pytest.raises(ValueError, match="unknown sampler"):
        sampling_scheduler("euler", 10, DiffusionConfig())
    with pytest.raises(ValueError, match="steps"):
        sampling_scheduler("ddim", 0, DiffusionConfig())
