"""The humanoid's collision geometry as a body surface."""

from __future__ import annotations

import numpy as np

from physmotion.physics.humanoid import body_from_joints
from physmotion.physics.surface import HumanoidSurface


def test_heights_follow_the_motion_given_not_a_freed_one(real_walk: np.ndarray) -> None:
    """Each call answers for its own array, even when the previous one was a freed temporary whose
    memory (and id) the next array may reuse."""
    walk = real_walk[:20]
    surface = HumanoidSurface(body_from_joints(walk))
    low = surface.lowest_height(walk.copy())
    for step in (0.1, 0.2, 0.3):  # a run of temporaries of one shape, as a benchmark loop makes them
        moved = surface.lowest_height(walk.astype(np.float32).astype(np.float64) + np.array([0.0, step, 0.0]))
        np.testing.assert_allclose(moved, low + step, atol=1e-6)
    feet = surface.foot_heights(walk.copy())
    assert feet.shape == (20, 4) and np.all(feet >= low[:, None] - 1e-9)
