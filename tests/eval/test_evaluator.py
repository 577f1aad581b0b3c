"""The evaluator network, its loss, its folder format and its training, on the bundled data."""

import copy
import json
from dataclasses import replace

import numpy as np
import pytest
import torch

from physmotion.data.dataset import load_items
from physmotion.errors import PhysmotionError, ShapeError
from physmotion.eval.evaluator import Evaluator, contrastive_loss


def _some_features(built_dir, n=5):
    return [it.features for it in load_items(built_dir, "val")[:n]]


def test_embeddings_are_unit_vectors_and_independent_of_the_batch(tiny_evaluator, built_dir):
    feats = _some_features(built_dir)
    assert len({len(f) for f in feats}) > 1  # different lengths: the batch is padded
    together = tiny_evaluator.encode_motions(feats)
    alone = np.concatenate([tiny_evaluator.encode_motions([f]) for f in feats])
    assert together.shape == (5, tiny_evaluator.config.latent_dim)
    np.testing.assert_allclose(np.linalg.norm(together, axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(together, alone, atol=1e-5)
    texts = tiny_evaluator.encode_texts(["a person walks forward", "run", "a person walks forward"])
    np.testing.assert_allclose(texts[0], texts[2])
    assert not np.allclose(texts[0], texts[1])


def test_save_load_round_trip(tiny_evaluator, tmp_path, built_dir):
    tiny_evaluator.save(tmp_path / "copy")
    again = Evaluator.load(tmp_path / "copy")
    feats = _some_features(built_dir, 3)
    np.testing.assert_array_equal(again.encode_motions(feats), tiny_evaluator.encode_motions(feats))
    assert again.info["licence_tags"] == tiny_evaluator.info["licence_tags"]


def test_training_records_losses_val_and_test_retrieval(tiny_evaluator_dir):
    losses = np.loadtxt(tiny_evaluator_dir / "loss.csv", delimiter=",", skiprows=1)
    assert losses.shape == (3, 2) and np.all(np.isfinite(losses[:, 1]))
    assert losses[-1, 1] < losses[0, 1]  # contrastive loss falls over 3 epochs
    info = json.loads((tiny_evaluator_dir / "config.json").read_text())["info"]
    assert 1 <= info["best_epoch"] <= 3 and len(info["val_history"]) == 3
    test = info["test_retrieval"]
    for key in ("own_captions", "shuffled_captions"):
        r1, r3 = test[key]["R@1"]["mean"], test[key]["R@3"]["mean"]
        assert 0.0 <= r1 <= r3 <= 1.0


def test_training_leaves_the_callers_config_alone(built_dir, tmp_path):
    """The run takes the text and feature widths from its encoder and data in a copy: the config passed
    in is the same after the run, while the saved evaluator holds what was used."""
    from physmotion.eval.train import train_evaluator
    from tests.conftest import tiny_evaluator_config

    cfg = tiny_evaluator_config(built_dir, tmp_path / "evaluator", epochs=1)
    cfg = replace(cfg, evaluator=replace(cfg.evaluator, text_dim=1, feature_dim=1))
    before = copy.deepcopy(cfg)
    result = train_evaluator(cfg, progress=False)
    assert cfg == before
    assert (result.evaluator.config.text_dim, result.evaluator.config.feature_dim) == (384, 263)
    again = Evaluator.load(tmp_path / "evaluator")
    assert (again.config.text_dim, again.config.feature_dim) == (384, 263)


def test_filtered_negatives_leave_the_softmax():
    # Two pairs whose captions are the same: each text is as close to the other motion as to its own.
    text = torch.nn.functional.normalize(torch.tensor([[1.0, 0.0], [1.0, 0.0]]), dim=1)
    motion = text.clone()
    same = torch.ones(2, 2)
    filtered = contrastive_loss(text, motion, same, temperature=0.1, threshold=0.8)
    unfiltered = contrastive_loss(text, motion, torch.eye(2), temperature=0.1, threshold=0.8)
    assert filtered.item() == pytest.approx(0.0, abs=1e-6)  # only the positive is left
    assert unfiltered.item() == pytest.approx(np.log(2), rel=1e-5)  # two equal logits


def test_bad_motion_input_is_a_clear_error(tiny_evaluator):
    good = np.zeros((40, 263), np.float32)
    with pytest.raises(ShapeError, match="NaN"):
        tiny_evaluator.encode_motions([np.full((40, 263), np.nan, np.float32)])
    with pytest.raises(ShapeError, match="263"):
        tiny_evaluator.encode_motions([good[:, :200]])
    with pytest.raises(PhysmotionError, match="no motion"):
        tiny_evaluator.encode_motions([])
    with pytest.raises(PhysmotionError, match="empty"):
        tiny_evaluator.encode_texts([""])


def test_missing_or_broken_folder(tmp_path):
    with pytest.raises(PhysmotionError, match="no model checkpoint"):
        Evaluator.load(tmp_path)
    (tmp_path / "model.safetensors").write_bytes(b"not a safetensors file")
    (tmp_path / "config.json").write_text("{}")
    with pytest.raises(PhysmotionError, match="unreadable"):
        Evaluator.load(tmp_path)
