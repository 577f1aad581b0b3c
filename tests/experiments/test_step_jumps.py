"""experiments/step_jumps.py: the split of "jumps past the sample's" into P's and the denoiser's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from experiments.step_jumps import _where, measure
from physmotion.io import import_clip, load_manifest


def test_a_walks_largest_step_is_a_foots(mocap_dir: Path) -> None:
    info = next(c for c in load_manifest(mocap_dir) if c.clip == "bandai2_dataset-2_walk_normal_001")
    walk = import_clip(info).joints.astype(np.float64)
    assert _where(walk) == "foot"
    moved = walk.copy()
    moved[30:, 20, 0] += 0.3  # the left wrist pulled 30 cm in one frame
    assert _where(moved) == "arm"


@pytest.mark.slow
def test_post_has_no_denoising_after_its_p(small_built_dir: Path, tiny_model_dir: Path) -> None:
    """post:1's P is given the plain sample itself, so its jumps past P's input are its jumps past the
    sample and nothing is the denoiser's; PhysDiff's last P is given a denoised motion."""
    rows = measure(small_built_dir, "test", [0], ["post:1", "physdiff:end:1,space:1"], batch=4,
                   model_dir=tiny_model_dir, max_motions=4, recover=False)  # fmt: skip
    post, physdiff = rows["post:1"], rows["physdiff:end:1,space:1"]
    assert post["motions"] == physdiff["motions"] == 4
    assert post["input_past_sample"] == 0.0 and post["past_input"] == post["past_sample"]
    for r in rows.values():
        assert 0 <= r["past_input"] <= 1 and 0 <= r["with_reset"] <= 1
        assert sum(r["past_sample_where"].values()) == round(r["past_sample"] * r["motions"])
