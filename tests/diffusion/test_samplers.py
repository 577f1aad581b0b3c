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


# --- BioMoDiffuse (arch "biomo"): physics guidance, speed, the dpmpp-sde sampler, refusals ---

import copy
import math

from physmotion.diffusion.samplers import default_sampler, guided_x0
from physmotion.text.encoder import load_text_encoder

_SDE = {"sampler": "dpmpp-sde", "steps": 4}


def _with_other_physics(model):
    """A copy of ``model`` whose physical network has other weights (the rest is untouched)."""
    other = copy.deepcopy(model)
    gen = torch.Generator().manual_seed(5)
    with torch.no_grad():
        for p in other.net.physics.parameters():
            p.add_(torch.randn(p.shape, generator=gen) * 0.5)
    return other


def test_dpmpp_sde_same_seed_same_motion(tiny_model) -> None:
    cfg = SamplerConfig(sampler="dpmpp-sde", steps=8)
    a = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    b = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    c = sample(tiny_model, ["a person walks forward", "run"], [40, 48], cfg, seed=8)
    ode_cfg = SamplerConfig(sampler="dpmpp", steps=8)
    ode = sample(tiny_model, ["a person walks forward", "run"], [40, 48], ode_cfg, seed=7)
    assert a.shape == (2, 48, 263) and torch.isfinite(a).all()
    assert torch.equal(a, b) and not torch.allclose(a, c) and not torch.allclose(a, ode)
    assert torch.all(a[0, 40:] == 0)


