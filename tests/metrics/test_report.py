"""The root residual as reports give it: mean and 95th percentile of force and torque."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.metrics.report import residual_line, residual_stats, residual_summary
from physmotion.motion import Motion


def test_residual_stats_and_line() -> None:
    force = np.linspace(0.0, 0.2, 101)
    residual = np.stack([force, 2 * force], axis=-1)
    s = residual_stats(residual)
    assert s["residual_force"] == pytest.approx(0.1)
    assert s["residual_force_p95"] == pytest.approx(0.19)
    assert s["residual_torque_p95"] == pytest.approx(0.38)
    line = residual_line(residual[None])  # a batch of motions counts all frames
    assert "force mean 0.100 W, p95 0.190 W" in line and "torque mean 0.200 W m, p95 0.380 W m" in line


def test_share_of_frames_at_the_cap() -> None:
    force = np.array([0.0, 0.1, 0.199, 0.2, 0.2])  # within 1 % of the 0.2 W cap: the last three
    residual = np.stack([force, force], axis=-1)
    assert "residual_at_cap" not in residual_stats(residual)
    assert residual_stats(residual, bound=0.2)["residual_at_cap"] == pytest.approx(0.6)
    assert residual_stats(residual, bound=0.3)["residual_at_cap"] == 0.0
    assert "at its 0.20 W cap in 60.0 % of frames" in residual_line(residual, bound=0.2)


def test_residual_summary_of_a_motion() -> None:
    joints = np.zeros((10, 22, 3), np.float32)
    assert residual_summary(Motion(joints=joints)) == {}
    m = Motion(joints=joints, residual=np.full((10, 2), 0.05, np.float32))
    assert residual_summary(m)["residual_torque_p95"] == pytest.approx(0.05)
