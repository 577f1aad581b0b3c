"""experiments/teacher_data.py and learn_from_search.py: prompts kept apart from evaluation, one evaluated row."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from experiments.learn_from_search import evaluate_row
from experiments.teacher_data import EVAL_PROMPTS, synthetic_prompts
from physmotion.imitator.clips import dataset_clips
from physmotion.physics.search import SearchConfig


def test_synthetic_prompts_are_train_captions_and_never_an_evaluation_prompt(small_built_dir: Path) -> None:
    from physmotion.morph.synth import train_captions

    picked = synthetic_prompts(str(small_built_dir), 5, seed=3)
    assert len(picked) == len(set(picked)) == min(5, len(train_captions(small_built_dir)))
    assert set(picked) <= set(train_captions(small_built_dir)) and not set(picked) & EVAL_PROMPTS
    assert synthetic_prompts(str(small_built_dir), 5, seed=3) == picked  # seeded


def test_a_row_is_measured_with_the_search_s_fall(small_built_dir: Path) -> None:
    clip = next(c for c in dataset_clips(small_built_dir, "train") if "_run_" in c.name and c.name[0] != "M")
    joints = clip.joints[:40]
    off = evaluate_row(("off", {"kind": "tracker", "hand": False}, joints, clip.fps))
    on = evaluate_row(("on", {"kind": "tracker", "hand": True}, joints, clip.fps))
    tiny = SearchConfig(candidates=4, rounds=1, elites=2, horizon=3, retries=0, rollback=0)
    searched = evaluate_row(("s", {"kind": "search", "config": tiny}, joints, clip.fps))
    assert on["survived"] == on["steps"] > off["survived"]  # the hand keeps the run up; without it, it falls
    assert off["steps"] == searched["steps"] == round(39 / 20 * 30) + 1 - 1  # control steps after the first
    for r in (off, on, searched):
        assert 0 <= r["survived"] <= r["steps"] and r["cpu"] > 0 and np.isfinite(r["mpjpe_rel"])
