"""What physics kept of a sample's dynamics, on captured clips: a jump's flight and a teleport."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.metrics.dynamics import flight_kept, flight_ratios, jumps_past, largest_step, step_jumps


@pytest.fixture(scope="module")
def jump_and_walk(mocap_dir: Path) -> tuple[np.ndarray, np.ndarray]:
    """The first captured jump and walk of the manifest, imported: joints (T, 22, 3)."""
    from experiments.projection_quality import category
    from physmotion.io.importer import import_clip, load_manifest

    clips = load_manifest(mocap_dir)
    first = {kind: next(c for c in clips if category(c.captions) == kind) for kind in ("jump", "walk")}
    return tuple(import_clip(first[kind]).joints.astype(np.float64) for kind in ("jump", "walk"))


def test_a_flattened_jump_keeps_less_flight(jump_and_walk) -> None:
    jump, walk = jump_and_walk
    assert flight_kept([jump], [jump]) == pytest.approx(1.0)
    half = jump * np.array([1.0, 0.5, 1.0])  # every height halved: half the flight
    assert flight_kept([half], [jump]) == pytest.approx(0.5, abs=0.01)
    assert flight_kept([walk], [walk]) is None  # a walk has no flight to keep: no ratio at all
    assert flight_ratios([half, walk], [jump, walk]) == pytest.approx([0.5], abs=0.01)


def test_a_teleport_is_a_jump_past_the_sample(jump_and_walk) -> None:
    _, walk = jump_and_walk
    moved = walk.copy()
    moved[40:, :, 1] += 0.25  # 25 cm up in one frame
    assert largest_step(moved) > largest_step(walk) + 0.05
    assert step_jumps([walk, moved], [walk, walk]) == 0.5
    assert step_jumps([walk + 0.01], [walk]) == 0.0  # a constant shift moves nothing between frames
    with pytest.raises(ValueError, match="pair"):
        step_jumps([walk], [])
    # against given largest steps (what P was given): the same count, from the steps alone
    assert jumps_past([walk, moved], [largest_step(walk)] * 2) == 0.5
    assert jumps_past([moved], [largest_step(moved) - 0.019]) == 0.0  # within the 2 cm margin
    with pytest.raises(ValueError, match="reference steps"):
        jumps_past([walk], [])
