"""Our text-motion evaluator: a contrastive retrieval model (TMR-style) that embeds captions and motions in
one space, for FID, R-Precision, MM-Dist, Diversity and MultiModality.

The HumanML3D evaluator (Guo et al. 2022) cannot be downloaded here, so we train our own the way TMR does
(Petrovich et al. 2023, github.com/Mathux/TMR, ``src/model/tmr.py`` and ``src/model/losses.py``):
- two transformer encoders, one over motion frames and one over the frozen text model's token features,
  each reading out a learned summary token (TMR's ACTOR-style encoders, without the VAE head);
- a symmetric InfoNCE loss at temperature 0.1 on cosine similarities;
- negatives whose captions are near-duplicates of the positive's (sentence similarity above 0.8) are left
  out of the softmax, as TMR filters them: our captions repeat ("walk" names many clips), and pushing apart
  two walks that share a caption would teach the model noise.
TMR also decodes motions from the latent (a reconstruction loss); we leave the decoder out: retrieval is
the only use here, and the contrastive loss alone is TMR's strongest ablation after the full model.

Like Guo's evaluator we drop the 4 foot-contact channels of the 263-d features: they are binary labels a
physics projection can flip without changing the motion, and an evaluator should judge the motion.

Embeddings are L2-normalised, so distances (MM-Dist, Diversity) lie in [0, 2]; they are not on the scale
of Guo's evaluator, whose numbers in papers cannot be compared with ours.

On disk an evaluator is a model folder (:mod:`physmotion.checkpoint`); the shipped one is
``physmotion/weights/evaluator``.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from physmotion.checkpoint import load_folder, save_folder
from physmotion.conventions import MAX_FRAMES
from physmotion.nets.denoiser import positional_encoding
from physmotion.errors import PhysmotionError, ShapeError
from physmotion.features.humanml3d import FEATURE_DIM
from physmotion.features.normalize import Normalizer
from physmotion.motion import joined_licence_tag
from physmotion.paths import WEIGHTS_DIR
from physmotion.text.encoder import DEFAULT_ENCODER, MINILM_DIM, TextFeatures, load_text_encoder

DEFAULT_EVALUATOR_DIR = WEIGHTS_DIR / "evaluator"
CONTACT_DIMS = 4  # the last 4 of the 263: foot contacts


@dataclass
class EvaluatorConfig:
    """Architecture of the evaluator. ``latent_dim`` is small on purpose: our test split has 58 motions,
    and FID's covariance from so few samples is only meaningful in a low-dimensional space."""

    feature_dim: int = FEATURE_DIM
    text_dim: int = MINILM_DIM
    text_encoder: str = DEFAULT_ENCODER
    latent_dim: int = 64
    d_model: int = 128
    motion_layers: int = 4
    text_layers: int = 2
    heads: int = 4
    ff_mult: int = 4
    dropout: float = 0.1
    max_frames: int = MAX_FRAMES
    drop_contacts: bool = True
    temperature: float = 0.1  # TMR's
    filter_threshold: float = 0.8  # TMR's: negatives with caption similarity above this are ignored

    def to_dict(self) -> dict:
        return asdict(self)

    @property
    def motion_in(self) -> int:
        return self.feature_dim - (CONTACT_DIMS if self.drop_contacts else 0)


