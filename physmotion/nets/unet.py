"""BioMoDiffuse's backbone: a conditional 1D UNet over time with cross-attention to the caption.

Shape after BioMoDiffuse's Table 7 ("Cond Unet1D": time MLP; down blocks of residual convs and cross
attention; two mid blocks; up blocks with transposed convs) and StableMoFusion's 1D UNet, whose design
BioMoDiffuse adopts. ``config.layers`` is the number of down/up levels (each halves/doubles time);
channels are ``d_model`` times (1, 1, 2, 2, ...). Like the transformer it predicts x0, and it takes the
same inputs, so either backbone plugs into training and the samplers.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from physmotion.nets.backbone import DenoiserConfig, TimeTextCondition
from physmotion.text.encoder import TextFeatures


def _groups(channels: int) -> int:
    return 8 if channels % 8 == 0 else 1


class _ResBlock(nn.Module):
    """GroupNorm-SiLU-Conv twice, with the condition added in between (FiLM shift), and a skip."""

    def __init__(self, cin: int, cout: int, d_cond: int, dropout: float) -> None:
        super().__init__()
        self.norm1, self.conv1 = nn.GroupNorm(_groups(cin), cin), nn.Conv1d(cin, cout, 5, padding=2)
        self.cond = nn.Linear(d_cond, 2 * cout)
        self.norm2, self.conv2 = nn.GroupNorm(_groups(cout), cout), nn.Conv1d(cout, cout, 5, padding=2)
        self.drop = nn.Dropout(dropout)
        self.skip = nn.Conv1d(cin, cout, 1) if cin != cout else nn.Identity()

    def forward(self, x: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        h = self.conv1(F.silu(self.norm1(x)))
        scale, shift = self.cond(F.silu(cond)).chunk(2, dim=-1)
        h = self.norm2(h) * (1 + scale[:, :, None]) + shift[:, :, None]
        return self.skip(x) + self.conv2(self.drop(F.silu(h)))


class _CrossAttention(nn.Module):
    """Frames attend to [condition token, caption tokens]."""

    def __init__(self, channels: int, d_model: int, heads: int) -> None:
        super().__init__()
        self.norm = nn.LayerNorm(channels)
        self.kv = nn.Linear(d_model, channels)
        self.attn = nn.MultiheadAttention(channels, heads, batch_first=True)

    def forward(self, x: torch.Tensor, context: torch.Tensor, context_mask: torch.Tensor) -> torch.Tensor:
        q = self.norm(x.transpose(1, 2))
        kv = self.kv(context)
        out, _ = self.attn(q, kv, kv, key_padding_mask=~context_mask, need_weights=False)
        return x + out.transpose(1, 2)


class UNetDenoiser(nn.Module):
    """x0 = f(x_t, t, text): x (B, T, D) normalised features, mask (B, T) True on real frames."""

    def __init__(self, config: DenoiserConfig, extra_channels: int = 0) -> None:
        """extra_channels: per-frame inputs concatenated to x (BioMoDiffuse's physical network output)."""
        super().__init__()
        self.config = c = config
        self.cond = TimeTextCondition(c.d_model, c.text_dim)
        chans = [c.d_model * (1 if i < 2 else 2) for i in range(c.layers + 1)]
        self.in_conv = nn.Conv1d(c.feature_dim + extra_channels, chans[0], 3, padding=1)
        self.down = nn.ModuleList()
        for i in range(c.layers):
            self.down.append(nn.ModuleList([
                _ResBlock(chans[i], chans[i + 1], c.d_model, c.dropout),
                _CrossAttention(chans[i + 1], c.d_model, c.heads),
                nn.Conv1d(chans[i + 1], chans[i + 1], 4, stride=2, padding=1),
            ]))  # fmt: skip
        mid = chans[-1]
        self.mid = nn.ModuleList([_ResBlock(mid, mid, c.d_model, c.dropout), _CrossAttention(mid, c.d_model, c.heads),
                                  _ResBlock(mid, mid, c.d_model, c.dropout)])  # fmt: skip
        self.up = nn.ModuleList()
        for i in reversed(range(c.layers)):
            self.up.append(nn.ModuleList([
                nn.ConvTranspose1d(chans[i + 1], chans[i + 1], 4, stride=2, padding=1),
                _ResBlock(2 * chans[i + 1], chans[i], c.d_model, c.dropout),
                _CrossAttention(chans[i], c.d_model, c.heads),
            ]))  # fmt: skip
        self.out = nn.Sequential(nn.GroupNorm(_groups(chans[0]), chans[0]), nn.SiLU(),
                                 nn.Conv1d(chans[0], c.feature_dim, 3, padding=1))  # fmt: skip

    def forward(
        self,
        x: torch.Tensor,
        t: torch.Tensor,
        text: TextFeatures,
        mask: torch.Tensor,
        drop_text: torch.Tensor | None = None,
        extra: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """extra: (B, T, extra_channels) inputs beside x, or None when the network has none."""
        frames = x.shape[1]
        if extra is not None:
            x = torch.cat([x, extra.to(x)], dim=-1)
        cond, words, word_mask = self.cond(t, text, drop_text)
        context = torch.cat([cond[:, None], words], dim=1)
        context_mask = torch.cat([torch.ones_like(word_mask[:, :1]), word_mask], dim=1)
        unit = 2 ** self.config.layers  # pad time to a multiple of the total downsampling
        width = -(-frames // unit) * unit
        m = F.pad(mask, (0, width - frames)).to(x.dtype)[:, None]
        h = self.in_conv(F.pad(x.transpose(1, 2), (0, width - frames)) * m)
        skips, masks = [], []
        for block, attn, downsample in self.down:
            h = attn(block(h, cond), context, context_mask) * m
            skips.append(h)
            masks.append(m)
            h, m = downsample(h), F.max_pool1d(m, 2)
        h = self.mid[2](self.mid[1](self.mid[0](h, cond), context, context_mask), cond) * m
        for (upsample, block, attn), skip, m in zip(self.up, reversed(skips), reversed(masks)):
            h = attn(block(torch.cat([upsample(h), skip], dim=1), cond), context, context_mask) * m
        return self.out(h)[:, :, :frames].transpose(1, 2)
