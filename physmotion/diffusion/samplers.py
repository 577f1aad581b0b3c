"""The sampling loop: DDPM, DDIM (eta) or DPM-Solver++ on an x0-predicting denoiser, with classifier-free
guidance and an optional hook that replaces the predicted x0 at chosen steps (PhysDiff's Algorithm 2).

Classifier-free guidance as in MDM's ``ClassifierFreeSampleModel``: x0 = x0_uncond + s (x0_cond - x0_uncond),
both halves in one batched forward pass. Randomness: the starting noise of sample i comes from a generator
seeded by (seed, i), so a sample does not change with the batch it is drawn in; the stochastic steps of
DDPM and DDIM with eta > 0 draw from one generator seeded by ``seed``.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np
import torch

from physmotion.conventions import CFG_SCALE_RANGE
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.schedule import SAMPLERS, sampling_scheduler
from physmotion.errors import PhysmotionError
from physmotion.text.encoder import TextFeatures, load_text_encoder

BIOMO_PHYS_SCALE = 1.0  # measured on the val split: docs/decisions/biomodiffuse.md, "physics guidance weight"

# (x0 normalised (B, T, D), lengths (B,)) -> replacement x0 of the same shape
X0Hook = Callable[[torch.Tensor, list[int]], torch.Tensor]


@dataclass
class SamplerConfig:
    """How to sample: which scheduler, how many steps, how much guidance.

    phys_scale and speed apply to BioMoDiffuse models (``arch="biomo"``) only: phys_scale None runs the
    physical network on every pass; a number w forms physics guidance (:func:`guided_x0`), 0 being the
    model without its physical network. speed scales the physical network's accelerations (Sec. 3.4).
    """

    # DPM-Solver++ (2M, Karras) at 10 steps: FID and R@3 within DDIM 50's intervals at a fifth of its
    # time (docs/decisions/sampling.md: "few-step sampling as the default")
    sampler: str = "dpmpp"
    steps: int = 10
    eta: float = 0.0  # DDIM only: 0 is deterministic DDIM, 1 is DDPM-like
    cfg_scale: float = 2.5
    phys_scale: float | None = None
    speed: float = 1.0

    def check(self) -> None:
        if self.sampler not in SAMPLERS:
            raise PhysmotionError(f"unknown sampler {self.sampler!r}: choose one of {', '.join(SAMPLERS)}")
        if not 1 <= self.steps <= 1000:
            raise PhysmotionError(f"steps must be between 1 and 1000, got {self.steps}")
        if not 0.0 <= self.eta <= 1.0:
            raise PhysmotionError(f"eta must be between 0 and 1, got {self.eta}")
        lo, hi = CFG_SCALE_RANGE
        if not (np.isfinite(self.cfg_scale) and lo <= self.cfg_scale <= hi):
            raise PhysmotionError(f"cfg_scale must be between {lo:g} and {hi:g} (MDM's default: 2.5), "
                                  f"got {self.cfg_scale:g}")  # fmt: skip
        if self.phys_scale is not None and not (np.isfinite(self.phys_scale) and self.phys_scale >= 0):
            raise PhysmotionError(f"phys_scale must be a number >= 0, got {self.phys_scale}")
        if not (np.isfinite(self.speed) and 0.0 < self.speed <= 4.0):
            raise PhysmotionError(f"speed must be in (0, 4], got {self.speed}")

    def check_model(self, model: MotionDiffusion) -> None:
        """Refuse the BioMoDiffuse-only options for a model without a physical network."""
        if model.denoiser.arch != "biomo" and (self.phys_scale is not None or self.speed != 1.0):
            raise PhysmotionError(f"--phys-scale and --speed need a BioMoDiffuse model (arch biomo); this one "
                                  f"is a {model.denoiser.arch}")  # fmt: skip


BIOMO_SAMPLER = SamplerConfig(sampler="dpmpp-sde", steps=10, cfg_scale=2.5, phys_scale=BIOMO_PHYS_SCALE)
"""BioMoDiffuse's sampling default (App. B): SDE DPM-Solver++ 2nd order, Karras sigmas, 10 steps, CFG 2.5,
with physics guidance (its weight: docs/decisions/biomodiffuse.md, "physics guidance weight")."""


def default_sampler(model: MotionDiffusion) -> SamplerConfig:
    """The sampler a model is meant to be used with: BioMoDiffuse's for ``biomo``, else DPM-Solver++ 10."""
    return replace(BIOMO_SAMPLER) if model.denoiser.arch == "biomo" else SamplerConfig()


