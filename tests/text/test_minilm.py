"""Our MiniLM (tokenizers + a small torch BERT) against transformers' BertModel, and the on-disk cache of
prompt features: the same numbers bit for bit, a pure function of the text, atomic entries."""

from __future__ import annotations

import pytest
import torch

from physmotion.text.encoder import HFTextEncoder, MiniLMEncoder, cache_dir, minilm_path

TEXTS = ["a person walks forward", "someone jumps up and down twice then sits on the floor", "wave",
         "Ünïcode café  naïve", "x " * 100]  # fmt: skip


@pytest.fixture(scope="module")
def reference() -> HFTextEncoder:
    return HFTextEncoder(minilm_path(), name="minilm")


def test_same_features_as_transformers_bit_for_bit(reference, tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", str(tmp_path))
    ours = MiniLMEncoder(minilm_path())
    for text in TEXTS:  # one at a time: transformers pads a batch, and padding moves the last bits
        a, b = reference.encode([text]), ours.encode([text])
        assert (
            torch.equal(a.tokens, b.tokens)
            and torch.equal(a.pooled, b.pooled)
            and torch.equal(a.mask, b.mask)
        )
        assert ours.count_tokens(text) == reference.count_tokens(text)
    assert ours.count_tokens(TEXTS[-1]) > ours.max_tokens  # the long one was truncated as transformers does


def test_batched_network_matches_transformers(reference) -> None:
    """The network alone on a padded batch (the key mask path) gives transformers' hidden states."""
    from physmotion.text.minilm import load_minilm

    batch = reference.tokenizer(TEXTS[:3], padding=True, truncation=True, max_length=32, return_tensors="pt")
    with torch.no_grad():
        want = reference.model(
            input_ids=batch["input_ids"], attention_mask=batch["attention_mask"]
        ).last_hidden_state
        got = load_minilm(minilm_path())(batch["input_ids"], batch["attention_mask"])
    keep = batch["attention_mask"].bool()
    assert torch.equal(want[keep], got[keep])


def test_features_do_not_depend_on_the_batch(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", str(tmp_path))
    alone = MiniLMEncoder(minilm_path()).encode([TEXTS[0]])
    together = MiniLMEncoder(minilm_path()).encode([TEXTS[1], TEXTS[0], TEXTS[2]])
    n = int(alone.mask[0].sum())
    assert torch.equal(alone.tokens[0, :n], together.tokens[1, :n]) and torch.equal(
        alone.pooled[0], together.pooled[1]
    )


def test_disk_cache_is_used_and_loads_nothing(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", str(tmp_path))
    first = MiniLMEncoder(minilm_path())
    a = first.encode(TEXTS[:2])
    files = sorted(first.disk.glob("*.npz"))
    assert len(files) == 2 and first.disk.is_relative_to(tmp_path)
    assert not list(first.disk.glob(".tmp-*"))  # written through a temporary file, renamed
    second = MiniLMEncoder(minilm_path())
    b = second.encode(TEXTS[:2])
    assert second._model is None and second._tokenizer is None  # neither network nor tokenizer loaded
    assert torch.equal(a.tokens, b.tokens) and torch.equal(a.pooled, b.pooled)
    assert second.count_tokens(TEXTS[0]) == first.count_tokens(TEXTS[0]) and second._tokenizer is None


def test_damaged_entry_is_recomputed(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", str(tmp_path))
    enc = MiniLMEncoder(minilm_path())
    want = enc.encode([TEXTS[0]])
    (path,) = enc.disk.glob("*.npz")
    path.write_bytes(b"not an npz")
    again = MiniLMEncoder(minilm_path())
    assert torch.equal(again.encode([TEXTS[0]]).tokens, want.tokens)
    assert again._model is not None  # recomputed, and the entry rewritten
    assert MiniLMEncoder(minilm_path())._read(TEXTS[0])


def test_cache_dir_from_the_environment(tmp_path, monkeypatch) -> None:
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", str(tmp_path / "c"))
    assert cache_dir() == tmp_path / "c"
    monkeypatch.delenv("PHYSMOTION_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir() == tmp_path / "xdg" / "physmotion"
    monkeypatch.setenv("PHYSMOTION_CACHE_DIR", "off")
    assert cache_dir() is None
    enc = MiniLMEncoder(minilm_path())
    enc.encode([TEXTS[2]])
    assert enc.disk is None and not (tmp_path / "xdg").exists()