def test_biomo_same_seed_same_motion(tiny_biomo) -> None:
    cfg = SamplerConfig(**_SDE, phys_scale=1.0)
    a = sample(tiny_biomo, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    b = sample(tiny_biomo, ["a person walks forward", "run"], [40, 48], cfg, seed=7)
    c = sample(tiny_biomo, ["a person walks forward", "run"], [40, 48], cfg, seed=8)
    assert a.shape == (2, 48, 329) and torch.isfinite(a).all()
    assert torch.equal(a, b) and not torch.allclose(a, c)
    assert torch.all(a[0, 40:] == 0)


def test_biomo_sample_does_not_depend_on_its_batch(tiny_biomo) -> None:
    """With a deterministic sampler (DDIM) and physics guidance, as the transformer's test above."""
    cfg = SamplerConfig(steps=4, phys_scale=2.0)
    alone = sample(tiny_biomo, ["a person walks forward"], [40], cfg, seed=3)
    batch = sample(tiny_biomo, ["a person walks forward", "a person waves"], [40, 40], cfg, seed=3)
    assert torch.allclose(alone[0], batch[0], atol=1e-4)


@pytest.mark.slow  # BioMoDiffuse sampling with the physical network: 10-50 s each on 2 cores
def test_default_sampler_follows_the_architecture(tiny_model, tiny_biomo) -> None:
    assert default_sampler(tiny_model) == SamplerConfig()
    bio = default_sampler(tiny_biomo)
    assert bio == SamplerConfig(sampler="dpmpp-sde", steps=10, cfg_scale=2.5, phys_scale=1.0, speed=1.0)
    bio.steps = 3  # a copy: the caller may change it
    assert default_sampler(tiny_biomo).steps == 10
    # sample() without a config uses the model's default
    a = sample(tiny_biomo, ["a person jumps"], [40], None, seed=2)
    b = sample(tiny_biomo, ["a person jumps"], [40], default_sampler(tiny_biomo), seed=2)
    c = sample(tiny_biomo, ["a person jumps"], [40], SamplerConfig(), seed=2)
    assert torch.equal(a, b) and not torch.allclose(a, c)


@pytest.mark.slow  # BioMoDiffuse sampling with the physical network: 10-50 s each on 2 cores
def test_physics_weight_zero_is_the_model_without_its_physical_network(tiny_biomo, monkeypatch) -> None:
    """w = 0: other physical-network weights give the same motion, and the network is never run."""
    cfg = SamplerConfig(**_SDE, phys_scale=0.0)
    other = _with_other_physics(tiny_biomo)
    a = sample(tiny_biomo, ["a person walks forward"], [40], cfg, seed=1)
    b = sample(other, ["a person walks forward"], [40], cfg, seed=1)
    assert torch.equal(a, b)
    # the changed weights matter as soon as the physical network is used
    with_phys = SamplerConfig(**_SDE, phys_scale=1.0)
    assert not torch.allclose(sample(tiny_biomo, ["a person walks forward"], [40], with_phys, seed=1),
                              sample(other, ["a person walks forward"], [40], with_phys, seed=1))  # fmt: skip

    def refuse(*args, **kwargs):
        raise AssertionError("the physical network ran")

    monkeypatch.setattr(other.net.physics, "forward", refuse)
    assert torch.equal(sample(other, ["a person walks forward"], [40], cfg, seed=1), a)
    fast = SamplerConfig(**_SDE, phys_scale=0.0, speed=3.0)  # speed scales a network that does not run
    assert torch.equal(sample(other, ["a person walks forward"], [40], fast, seed=1), a)
    with pytest.raises(AssertionError, match="physical network ran"):
        sample(other, ["a person walks forward"], [40], with_phys, seed=1)


@pytest.mark.slow  # BioMoDiffuse sampling with the physical network: 10-50 s each on 2 cores
def test_physics_weight_and_speed_change_the_motion(tiny_biomo) -> None:
    def run(**kw) -> torch.Tensor:
        return sample(tiny_biomo, ["a person runs"], [40], SamplerConfig(**_SDE, **kw), seed=4)

    by_scale = {w: run(phys_scale=w) for w in (None, 0.0, 1.0, 2.0)}
    for i, a in enumerate(by_scale.values()):
        assert torch.isfinite(a).all()
        for b in list(by_scale.values())[i + 1 :]:
            assert not torch.allclose(a, b, atol=1e-4)
    assert not torch.allclose(run(phys_scale=None, speed=2.0), by_scale[None], atol=1e-4)
    assert not torch.allclose(run(phys_scale=1.0, speed=0.5), by_scale[1.0], atol=1e-4)
    assert torch.equal(run(phys_scale=1.0, speed=1.0), by_scale[1.0])


@pytest.mark.slow  # BioMoDiffuse sampling with the physical network: 10-50 s each on 2 cores
def test_guided_x0_composes_text_and_physics_guidance(tiny_biomo) -> None:
    """x0 = u_n + s (c_n - u_n) + w (c_p - c_n), from the denoiser's passes run one by one."""
    net = tiny_biomo.net
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(2, 40, 329, generator=gen)
    t = torch.tensor([300, 800])
    text = load_text_encoder(tiny_biomo.text_encoder).encode(["a person walks", "a person waves"])
    mask = torch.arange(40)[None] < torch.tensor([40, 32])[:, None]
    yes, no = torch.zeros(2, dtype=torch.bool), torch.ones(2, dtype=torch.bool)

    def x0(drop_text, drop_phys, speed=1.0):
        with torch.no_grad():
            return net(x, t, text, mask, drop_text, drop_phys, speed=speed)

    s, w = 2.5, 1.5
    u_n, c_n, c_p = x0(no, no), x0(yes, no), x0(yes, yes)
    u_p = x0(no, yes)
    with torch.no_grad():
        got = guided_x0(net, x, t, text, mask, s, phys_scale=w)
        plain = guided_x0(net, x, t, text, mask, s, phys_scale=0.0)
        always = guided_x0(net, x, t, text, mask, s, phys_scale=None, speed=2.0)
        no_text = guided_x0(net, x, t, text, mask, s, with_text=False, phys_scale=w)
    tol = {"rtol": 1e-4, "atol": 1e-4}
    torch.testing.assert_close(got, u_n + s * (c_n - u_n) + w * (c_p - c_n), **tol)
    torch.testing.assert_close(plain, u_n + s * (c_n - u_n), **tol)
    torch.testing.assert_close(no_text, u_n + w * (u_p - u_n), **tol)
    u2, c2 = x0(no, yes, speed=2.0), x0(yes, yes, speed=2.0)
    torch.testing.assert_close(always, u2 + s * (c2 - u2), **tol)


@pytest.mark.parametrize("options", [{"phys_scale": 1.0}, {"phys_scale": 0.0}, {"speed": 2.0}, {"speed": 0.5}])
def test_biomo_options_refused_for_other_models(tiny_model, options) -> None:
    cfg = SamplerConfig(steps=2, **options)
    cfg.check()  # valid values: the model is what is wrong
    with pytest.raises(PhysmotionError, match="biomo") as err:
        sample(tiny_model, ["a person walks"], [40], cfg)
    assert "\n" not in str(err.value)
    with pytest.raises(PhysmotionError, match="transformer"):
        cfg.check_model(tiny_model)


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"phys_scale": -0.5}, "phys_scale"),
        ({"phys_scale": math.nan}, "phys_scale"),
        ({"phys_scale": math.inf}, "phys_scale"),
        ({"speed": 0.0}, "speed"),
        ({"speed": -1.0}, "speed"),
        ({"speed": math.nan}, "speed"),
        ({"speed": math.inf}, "speed"),
        ({"cfg_scale": math.nan}, "cfg_scale"),
    ],
)
def test_bad_physics_options(tiny_biomo, options, message) -> None:
    cfg = SamplerConfig(**_SDE, **options)
    with pytest.raises(PhysmotionError, match=message) as err:
        cfg.check()
    assert "\n" not in str(err.value)
    with pytest.raises(PhysmotionError, match=message):
        sample(tiny_biomo, ["a person walks"], [40], cfg)
