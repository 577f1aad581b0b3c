"""What both denoiser backbones share: their config and the timestep + caption condition.

:mod:`physmotion.nets.denoiser` (MDM's transformer, and ``build_denoiser``) and
:mod:`physmotion.nets.unet` (BioMoDiffuse's 1D UNet) both build on this module; the UNet never
imports the transformer's module.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import torch
from torch import nn

from physmotion.conventions import MAX_FRAMES
from physmotion.features.humanml3d import FEATURE_DIM
from physmotion.text.encoder import MINILM_DIM, TextFeatures


@dataclass
class DenoiserConfig:
    """Shape of a denoiser; stored in every checkpoint."""

    arch: str = "transformer"  # "transformer" (MDM), "unet" (BioMoDiffuse's 1D UNet) or "biomo" (UNet + physics)
    feature_dim: int = FEATURE_DIM
    text_dim: int = MINILM_DIM
    d_model: int = 256
    layers: int = 4
    heads: int = 4
    ff_mult: int = 4
    dropout: float = 0.1
    max_frames: int = MAX_FRAMES
    phys_hidden: int = 128  # "biomo": width of the physical network (physmotion.nets.physnet)

    def to_dict(self) -> dict:
        return asdict(self)


def timestep_embedding(t: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """Sinusoidal embedding of diffusion timesteps t (B,) -> (B, dim), as in DDPM/MDM."""
    half = dim // 2
    freqs = torch.exp(-math.log(max_period) * torch.arange(half, device=t.device, dtype=torch.float32) / half)
    args = t.float()[:, None] * freqs[None]
    return torch.cat([torch.cos(args), torch.sin(args)], dim=-1)


class TimeTextCondition(nn.Module):
    """Timestep + sentence vector -> one d-dim condition vector; caption tokens -> d-dim tokens."""

    def __init__(self, d_model: int, text_dim: int) -> None:
        super().__init__()
        self.d_model = d_model
        self.time_mlp = nn.Sequential(nn.Linear(d_model, d_model), nn.SiLU(), nn.Linear(d_model, d_model))
        self.pooled_proj = nn.Linear(text_dim, d_model)
        self.token_proj = nn.Linear(text_dim, d_model)

    def forward(
        self, t: torch.Tensor, text: TextFeatures, drop_text: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Returns cond (B, d), tokens (B, L, d), token mask (B, L) with dropped captions masked out."""
        keep = torch.ones(len(t), dtype=torch.bool, device=t.device) if drop_text is None else ~drop_text
        cond = self.time_mlp(timestep_embedding(t, self.d_model))
        cond = cond + self.pooled_proj(text.pooled) * keep[:, None]
        tokens = self.token_proj(text.tokens) * keep[:, None, None]
        return cond, tokens, text.mask & keep[:, None]
