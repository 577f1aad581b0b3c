"""Noise schedules and samplers' schedulers, from diffusers.

Training follows MDM: 1000 DDPM steps on the cosine schedule (``squaredcos_cap_v2``), and the network
predicts x0 (``prediction_type="sample"``), so every diffusers scheduler can step on its output as is.

Sampling schedulers:
- ``ddpm``: ancestral DDPM (``DDPMScheduler``) on a subset of steps;
- ``ddim``: ``DDIMScheduler`` with eta (0 = deterministic), the one PhysDiff's Algorithm 2 uses;
- ``dpmpp``: 2nd-order multistep DPM-Solver++ (``DPMSolverMultistepScheduler``) with Karras spacing;
- ``dpmpp-sde``: its SDE variant (``algorithm_type="sde-dpmsolver++"``), BioMoDiffuse's sampler (App. B).

The Karras pitfall: with the cosine schedule, diffusers' ``use_karras_sigmas=True`` starts from the
schedule's sigma_max of ~2e4, and the first half of the Karras sigmas all round to timestep 998 (at 10
steps: 998, 998, 998, 998, 997, 995, 983, 894, 259, 0); the repeated timesteps then break the scheduler's
step-index lookup and a plain ``for t in timesteps`` loop runs off the end. We instead compute the Karras
sigmas between the schedule's sigma_min and ``KARRAS_SIGMA_MAX`` (80, EDM's value, where the signal is
1.2% of the noise), map them to distinct integer timesteps, and hand those to the scheduler.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

SAMPLERS = ("ddpm", "ddim", "dpmpp", "dpmpp-sde")
KARRAS_SIGMA_MAX = 80.0
KARRAS_RHO = 7.0


@dataclass
class DiffusionConfig:
    """The forward process; stored in every checkpoint."""

    num_train_timesteps: int = 1000
    beta_schedule: str = "squaredcos_cap_v2"  # MDM's cosine schedule

    def to_dict(self) -> dict:
        return asdict(self)


def _common(cfg: DiffusionConfig) -> dict:
    return {"num_train_timesteps": cfg.num_train_timesteps, "beta_schedule": cfg.beta_schedule,
            "prediction_type": "sample"}  # fmt: skip


def training_scheduler(cfg: DiffusionConfig):
    """The DDPM forward process used to noise training samples (``add_noise``)."""
    from diffusers import DDPMScheduler

    return DDPMScheduler(**_common(cfg), clip_sample=False)


def karras_timesteps(alphas_cumprod: np.ndarray, steps: int, sigma_max: float = KARRAS_SIGMA_MAX) -> list[int]:
    """Distinct integer timesteps, descending, whose sigmas follow Karras et al.'s rho=7 spacing.

    alphas_cumprod: (N,) of the training schedule. sigma(t) = sqrt((1 - a_t) / a_t) is increasing in t,
    so each Karras sigma maps to a fractional t by interpolation; rounding can merge neighbours at the
    low-noise end, which are dropped (so fewer than ``steps`` may come back for tiny schedules).
    """
    sigmas_train = np.sqrt((1.0 - alphas_cumprod) / alphas_cumprod)
    lo, hi = float(sigmas_train[0]), min(float(sigmas_train[-1]), sigma_max)
    ramp = np.linspace(0.0, 1.0, steps)
    inv = hi ** (1 / KARRAS_RHO) + ramp * (lo ** (1 / KARRAS_RHO) - hi ** (1 / KARRAS_RHO))
    sigmas = inv**KARRAS_RHO
    t = np.interp(np.log(sigmas), np.log(sigmas_train), np.arange(len(sigmas_train)))
    out: list[int] = []
    for v in np.round(t).astype(int):
        if not out or v < out[-1]:
            out.append(int(v))
    return out


def sampling_scheduler(name: str, steps: int, cfg: DiffusionConfig):
    """A diffusers scheduler for ``name`` in :data:`SAMPLERS`, with its timesteps set for ``steps`` steps."""
    if name not in SAMPLERS:
        raise ValueError(f"unknown sampler {name!r}: choose one of {', '.join(SAMPLERS)}")
    if not 1 <= steps <= cfg.num_train_timesteps:
        raise ValueError(f"steps must be in 1..{cfg.num_train_timesteps}, got {steps}")
    if name == "ddim" and cfg.beta_schedule in _BETAS:
        return DDIM(cfg, steps)
    if name == "dpmpp" and cfg.beta_schedule in _BETAS:
        return DPMSolverPP(cfg, steps)
    from diffusers import DDIMScheduler, DDPMScheduler, DPMSolverMultistepScheduler

    if name == "ddpm":
        sched = DDPMScheduler(**_common(cfg), clip_sample=False, timestep_spacing="trailing")
        sched.set_timesteps(steps)
    elif name == "ddim":
        # set_alpha_to_one: the last step returns the predicted x0 itself (no leftover noise).
        sched = DDIMScheduler(**_common(cfg), clip_sample=False, set_alpha_to_one=True, timestep_spacing="trailing")
        sched.set_timesteps(steps)
    else:
        algorithm = "sde-dpmsolver++" if name == "dpmpp-sde" else "dpmsolver++"
        sched = DPMSolverMultistepScheduler(**_common(cfg), algorithm_type=algorithm, solver_order=2,
                                            final_sigmas_type="zero")  # fmt: skip
        sched.set_timesteps(timesteps=karras_timesteps(sched.alphas_cumprod.numpy(), steps))
        sched.set_begin_index(0)
    return sched


def _cosine_betas(n: int):
    """diffusers' ``betas_for_alpha_bar`` (``squaredcos_cap_v2``), the same float32 numbers."""
    import math

    import torch

    def alpha_bar(t: float) -> float:
        return math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2

    return torch.tensor([min(1 - alpha_bar((i + 1) / n) / alpha_bar(i / n), 0.999) for i in range(n)],
                        dtype=torch.float32)  # fmt: skip


