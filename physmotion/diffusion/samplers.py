"""The sampling loop: DDPM, DDIM (eta) or DPM-Solver++ on an x0-predicting denoiser, with classifier-free
guidance and an optional hook that replaces the predicted x0 at chosen steps (PhysDiff's Algorithm 2).

Classifier-free guidance as in MDM's ``ClassifierFreeSampleModel``: x0 = x0_uncond + s (x0_cond - x0_uncond),
both halves in one batched forward pass. Randomness: the starting noise of sample i comes from a generator
seeded by (seed, i), so a sample does not change with the batch it is drawn in; the stochastic steps of
DDPM and DDIM with eta > 0 draw from one generator seeded by ``seed``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.schedule import SAMPLERS, sampling_scheduler
from physmotion.errors import PhysmotionError
from physmotion.text.encoder import TextFeatures, load_text_encoder

# (x0 normalised (B, T, D), lengths (B,)) -> replacement x0 of the same shape
X0Hook = Callable[[torch.Tensor, list[int]], torch.Tensor]


@dataclass
class SamplerConfig:
    """How to sample: which scheduler, how many steps, how much guidance."""

    sampler: str = "ddim"
    steps: int = 50
    eta: float = 0.0  # DDIM only: 0 is deterministic DDIM, 1 is DDPM-like
    cfg_scale: float = 2.5

    def check(self) -> None:
        if self.sampler not in SAMPLERS:
            raise PhysmotionError(f"unknown sampler {self.sampler!r}: choose one of {', '.join(SAMPLERS)}")
        if not 1 <= self.steps <= 1000:
            raise PhysmotionError(f"steps must be between 1 and 1000, got {self.steps}")
        if not 0.0 <= self.eta <= 1.0:
            raise PhysmotionError(f"eta must be between 0 and 1, got {self.eta}")


def initial_noise(batch: int, frames: int, dim: int, seed: int) -> torch.Tensor:
    """x_T (batch, frames, dim): sample i's noise depends on (seed, i) only."""
    rows = []
    for i in range(batch):
        state = int(np.random.SeedSequence([seed, i]).generate_state(1)[0])
        rows.append(torch.randn(frames, dim, generator=torch.Generator().manual_seed(state)))
    return torch.stack(rows)


@torch.no_grad()
def sample(
    model: MotionDiffusion,
    texts: Sequence[str],
    lengths: Sequence[int],
    config: SamplerConfig | None = None,
    seed: int = 0,
    hook: X0Hook | None = None,
    hook_steps: Sequence[int] = (),
    on_step: Callable[[int, int], None] | None = None,
    noise: torch.Tensor | None = None,
) -> torch.Tensor:
    """Sample normalised features (B, max(lengths), D); frames past each length are padding.

    hook / hook_steps: at each loop index i in hook_steps (0 = first, steps-1 = last step), the predicted
    x0 is replaced by hook(x0, lengths) before the scheduler's update. on_step(i, steps) reports progress.
    noise: the unit-variance starting noise (B, max(lengths), D) to use instead of
    ``initial_noise(B, max(lengths), D, seed)`` (a caller whose samples must not depend on the batch
    they are drawn in, e.g. Morph's synthetic data, seeds each row itself).
    """
    cfg = config or SamplerConfig()
    cfg.check()
    if len(texts) != len(lengths) or not texts:
        raise PhysmotionError("give one length per text, and at least one text")
    max_frames = model.denoiser.max_frames
    for n in lengths:
        if not 1 <= n <= max_frames:
            raise PhysmotionError(f"length {n} frames is outside 1..{max_frames} for this model")
    device = next(model.net.parameters()).device
    encoder = load_text_encoder(model.text_encoder)
    text = encoder.encode(list(texts)).to(device)
    b, width = len(texts), max(lengths)
    mask = (torch.arange(width)[None] < torch.tensor(list(lengths))[:, None]).to(device)
    sched = sampling_scheduler(cfg.sampler, cfg.steps, model.diffusion)
    if noise is not None and tuple(noise.shape) != (b, width, model.denoiser.feature_dim):
        raise PhysmotionError(f"noise must be {(b, width, model.denoiser.feature_dim)}, got {tuple(noise.shape)}")
    x0_noise = initial_noise(b, width, model.denoiser.feature_dim, seed) if noise is None else noise.float()
    x = x0_noise.to(device) * sched.init_noise_sigma
    gen = torch.Generator().manual_seed(seed)
    both = _doubled(text)
    drop = torch.cat([torch.zeros(b, dtype=torch.bool), torch.ones(b, dtype=torch.bool)]).to(device)
    hook_at = set(hook_steps)
    timesteps = sched.timesteps
    for i, t in enumerate(timesteps):
        tt = torch.full((2 * b,), int(t), device=device)
        out = model.net(torch.cat([x, x]), tt, both, torch.cat([mask, mask]), drop)
        cond, uncond = out[:b], out[b:]
        x0 = uncond + cfg.cfg_scale * (cond - uncond)
        if hook is not None and i in hook_at:
            x0 = hook(x0, list(lengths)).to(x0)
        kwargs = {"eta": cfg.eta} if cfg.sampler == "ddim" else {}
        x = sched.step(x0, t, x, generator=gen, **kwargs).prev_sample
        x = x * mask[..., None]
        if on_step is not None:
            on_step(i + 1, len(timesteps))
    return x


def _doubled(text: TextFeatures) -> TextFeatures:
    """The text batch twice: conditional half, then the half that will be dropped (null condition)."""
    return TextFeatures(torch.cat([text.tokens, text.tokens]), torch.cat([text.mask, text.mask]),
                        torch.cat([text.pooled, text.pooled]))  # fmt: skip
