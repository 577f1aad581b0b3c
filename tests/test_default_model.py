"""The shipped default model: it loads offline, the text steers the motion, and PhysDiff makes it more
physical. Real sampling with the committed weights (no mocks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.model import MotionDiffusion
from physmotion.generate import GenerateConfig, generate

SEEDS = 3


@pytest.fixture(scope="module")
def model() -> MotionDiffusion:
    return MotionDiffusion.load()


@pytest.fixture(scope="module")
def stats(model: MotionDiffusion) -> dict[str, dict[str, float]]:
    """Per prompt, means over seeds of: root speed (m/s), vertical root range (m), highest foot joint
    (m), peak foot speed relative to the pelvis (m/s) and the highest wrist above the pelvis (m)."""
    prompts = ["walk", "run", "jump", "kick", "wave"]
    res = generate(prompts, GenerateConfig(physics="none", num=SEEDS, seed=0), model)
    out = {}
    for i, p in enumerate(prompts):
        js = np.stack([m.joints for m in res.motions[SEEDS * i : SEEDS * (i + 1)]])
        root = js[:, :, 0]
        feet_rel = js[:, :, [7, 8, 10, 11]] - js[:, :, [0]]
        foot_speed = np.linalg.norm(np.diff(feet_rel, axis=1), axis=-1) * 20  # (seeds, T-1, 4), m/s
        out[p] = {
            "speed": float(np.linalg.norm(np.diff(root[..., [0, 2]], axis=1), axis=-1).mean() * 20),
            "vertical": float(np.ptp(root[..., 1], axis=1).mean()),
            "foot_high": float(js[:, :, [7, 8, 10, 11], 1].max(axis=(1, 2)).mean()),
            "foot_speed": float(foot_speed.max(axis=(1, 2)).mean()),
            "wrist_over_pelvis": float((js[:, :, [20, 21], 1] - js[:, :, [0], 1]).max(axis=(1, 2)).mean()),
        }
    return out


def test_default_model_card_and_licence(model: MotionDiffusion) -> None:
    from physmotion.diffusion.model import DEFAULT_MODEL_DIR

    card = (DEFAULT_MODEL_DIR / "README.md").read_text()
    assert "CC-BY-NC" in card and model.licence_tag == "NC"
    assert sum(p.stat().st_size for p in DEFAULT_MODEL_DIR.iterdir()) < 60e6


@pytest.mark.slow  # the shipped model, 5 prompts x 3 seeds x 6 s (about 90 s); tests/test_pins.py pins it fast
def test_run_is_faster_and_bouncier_than_walk(stats) -> None:
    assert stats["run"]["speed"] > 1.5 * stats["walk"]["speed"]
    assert stats["walk"]["speed"] > 0.5  # walking goes somewhere
    assert stats["run"]["vertical"] > 2 * stats["walk"]["vertical"]
    assert stats["run"]["foot_high"] > stats["walk"]["foot_high"] + 0.05
    assert stats["run"]["foot_speed"] > 2 * stats["walk"]["foot_speed"]


@pytest.mark.slow  # the shipped model, 5 prompts x 3 seeds x 6 s (about 90 s); tests/test_pins.py pins it fast
def test_jump_moves_the_root_up_and_down(stats) -> None:
    assert stats["jump"]["vertical"] > 2 * stats["walk"]["vertical"]
    assert stats["jump"]["foot_high"] > stats["walk"]["foot_high"]  # the feet leave the floor


@pytest.mark.slow  # the shipped model, 5 prompts x 3 seeds x 6 s (about 90 s); tests/test_pins.py pins it fast
def test_kick_lifts_a_foot_fast(stats) -> None:
    assert stats["kick"]["foot_high"] > stats["walk"]["foot_high"] + 0.1
    assert stats["kick"]["foot_speed"] > 1.5 * stats["walk"]["foot_speed"]


@pytest.mark.slow  # the shipped model, 5 prompts x 3 seeds x 6 s (about 90 s); tests/test_pins.py pins it fast
def test_wave_raises_a_hand(stats) -> None:
    assert stats["wave"]["wrist_over_pelvis"] > stats["walk"]["wrist_over_pelvis"] + 0.15


@pytest.mark.slow  # the shipped model, 5 prompts x 3 seeds x 6 s (about 90 s); tests/test_pins.py pins it fast
def test_standing_actions_stay_in_place(stats) -> None:
    for p in ("wave", "kick"):
        assert stats[p]["speed"] < 0.5 * stats["walk"]["speed"], p


@pytest.mark.slow
def test_physics_modes_match_the_recorded_bench(model: MotionDiffusion) -> None:
    """32 prompts, 6 s, seed 0, every mode of experiments/physdiff_quality.py, against seed 0 of
    results/physdiff_quality.json, whose three-seed means the README and the model card quote
    (tests/test_results.py). Generation is deterministic; the margin allows another CPU's rounding in
    the simulation. PhysDiff must beat the grounded baseline and post-processing, not only ``none``."""
    from experiments.physdiff_quality import compare_modes
    from experiments.prompts import PHYSICS_PROMPTS

    recorded = json.loads((Path(__file__).parents[1] / "results" / "physdiff_quality.json").read_text())
    assert recorded["meta"]["seeds"][0] == 0 and recorded["meta"]["prompts"] == len(PHYSICS_PROMPTS)
    expected = recorded["runs"][0]
    res = compare_modes(model, PHYSICS_PROMPTS, list(expected))
    # Four chained projections, each with resets, amplify rounding: post:4 read 11.46 mm on the AVX2 CPU
    # that recorded the bench, 10.02 and 9.95 mm in two runs on an AVX-512 one (a pytest session and a
    # script), where the other modes agreed to 0.5 %.
    margin = {"post:4": 0.25}
    for mode, row in expected.items():
        assert res[mode]["phys_err"] == pytest.approx(row["phys_err"], rel=margin.get(mode, 0.1)), mode
    err = {mode: row["phys_err"] for mode, row in res.items()}
    physdiff = err["physdiff:end:4,space:1"]
    assert physdiff < err["post:4"] and physdiff < err["none+floor"] < err["none"]
