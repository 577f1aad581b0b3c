"""The MDM-style denoiser: a transformer encoder that predicts the clean motion x0.

Follows MDM (GuyTevet/motion-diffusion-model, model/mdm.py, ``arch='trans_enc'``): a linear input
projection of the 263-d frames, sinusoidal positions, a timestep embedding (sinusoid -> MLP) to which
the projected sentence vector is added to make one condition token, and a stack of pre-norm encoder
layers over [condition token, frames]; the output projection of the frame tokens is x0. Two changes:
the caption's per-token features are appended as extra tokens (MDM only sees CLIP's pooled vector; our
MiniLM is a weaker sentence encoder, and the words carry the verb), and padded frames are masked out of
attention, so one batch can mix lengths.

Classifier-free guidance: ``drop_text`` (B,) bool replaces a caption by the null condition (no text
tokens, zero sentence vector), as MDM's ``cond_mask_prob`` does.

The config and the time/text condition live in :mod:`physmotion.nets.backbone`, which the UNet
(:mod:`physmotion.nets.unet`) shares; :func:`build_denoiser` builds either backbone.
"""

from __future__ import annotations

import math

import torch
from torch import nn

from physmotion.nets.backbone import DenoiserConfig, TimeTextCondition
from physmotion.nets.unet import UNetDenoiser
from physmotion.text.encoder import TextFeatures

__all__ = ["DenoiserConfig", "TransformerDenoiser", "build_denoiser", "positional_encoding"]


def positional_encoding(length: int, dim: int) -> torch.Tensor:
    """The fixed sinusoidal table (length, dim) of 'Attention is all you need' (MDM's PositionalEncoding)."""
    pos = torch.arange(length, dtype=torch.float32)[:, None]
    div = torch.exp(torch.arange(0, dim, 2, dtype=torch.float32) * (-math.log(10000.0) / dim))
    table = torch.zeros(length, dim)
    table[:, 0::2], table[:, 1::2] = torch.sin(pos * div), torch.cos(pos * div)
    return table


class TransformerDenoiser(nn.Module):
    """x0 = f(x_t, t, text): x (B, T, D) normalised features, mask (B, T) True on real frames."""

    def __init__(self, config: DenoiserConfig) -> None:
        super().__init__()
        self.config = c = config
        self.cond = TimeTextCondition(c.d_model, c.text_dim)
        self.in_proj = nn.Linear(c.feature_dim, c.d_model)
        self.register_buffer("pos", positional_encoding(c.max_frames, c.d_model), persistent=False)
        self.type_emb = nn.Parameter(torch.zeros(3, c.d_model))  # condition / word / frame tokens
        layer = nn.TransformerEncoderLayer(c.d_model, c.heads, c.ff_mult * c.d_model, c.dropout,
                                           activation="gelu", batch_first=True, norm_first=True)  # fmt: skip
        self.encoder = nn.TransformerEncoder(layer, c.layers, enable_nested_tensor=False)
        self.out_norm = nn.LayerNorm(c.d_model)
        self.out_proj = nn.Linear(c.d_model, c.feature_dim)

    def forward(
        self,
        x: torch.Tensor,
        t: torch.Tensor,
        text: TextFeatures,
        mask: torch.Tensor,
        drop_text: torch.Tensor | None = None,
    ) -> torch.Tensor:
        frames = x.shape[1]
        if frames > self.config.max_frames:
            raise ValueError(f"{frames} frames is more than this model's {self.config.max_frames}")
        cond, words, word_mask = self.cond(t, text, drop_text)
        h = self.in_proj(x) + self.pos[:frames] + self.type_emb[2]
        seq = torch.cat([(cond + self.type_emb[0])[:, None], words + self.type_emb[1], h], dim=1)
        valid = torch.cat([torch.ones_like(mask[:, :1]), word_mask, mask], dim=1)
        out = self.encoder(seq, src_key_padding_mask=~valid)
        return self.out_proj(self.out_norm(out[:, -frames:]))


def build_denoiser(config: DenoiserConfig) -> nn.Module:
    """The denoiser network named by ``config.arch``."""
    if config.arch == "transformer":
        return TransformerDenoiser(config)
    if config.arch == "unet":
        return UNetDenoiser(config)
    if config.arch == "biomo":
        from physmotion.nets.physnet import BioMoDenoiser

        return BioMoDenoiser(config)
    raise ValueError(f"unknown denoiser architecture {config.arch!r} (transformer, unet or biomo)")
