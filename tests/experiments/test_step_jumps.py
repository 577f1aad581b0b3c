"""experiments/step_jumps.py: the split of "jumps past the sample's" into P's and the denoiser's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from experiments.step_jumps import _STAGES, CONTROL, _stage, _where, measure
from physmotion.io import import_clip, load_manifest


def test_a_walks_largest_step_is_a_foots(mocap_dir: Path) -> None:
    info = next(c for c in load_manifest(mocap_dir) if c.clip == "bandai2_dataset-2_walk_normal_001")
    walk = import_clip(info).joints.astype(np.float64)
    assert _where(walk) == "foot"
    moved = walk.copy()
    moved[30:, 20, 0] += 0.3  # the left wrist pulled 30 cm in one frame
    assert _where(moved) == "arm"


def test_a_jump_is_put_on_the_first_stage_that_makes_it(mocap_dir: Path) -> None:
    """The denoiser before P's reference, the reference before the simulation; in the simulation, a foot
    dragged along the floor is told from a wrist pulled in the air."""
    info = next(c for c in load_manifest(mocap_dir) if c.clip == "bandai2_dataset-2_walk_normal_001")
    walk = import_clip(info).joints.astype(np.float64)
    plain = 0.2
    assert _stage(walk, plain, given=0.25, reference=0.3) == _STAGES[0]
    assert _stage(walk, plain, given=0.21, reference=0.25) == _STAGES[1]
    # a standing left toe: the frame where it is lowest and slowest
    steps = np.linalg.norm(np.diff(walk, axis=0), axis=-1)
    f = int(np.argmin(walk[:-1, 10, 1] + steps[:, 10]))
    dragged = walk.copy()
    dragged[f + 1 :, 10, 0] += 0.4  # the left toe slid 40 cm along the floor in one frame
    assert _stage(dragged, plain, given=0.2, reference=0.2) == _STAGES[2]
    pulled = walk.copy()
    pulled[f + 1 :, 20, 0] += 0.4  # the left wrist instead
    assert _stage(pulled, plain, given=0.2, reference=0.2) == _STAGES[3]
    lifted = dragged.copy()
    lifted[f + 1 :, 10, 1] += 0.1  # the toe slid and rose 10 cm: off the floor
    assert _stage(lifted, plain, given=0.2, reference=0.2) == _STAGES[3]


@pytest.mark.slow
def test_post_has_no_denoising_after_its_p(small_built_dir: Path, tiny_model_dir: Path) -> None:
    """post:1's P is given the plain sample itself, so its jumps past P's input are its jumps past the
    sample and nothing is the denoiser's; PhysDiff's last P is given a denoised motion."""
    rows = measure(small_built_dir, "test", [0], ["post:1", "physdiff:end:1,space:1"], batch=4,
                   model_dir=tiny_model_dir, max_motions=4, recover=False, control=True)  # fmt: skip
    post, physdiff, control = rows.pop("post:1"), rows.pop("physdiff:end:1,space:1"), rows.pop(CONTROL)
    assert not rows and control["motions"] == 4 and 0 <= control["past_sample"] <= 1
    assert post["motions"] == physdiff["motions"] == 4
    assert post["input_past_sample"] == 0.0 and post["past_input"] == post["past_sample"]
    for r in (post, physdiff):
        assert 0 <= r["past_input"] <= 1 and 0 <= r["with_reset"] <= 1
        assert sum(r["past_sample_where"].values()) == round(r["past_sample"] * r["motions"])
        assert sum(r["past_sample_stage"].values()) == round(r["past_sample"] * r["motions"])
    assert post["past_sample_stage"]["denoiser"] == 0