def _linear_betas(n: int):
    import torch

    return torch.linspace(0.0001, 0.02, n, dtype=torch.float32)


_BETAS = {"squaredcos_cap_v2": _cosine_betas, "linear": _linear_betas}


class _Step:
    def __init__(self, prev_sample, pred_original_sample) -> None:
        self.prev_sample, self.pred_original_sample = prev_sample, pred_original_sample


class DDIM:
    """``sampling_scheduler("ddim")``: diffusers' ``DDIMScheduler`` as we configure it (x0 prediction, no
    clipping, ``set_alpha_to_one``, trailing spacing), the same float32 arithmetic in the same order,
    without importing diffusers (whose import pulls ``torch._dynamo``: 2-3 s of a cold start).
    ``tests/diffusion/test_schedule.py`` checks it against diffusers bit for bit."""

    init_noise_sigma = 1.0

    def __init__(self, cfg: DiffusionConfig, steps: int) -> None:
        import torch

        self.num_train_timesteps = cfg.num_train_timesteps
        self.betas = _BETAS[cfg.beta_schedule](cfg.num_train_timesteps)
        self.alphas = 1.0 - self.betas
        self.alphas_cumprod = torch.cumprod(self.alphas, dim=0)
        self.final_alpha_cumprod = torch.tensor(1.0)
        self.set_timesteps(steps)

    def set_timesteps(self, steps: int) -> None:
        import torch

        self.num_inference_steps = steps
        ratio = self.num_train_timesteps / steps
        timesteps = np.round(np.arange(self.num_train_timesteps, 0, -ratio)).astype(np.int64) - 1
        self.timesteps = torch.from_numpy(timesteps)

    def step(self, model_output, timestep, sample, eta: float = 0.0, generator=None, **_):
        import torch

        prev_timestep = timestep - self.num_train_timesteps // self.num_inference_steps
        alpha_prod_t = self.alphas_cumprod[timestep]
        alpha_prod_t_prev = self.alphas_cumprod[prev_timestep] if prev_timestep >= 0 else self.final_alpha_cumprod
        beta_prod_t = 1 - alpha_prod_t
        pred_original_sample = model_output
        pred_epsilon = (sample - alpha_prod_t ** (0.5) * pred_original_sample) / beta_prod_t ** (0.5)
        beta_prod_t_prev = 1 - alpha_prod_t_prev
        variance = (beta_prod_t_prev / beta_prod_t) * (1 - alpha_prod_t / alpha_prod_t_prev)
        std_dev_t = eta * variance ** (0.5)
        pred_sample_direction = (1 - alpha_prod_t_prev - std_dev_t**2) ** (0.5) * pred_epsilon
        prev_sample = alpha_prod_t_prev ** (0.5) * pred_original_sample + pred_sample_direction
        if eta > 0:
            noise = torch.randn(model_output.shape, generator=generator, device=model_output.device,
                                dtype=model_output.dtype)  # fmt: skip
            prev_sample = prev_sample + std_dev_t * noise
        return _Step(prev_sample, pred_original_sample)