class _Downsample(nn.Module):
    """Frames -> tokens at 1/4 the rate: two stride-2 convolutions, as Guo's ``MovementConvEncoder``
    (kernel 4, stride 2, padding 1). Positions past each motion's end are zeroed after each convolution,
    so a motion's tokens do not depend on how far its batch is padded."""

    def __init__(self, in_dim: int, d_model: int) -> None:
        super().__init__()
        self.convs = nn.ModuleList([nn.Conv1d(in_dim, d_model, 4, 2, 1), nn.Conv1d(d_model, d_model, 4, 2, 1)])

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        lengths = mask.sum(1)
        h = x.transpose(1, 2)
        for conv in self.convs:
            h = nn.functional.gelu(conv(h))
            lengths = torch.clamp(lengths // 2, min=1)
            mask = torch.arange(h.shape[-1], device=h.device)[None] < lengths[:, None]
            h = h * mask[:, None]
        return h.transpose(1, 2), mask


class _SequenceEncoder(nn.Module):
    """(B, L, in_dim) + mask (B, L) -> (B, latent) unit vectors, read from a learned summary token."""

    def __init__(self, in_dim: int, layers: int, c: EvaluatorConfig, max_len: int, downsample: bool) -> None:
        super().__init__()
        self.downsample = _Downsample(in_dim, c.d_model) if downsample else None
        self.in_proj = nn.Identity() if downsample else nn.Linear(in_dim, c.d_model)
        self.summary = nn.Parameter(torch.zeros(1, 1, c.d_model))
        self.register_buffer("pos", positional_encoding(max_len + 1, c.d_model), persistent=False)
        layer = nn.TransformerEncoderLayer(c.d_model, c.heads, c.ff_mult * c.d_model, c.dropout,
                                           activation="gelu", batch_first=True, norm_first=True)  # fmt: skip
        self.encoder = nn.TransformerEncoder(layer, layers, enable_nested_tensor=False)
        self.out = nn.Sequential(nn.LayerNorm(c.d_model), nn.Linear(c.d_model, c.latent_dim))

    def forward(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        if self.downsample is not None:
            x, mask = self.downsample(x, mask)
        h = torch.cat([self.summary.expand(len(x), -1, -1), self.in_proj(x)], dim=1)
        h = h + self.pos[: h.shape[1]]
        valid = torch.cat([torch.ones_like(mask[:, :1]), mask], dim=1)
        out = self.encoder(h, src_key_padding_mask=~valid)
        return nn.functional.normalize(self.out(out[:, 0]), dim=-1)


class EvaluatorNet(nn.Module):
    """The two encoders. Motions: normalised features (B, T, D) with the contacts already dropped."""

    def __init__(self, config: EvaluatorConfig) -> None:
        super().__init__()
        self.config = config
        self.motion = _SequenceEncoder(config.motion_in, config.motion_layers, config, config.max_frames, True)
        self.text = _SequenceEncoder(config.text_dim, config.text_layers, config, 64, False)

    def embed_motion(self, x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
        return self.motion(x, mask)

    def embed_text(self, text: TextFeatures) -> torch.Tensor:
        return self.text(text.tokens, text.mask)


def contrastive_loss(text: torch.Tensor, motion: torch.Tensor, caption_sim: torch.Tensor,
                     temperature: float, threshold: float) -> torch.Tensor:  # fmt: skip
    """TMR's filtered symmetric InfoNCE.

    text, motion: (B, L) unit embeddings of B pairs. caption_sim: (B, B) similarity of the captions'
    sentence vectors; off-diagonal pairs above ``threshold`` are not used as negatives.
    """
    logits = text @ motion.T / temperature
    same = (caption_sim > threshold) & ~torch.eye(len(text), dtype=torch.bool, device=text.device)
    logits = logits.masked_fill(same, float("-inf"))
    target = torch.arange(len(text), device=text.device)
    return 0.5 * (nn.functional.cross_entropy(logits, target) + nn.functional.cross_entropy(logits.T, target))


@dataclass
class Evaluator:
    """A trained evaluator: network, config, and the training data's feature Mean/Std."""

    net: EvaluatorNet
    config: EvaluatorConfig
    normalizer: Normalizer
    info: dict = field(default_factory=dict)  # data, licence tags, training summary, test retrieval

    def save(self, folder: str | Path) -> None:
        config = {"evaluator": self.config.to_dict(), "info": self.info}
        save_folder(folder, self.net, self.normalizer, config)

    @classmethod
    def load(cls, folder: str | Path | None = None, device: str = "cpu") -> Evaluator:
        """Load an evaluator folder (default: the shipped one)."""
        folder = Path(folder) if folder is not None else DEFAULT_EVALUATOR_DIR
        build = lambda c: EvaluatorNet(EvaluatorConfig(**c["evaluator"]))  # noqa: E731
        net, normalizer, config = load_folder(folder, build, device)
        return cls(net=net, config=net.config, normalizer=normalizer, info=config.get("info", {}))

    @property
    def device(self) -> torch.device:
        return next(self.net.parameters()).device

    def motion_batch(self, features: Sequence[np.ndarray]) -> tuple[torch.Tensor, torch.Tensor]:
        """Un-normalised feature arrays (T_i, 263) -> padded normalised input (B, T, D') and mask (B, T).

        Motions longer than the model's ``max_frames`` are cut to it; NaN/inf or a wrong width is an error.
        """
        c = self.config
        clips = []
        for f in features:
            f = np.asarray(f, dtype=np.float32)
            if f.ndim != 2 or f.shape[1] != c.feature_dim or len(f) < 2:
                raise ShapeError(f"evaluator input must be (T>=2, {c.feature_dim}) features, got {f.shape}")
            if not np.all(np.isfinite(f)):
                raise ShapeError("evaluator input has NaN or inf features")
            clips.append(self.normalizer.normalize(f[: c.max_frames])[:, : c.motion_in])
        width = max(len(f) for f in clips)
        x = torch.zeros(len(clips), width, c.motion_in)
        mask = torch.zeros(len(clips), width, dtype=torch.bool)
        for i, f in enumerate(clips):
            x[i, : len(f)], mask[i, : len(f)] = torch.from_numpy(f), True
        return x.to(self.device), mask.to(self.device)

    @torch.no_grad()
    def encode_motions(self, features: Sequence[np.ndarray], batch_size: int = 64) -> np.ndarray:
        """Embeddings (N, latent_dim) float64 of un-normalised 263-d feature arrays (T_i, 263)."""
        if len(features) == 0:
            raise PhysmotionError("no motion to encode")
        out = [self.net.embed_motion(*self.motion_batch(features[i : i + batch_size])).double().cpu()
               for i in range(0, len(features), batch_size)]  # fmt: skip
        return torch.cat(out).numpy()

    @torch.no_grad()
    def encode_texts(self, texts: Sequence[str], batch_size: int = 256) -> np.ndarray:
        """Embeddings (N, latent_dim) float64 of captions."""
        if len(texts) == 0:
            raise PhysmotionError("no text to encode")
        encoder = load_text_encoder(self.config.text_encoder)
        out = [self.net.embed_text(encoder.encode(texts[i : i + batch_size]).to(self.device)).double().cpu()
               for i in range(0, len(texts), batch_size)]  # fmt: skip
        return torch.cat(out).numpy()

    @property
    def licence_tag(self) -> str:
        """Every restriction of the training data's licences ("NC", "SA", or "NC,SA"), else "open"."""
        return joined_licence_tag(self.info.get("licence_tags", []))
