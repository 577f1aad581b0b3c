"""The bundled MiniLM encoder: offline, frozen, cached, per-token features plus a sentence vector."""

from __future__ import annotations

import pytest
import torch

from physmotion.errors import PhysmotionError
from physmotion.text.encoder import MINILM_DIM, load_text_encoder


@pytest.fixture(scope="module")
def encoder():
    return load_text_encoder("minilm")


def test_shapes_masks_and_pooling(encoder) -> None:
    out = encoder.encode(["a person walks forward", "run"])
    assert encoder.dim == MINILM_DIM == 384
    assert out.tokens.shape[0] == 2 and out.tokens.shape[2] == 384
    assert out.mask.dtype == torch.bool and out.mask[0].all()
    # "run" is [CLS] run [SEP]: three real tokens, zeros after them
    assert int(out.mask[1].sum()) == 3
    assert torch.all(out.tokens[1, 3:] == 0)
    assert torch.allclose(out.pooled.norm(dim=-1), torch.ones(2), atol=1e-5)


def test_same_text_same_features_and_cached(encoder) -> None:
    a = encoder.encode(["a person waves goodbye"])
    assert "a person waves goodbye" in encoder._cache
    b = encoder.encode(["a person waves goodbye", "a person kicks"])
    n = int(a.mask[0].sum())
    assert torch.equal(a.tokens[0, :n], b.tokens[0, :n])
    assert torch.equal(a.pooled[0], b.pooled[0])


def test_similar_captions_are_closer_than_different_ones(encoder) -> None:
    p = encoder.encode(["a person walks forward", "a person walks ahead", "a person waves goodbye"]).pooled
    assert float(p[0] @ p[1]) > float(p[0] @ p[2]) + 0.1


def test_frozen(encoder) -> None:
    assert not any(p.requires_grad for p in encoder.model.parameters())


@pytest.mark.parametrize("bad", ["", "   "])
def test_empty_text_is_an_error(encoder, bad: str) -> None:
    with pytest.raises(PhysmotionError, match="empty"):
        encoder.encode([bad])


def test_missing_model_folder_is_an_error(tmp_path) -> None:
    with pytest.raises(PhysmotionError, match="no such text-model folder"):
        load_text_encoder(str(tmp_path / "nope"))
