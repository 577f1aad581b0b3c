"""The shipped default model: it loads offline, the text steers the motion, and PhysDiff makes it more
physical. Real sampling with the committed weights (no mocks)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.model import MotionDiffusion
from physmotion.generate import GenerateConfig, generate

SEEDS = 12  # at 6, the bare "kick" read 4.0 or 4.6 m/s of peak foot speed, at 12 and 16 5.9-8.3: a few samples
# decide it (docs/decisions/morph.md, "the Morph-tuned model becomes the default")


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
    # trained on Bandai Namco's CC BY-NC data and HDM05's CC BY-SA data: both restrictions carry
    assert "CC BY-NC 4.0" in card and "CC BY-SA 3.0" in card and model.licence_tag == "NC,SA"
    assert model.info["licence_tags"] == ["NC", "SA", "open"]
    assert sum(p.stat().st_size for p in DEFAULT_MODEL_DIR.iterdir()) < 60e6


@pytest.mark.slow  # the shipped model, 5 prompts x 12 seeds x 6 s (about 60 s); tests/test_pins.py pins it fast
def test_run_is_faster_and_bouncier_than_walk(stats) -> None:
    assert stats["run"]["speed"] > 1.5 * stats["walk"]["speed"]
    assert stats["walk"]["speed"] > 0.5  # walking goes somewhere
    assert stats["run"]["vertical"] > 2 * stats["walk"]["vertical"]
    assert stats["run"]["foot_high"] > stats["walk"]["foot_high"] + 0.05
    # captured runs' peak foot speed is 1.4x walks' (medians 4.1 and 3.0 m/s over data_build/all's train)
    assert stats["run"]["foot_speed"] > 1.3 * stats["walk"]["foot_speed"]


@pytest.mark.slow  # the shipped model, 5 prompts x 12 seeds x 6 s (about 60 s); tests/test_pins.py pins it fast
def test_jump_moves_the_root_up_and_down(stats) -> None:
    assert stats["jump"]["vertical"] > 2 * stats["walk"]["vertical"]
    assert stats["jump"]["foot_high"] > stats["walk"]["foot_high"]  # the feet leave the floor


@pytest.mark.slow  # the shipped model, 5 prompts x 12 seeds x 6 s (about 60 s); tests/test_pins.py pins it fast
def test_kick_lifts_a_foot_fast(stats) -> None:
    # The bare label "kick" lifts a foot higher than walking on the mean (measured: 0.59 against 0.20 m),
    # though not in every sample; HDM05's kick captions lift it over the knees (test_new_verbs_do_what_they_say).
    assert stats["kick"]["foot_high"] > stats["walk"]["foot_high"]
    # captured kicks reach 2.3x walks' peak foot speed (medians 6.9 and 3.0 m/s); the default measured 2.6x,
    # the base model 1.8x
    assert stats["kick"]["foot_speed"] > 1.25 * stats["walk"]["foot_speed"]


@pytest.mark.slow  # the shipped model, 5 prompts x 12 seeds x 6 s (about 60 s); tests/test_pins.py pins it fast
def test_wave_raises_a_hand(stats) -> None:
    assert stats["wave"]["wrist_over_pelvis"] > stats["walk"]["wrist_over_pelvis"] + 0.15


@pytest.mark.slow  # the shipped model, 5 prompts x 12 seeds x 6 s (about 60 s); tests/test_pins.py pins it fast
def test_standing_actions_stay_in_place(stats) -> None:
    for p in ("wave", "kick"):
        assert stats[p]["speed"] < 0.5 * stats["walk"]["speed"], p


@pytest.mark.slow  # 32 prompts of 6 s in four modes with the shipped model (about 12 min on 2 cores)
def test_physics_modes_match_the_recorded_bench(model: MotionDiffusion) -> None:
    """32 prompts, 6 s, seed 0, the modes of experiments/physdiff_quality.py but post:4, against seed 0 of
    results/physdiff_quality.json, whose three-seed means the README and the model card quote
    (tests/test_results.py). Generation is deterministic; the margin allows another CPU's rounding in
    the simulation. PhysDiff must beat the grounded baseline, not only ``none``, and the recorded post:4.
    post:4 itself (four chained projections, 20 s a motion) is not reproduced here: it was 11 of the
    suite's 37 min (tests/README.md)."""
    from experiments.physdiff_quality import compare_modes
    from experiments.prompts import PHYSICS_PROMPTS

    recorded = json.loads((Path(__file__).parents[1] / "results" / "physdiff_quality.json").read_text())
    assert recorded["meta"]["seeds"][0] == 0 and recorded["meta"]["prompts"] == len(PHYSICS_PROMPTS)
    expected = {mode: row for mode, row in recorded["runs"][0].items() if mode != "post:4"}
    res = compare_modes(model, PHYSICS_PROMPTS, list(expected))
    for mode, row in expected.items():
        assert res[mode]["phys_err"] == pytest.approx(row["phys_err"], rel=0.1), mode
    err = {mode: row["phys_err"] for mode, row in res.items()}
    physdiff = err["physdiff:end:4,space:1"]
    assert physdiff < err["none+floor"] < err["none"]
    assert physdiff < recorded["runs"][0]["post:4"]["phys_err"]


@pytest.mark.slow  # 4 verbs x 3 prompts x 3 seeds of 4 s, plain sampling (about 30 s)
def test_new_verbs_do_what_they_say() -> None:
    """Issue 50's acceptance on generated joints: a squat goes down and back up by 25 cm, a kick lifts a
    foot above the knees, lying down ends with the pelvis under 0.35 m, a hop lifts both feet; for each
    verb's HDM05 caption and two unseen paraphrases (experiments/new_verbs.py, whose figures the model
    card quotes), over seeds 0-2. The captions the model trained on pass in at least 2 of 3 seeds; with the
    paraphrases, at least 5 of the 9 motions pass (measured: squat, kick and lie down 9 of 9, hop 6:
    "someone jumps up with both feet" stays on the floor, the shortfall the card states)."""
    from experiments.new_verbs import PROMPTS, measure
    from physmotion.metrics.actions import ACTION_CHECKS

    figures = measure("default", seeds=3, seconds=4.0)
    assert set(figures) == set(ACTION_CHECKS)
    for verb, f in figures.items():
        caption = PROMPTS[verb][0]  # HDM05's own caption of the class
        assert f["per_prompt"][caption] >= 2, (verb, f["per_prompt"])
        assert f["passed"] >= 5 / 9, (verb, f["per_prompt"])  # one motion of margin on another CPU's rounding
        # the figures are the checks' own: recount them from the measured values
        assert sum(map(ACTION_CHECKS[verb].accepts, f["values"])) == sum(f["per_prompt"].values())
