"""The projection P on real mocap: what it does today (see the physics issue's note for what it
does not do yet: the all-clips targets are measured by bench/projection_quality.py)."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.features.humanml3d import extract_features
from physmotion.metrics import physical_metrics
from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.projection import ProjectionConfig, project
from physmotion.physics.surface import HumanoidSurface


@pytest.fixture(scope="module")
def walk(real_walk: np.ndarray) -> np.ndarray:
    """4 s of Bandai's normal walk (80, 22, 3), data convention (floor at the lowest joint)."""
    return real_walk[:80]


def test_tracks_a_real_walk(walk: np.ndarray) -> None:
    out = project(walk)
    assert out.success and out.selected
    assert out.joints.shape == out.simulated.shape == walk.shape and out.mpjpe.shape == (80,)
    assert out.mpjpe.mean() < 0.12  # metres; the 60 mm is not reached yet
    assert out.contacts.any(axis=1).mean() > 0.5  # on its feet most of the time
    after = physical_metrics(out.simulated, body=HumanoidSurface(body_from_joints(walk)))
    # MuJoCo's soft contacts let the loaded soles sink a few mm: 2-3 mm after PhysDiff's 5 mm
    # tolerance (the issue asks for <= 1 mm; stiffer contacts reached 0.4 mm but broke tracking).
    assert after["penetrate"] < 5.0  # mm


def test_deterministic_and_batch_equals_one_by_one(walk: np.ndarray) -> None:
    short = walk[:40]
    one = project(short)
    again = project(short)
    np.testing.assert_array_equal(one.simulated, again.simulated)
    batch = project(np.stack([short, short[::-1].copy()]), config=ProjectionConfig(threads=2))
    np.testing.assert_array_equal(batch.simulated[0], one.simulated)
    np.testing.assert_array_equal(batch.mpjpe[0], one.mpjpe)
    np.testing.assert_array_equal(batch.simulated[1], project(short[::-1].copy()).simulated)


def test_a_floating_walk_comes_down(walk: np.ndarray) -> None:
    lifted = walk + np.array([0.0, 0.1, 0.0])
    out = project(lifted)
    surface = HumanoidSurface(body_from_joints(walk))
    before = physical_metrics(lifted.astype(np.float32), body=surface)["float"]
    after = physical_metrics(out.simulated, body=surface)["float"]
    print(f"\nfloat {before:.1f} -> {after:.1f} mm")
    assert after < 0.2 * before  # measured -88 %; the issue asks for -90 %


def test_imitation_selection_keeps_the_input_when_tracking_fails(walk: np.ndarray) -> None:
    jumpy = walk[:40].copy()
    jumpy[20:, :, 0] += 3.0  # teleports 3 m sideways: no body can follow
    out = project(jumpy)
    assert not out.success and not out.selected
    np.testing.assert_array_equal(out.joints, jumpy.astype(np.float32))
    assert out.mpjpe.max() > 0.5


def test_features_are_accepted(walk: np.ndarray) -> None:
    feats, canon = extract_features(walk[:41])
    out = project(feats)
    assert out.simulated.shape == (40, 22, 3) and out.success


@pytest.mark.parametrize(
    "bad, match",
    [(np.full((10, 22, 3), np.nan), "NaN"), (np.zeros((10, 21, 3)), "must be joints"),
     (np.zeros((1, 22, 3)), "at least 2 frames"), (np.full((10, 263), np.inf), "NaN or infinite")],
)  # fmt: skip
def test_bad_input_is_refused(bad: np.ndarray, match: str) -> None:
    with pytest.raises(ShapeError, match=match):
        project(bad)