class DPMSolverPP:
    """``sampling_scheduler("dpmpp")``: diffusers' ``DPMSolverMultistepScheduler`` as we configure it
    (DPM-Solver++ 2M, midpoint, x0 prediction, final sigma 0, first order at the first and last steps, our
    Karras timesteps), the same float32 arithmetic in the same order, without importing diffusers (the
    default sampler: its import would cost a cold start 2-3 s, as for :class:`DDIM`).
    ``tests/diffusion/test_dpmpp.py`` checks it against diffusers bit for bit."""

    init_noise_sigma = 1.0

    def __init__(self, cfg: DiffusionConfig, steps: int) -> None:
        import torch

        self.alphas_cumprod = torch.cumprod(1.0 - _BETAS[cfg.beta_schedule](cfg.num_train_timesteps), dim=0)
        timesteps = np.array(karras_timesteps(self.alphas_cumprod.numpy(), steps), dtype=np.int64)
        train_sigmas = (((1 - self.alphas_cumprod) / self.alphas_cumprod) ** 0.5).numpy()
        sigmas = np.interp(timesteps, np.arange(0, len(train_sigmas)), train_sigmas)
        self.sigmas = torch.from_numpy(np.concatenate([sigmas, [0]]).astype(np.float32))
        self.timesteps = torch.from_numpy(timesteps)
        self._outputs: list = [None, None]  # the model's x0 at the previous and the current step
        self._index = 0

    @staticmethod
    def _alpha_sigma(sigma):
        alpha = 1 / ((sigma**2 + 1) ** 0.5)
        return alpha, sigma * alpha

    def _lambda(self, k: int):
        """(alpha, sigma, log-SNR lambda) at position k of the sigmas."""
        import torch

        alpha, sigma = self._alpha_sigma(self.sigmas[k])
        return alpha, sigma, torch.log(alpha) - torch.log(sigma)

    def step(self, model_output, timestep, sample, generator=None, **_):
        import torch

        i = self._index
        self._outputs = [self._outputs[1], model_output]
        sample = sample.to(torch.float32)
        alpha_t, sigma_t, lambda_t = self._lambda(i + 1)
        _, sigma_s0, lambda_s0 = self._lambda(i)
        h = lambda_t - lambda_s0
        if i == 0 or i == len(self.timesteps) - 1:  # first order: no history yet, and the step to sigma 0
            prev = (sigma_t / sigma_s0) * sample - (alpha_t * (torch.exp(-h) - 1.0)) * model_output
        else:
            lambda_s1 = self._lambda(i - 1)[2]
            m0, m1 = self._outputs[-1], self._outputs[-2]
            r0 = (lambda_s0 - lambda_s1) / h
            d0, d1 = m0, (1.0 / r0) * (m0 - m1)
            prev = ((sigma_t / sigma_s0) * sample - (alpha_t * (torch.exp(-h) - 1.0)) * d0
                    - 0.5 * (alpha_t * (torch.exp(-h) - 1.0)) * d1)  # fmt: skip
        self._index += 1
        return _Step(prev.to(model_output.dtype), model_output)

