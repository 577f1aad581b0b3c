"""The sampling loop: reproducible under a seed, every sampler, guidance, and the x0 hook."""

from __future__ import annotations

import pytest
import torch

from physmotion.diffusion.samplers import SamplerConfig, initial_noise, sample
from physmotion.errors import PhysmotionError


@pytest.mark.parametrize("name", ["ddpm", "ddim", "dpmpp"])
def test_same_seed_same_motion(tiny_model, name: str) -> None:
    cfg = SamplerConfig(sampler=name, steps=8, eta=0.5 if name == "ddim" else 0.0)
    a = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    b = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    c = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=8)
    assert a.shape == (2, 48, 263) and torch.isfinite(a).all()
    assert torch.equal(a, b) and not torch.equal(a, c)
    assert torch.all(a[0, 40:] == 0)  # padding past the first motion's length


def test_a_sample_does_not_depend_on_its_batch(tiny_model) -> None:
    cfg = SamplerConfig(steps=6)
    alone = sample(tiny_model, ["a person walks forward"], [40], cfg, seed=3)
    batch = sample(tiny_model, ["a person walks forward", "a person waves"], [40, 40], cfg, seed=3)
    assert torch.allclose(alone[0], batch[0], atol=1e-4)
    assert torch.equal(initial_noise(2, 5, 3, seed=1)[0], initial_noise(1, 5, 3, seed=1)[0])


def test_guidance_scale_changes_the_result(tiny_model) -> None:
    a = sample(tiny_model, ["a person kicks"], [40], SamplerConfig(steps=6, cfg_scale=1.0), seed=0)
    b = sample(tiny_model, ["a person kicks"], [40], SamplerConfig(steps=6, cfg_scale=2.5), seed=0)
    assert not torch.allclose(a, b)


def test_hook_runs_at_the_scheduled_steps_and_replaces_x0(tiny_model) -> None:
    seen: list[int] = []

    def hook(x0: torch.Tensor, lengths: list[int]) -> torch.Tensor:
        seen.append(len(seen))
        assert lengths == [40]
        return torch.full_like(x0, 0.25)

    cfg = SamplerConfig(steps=10)
    x = sample(tiny_model, ["a person walks"], [40], cfg, seed=0, hook=hook, hook_steps=[9])
    assert len(seen) == 1
    # DDIM's last step returns x0 itself, so the hooked x0 comes out unchanged
    assert torch.allclose(x, torch.full_like(x, 0.25), atol=1e-5)


@pytest.mark.parametrize(
    ("texts", "lengths", "config", "message"),
    [
        ([], [], SamplerConfig(), "at least one"),
        (["walk"], [0], SamplerConfig(), "outside"),
        (["walk"], [500], SamplerConfig(), "outside"),
        (["walk"], [40], SamplerConfig(sampler="euler"), "unknown sampler"),
        (["walk"], [40], SamplerConfig(steps=0), "steps"),
        ([""], [40], SamplerConfig(), "empty"),
    ],
)
def test_bad_requests(tiny_model, texts, lengths, config, message) -> None:
    with pytest.raises(PhysmotionError, match=message):
        sample(tiny_model, texts, lengths, config)