def ddim_50() -> SamplerConfig:
    """DDIM with 50 steps and eta 0: PhysDiff's sampler, the default until the few-step one, and the sampler
    of every committed table measured before it (the experiments that reproduce them ask for it)."""
    return SamplerConfig(sampler="ddim", steps=50)


def guided_x0(
    net: torch.nn.Module,
    x: torch.Tensor,
    t: torch.Tensor,
    text: TextFeatures,
    mask: torch.Tensor,
    cfg_scale: float,
    *,
    with_text: bool = True,
    phys_scale: float | None = None,
    speed: float = 1.0,
) -> torch.Tensor:
    """The guided x0 prediction (B, T, D) at timesteps t (B,), all passes in one batch.

    Text (classifier-free): x0 = u + s (c - u), or u alone with ``with_text=False``. A BioMoDiffuse net
    with ``phys_scale`` w adds physics guidance, the two conditions composed as in compositional CFG
    (Liu et al. 2022; InstructPix2Pix's two-scale form): with u_n, c_n the predictions without the
    physical network and c_p with it, x0 = u_n + s (c_n - u_n) + w (c_p - c_n) (without text:
    u_n + w (u_p - u_n)). w = 0 is exactly the model without its physical network, w = 1 with s = 1
    the physics-conditioned prediction. ``phys_scale`` None: the physical network runs on every pass.
    """
    biomo = getattr(net, "physics", None) is not None
    b = len(x)
    guided = biomo and phys_scale is not None and phys_scale != 0.0
    no_phys = biomo and (phys_scale == 0.0 or guided)  # the base predictions run without physics
    # passes, named by their condition: c / u = with / without text, _p with the physical network
    passes = {"c": (False, no_phys)} if with_text else {}
    passes["u"] = (True, no_phys)
    if guided:
        passes["p"] = (not with_text, False)  # c_p, or u_p without text
    n = len(passes)
    drop_text = torch.tensor([v[0] for v in passes.values() for _ in range(b)], device=x.device)
    kwargs = {}
    if biomo:
        drop_phys = torch.tensor([v[1] for v in passes.values() for _ in range(b)], device=x.device)
        kwargs = {"drop_phys": drop_phys, "speed": speed}
    texts = TextFeatures(text.tokens.repeat(n, 1, 1), text.mask.repeat(n, 1), text.pooled.repeat(n, 1))
    pred = net(x.repeat(n, 1, 1), t.repeat(n), texts, mask.repeat(n, 1), drop_text, **kwargs)
    out = dict(zip(passes, pred.chunk(n)))
    x0 = out["u"] + cfg_scale * (out["c"] - out["u"]) if with_text else out["u"]
    if guided:
        x0 = x0 + phys_scale * (out["p"] - out["c" if with_text else "u"])
    return x0


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
    cfg = config or default_sampler(model)
    cfg.check()
    cfg.check_model(model)
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
    hook_at = set(hook_steps)
    timesteps = sched.timesteps
    for i, t in enumerate(timesteps):
        tt = torch.full((b,), int(t), device=device)
        x0 = guided_x0(model.net, x, tt, text, mask, cfg.cfg_scale, phys_scale=cfg.phys_scale,
                       speed=cfg.speed)  # fmt: skip
        if hook is not None and i in hook_at:
            x0 = hook(x0, list(lengths)).to(x0)
        kwargs = {"eta": cfg.eta} if cfg.sampler == "ddim" else {}
        x = sched.step(x0, t, x, generator=gen, **kwargs).prev_sample
        x = x * mask[..., None]
        if on_step is not None:
            on_step(i + 1, len(timesteps))
    return x
