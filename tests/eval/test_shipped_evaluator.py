"""The shipped evaluator (physmotion/weights/evaluator) on the real test split of the build it was trained on
(mocap and HDM05): the issue's acceptance."""

import numpy as np
import pytest

from physmotion.data.dataset import load_items
from physmotion.eval.evaluator import DEFAULT_EVALUATOR_DIR, Evaluator
from physmotion.eval.retrieval import split_retrieval
from physmotion.eval.table import REAL, EvaluateConfig, evaluate
from physmotion.metrics.generation import fid


@pytest.fixture(scope="module")
def shipped() -> Evaluator:
    return Evaluator.load()


def test_shipped_files_and_card():
    names = {p.name for p in DEFAULT_EVALUATOR_DIR.iterdir()}
    assert {"model.safetensors", "config.json", "README.md", "loss.csv"} <= names
    card = (DEFAULT_EVALUATOR_DIR / "README.md").read_text()
    assert "NC" in card and "R@3" in card


def test_own_captions_retrieve_far_better_than_shuffled(shipped, built_all_dir):
    own = split_retrieval(shipped, built_all_dir, "test", repeats=10)
    shuffled = split_retrieval(shipped, built_all_dir, "test", repeats=10, shuffle_texts=True)
    # measured when shipped: own R@1 0.49 / R@3 0.76, shuffled 0.03 / 0.09 (20 draws of 32)
    assert own.r_at[2][0] > 0.6 and own.r_at[0][0] > 0.4
    assert own.r_at[2][0] > 5 * shuffled.r_at[2][0]
    assert own.mm_dist[0] < shuffled.mm_dist[0]


def test_real_test_data_against_itself_has_fid_near_zero(shipped, tiny_model, built_all_dir):
    table = evaluate(tiny_model, shipped, built_all_dir, EvaluateConfig(modes=(), repeats=3))
    real_fid = table.rows[REAL]["FID"][0]
    test = shipped.encode_motions([it.features for it in load_items(built_all_dir, "test")])
    train = shipped.encode_motions([it.features for it in load_items(built_all_dir, "train")])
    other = fid(test, train)  # different motions of the same collection
    assert real_fid < 0.02 * other, (real_fid, other)
    assert abs(fid(test, test)) < 1e-6  # exactly zero up to the matrix square root's rounding
    assert table.rows[REAL]["R@3"][0] > 0.6 and np.isfinite(table.rows[REAL]["Diversity"][0])
