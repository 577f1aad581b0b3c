"""P's help as reports give it: the root residual's mean and 95th percentile of force and torque, the
share of frames at its cap, and the frames with a joint over its torque limit."""

from __future__ import annotations

import numpy as np
import pytest

from physmotion.metrics.report import NO_HELP, help_stats, help_words, residual_line, residual_stats, residual_summary
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


def test_no_outside_help_is_said_in_words() -> None:
    # A P with no hand (cap 0, the search's) that applied none says so; any residual, or a joint over its
    # limit, and the figures come back.
    zero = np.zeros((5, 2))
    assert residual_line(zero, 0.0, np.zeros(5, bool)) == NO_HELP == help_words(zero, 0.0)
    assert residual_line(zero, 0.0, np.array([False, True, False, False, False])) != NO_HELP
    some = zero.copy()
    some[2, 0] = 0.01
    assert "force mean 0.002 W" in residual_line(some, 0.0)
    assert help_words(some, 0.0).endswith("(W: body weight)")
    assert residual_line(zero, 0.2) != NO_HELP  # a tracker that happened to need no help still had a hand
    assert residual_stats(zero, 0.0)["residual_at_cap"] == 0.0  # no hand: nothing to be held at


def test_residual_summary_of_a_motion() -> None:
    joints = np.zeros((10, 22, 3), np.float32)
    assert residual_summary(Motion(joints=joints)) == {}
    m = Motion(joints=joints, residual=np.full((10, 2), 0.05, np.float32))
    assert residual_summary(m)["residual_torque_p95"] == pytest.approx(0.05)


def test_residual_summary_reads_the_cap_and_torque_limits_the_file_records() -> None:
    joints = np.zeros((4, 22, 3), np.float32)
    force = np.array([0.3, 0.3, 0.1, 0.0], np.float32)
    m = Motion(joints=joints, residual=np.stack([force, force], -1), residual_cap=0.3,
               over_limit=np.array([True, False, False, False]))
    row = residual_summary(m)
    assert row["residual_at_cap"] == pytest.approx(0.5) and row["over_limit"] == pytest.approx(0.25)
    line = residual_line(m.residual, m.residual_cap, m.over_limit)
    assert "cap in 50.0 % of frames" in line and "actuator's limit in 25.0 % of frames" in line


def test_help_pooled_over_motions() -> None:
    """Every frame of every projected motion counts; a motion without P's records is left out; the share
    at the cap needs one cap for all, the over-limit share flags from all."""
    joints = np.zeros((2, 22, 3), np.float32)
    a = Motion(joints=joints, residual=np.full((2, 2), 0.2, np.float32), residual_cap=0.2,
               over_limit=np.array([True, True]))
    b = Motion(joints=joints, residual=np.zeros((2, 2), np.float32), residual_cap=0.2,
               over_limit=np.array([False, False]))
    row = help_stats([a, b, Motion(joints=joints)])
    assert row["residual_force"] == pytest.approx(0.1)
    assert row["residual_at_cap"] == pytest.approx(0.5) and row["over_limit"] == pytest.approx(0.5)
    other_cap = Motion(joints=joints, residual=np.zeros((2, 2), np.float32), residual_cap=0.3)
    assert "residual_at_cap" not in help_stats([a, other_cap]) and "over_limit" not in help_stats([a, other_cap])
    assert help_stats([Motion(joints=joints)]) == {}


def test_the_share_at_a_cap_counts_every_cap_where_the_file_records_it() -> None:
    """A file that records which frames were held at a cap (force, lift or torque, any residual update)
    is read by that record, not by its mean force alone: here no frame's mean force is at the cap, yet
    two frames were held (a lift or torque cap, or a peak averaged away). Peaks are reported too."""
    joints = np.zeros((4, 22, 3), np.float32)
    residual = np.full((4, 2), 0.05, np.float32)
    peak = np.array([[0.3, 0.9], [0.1, 1.0], [0.05, 0.05], [0.05, 0.05]], np.float32)
    held = np.array([True, True, False, False])
    m = Motion(joints=joints, residual=residual, residual_cap=0.3, residual_peak=peak, residual_at_cap=held)
    row = residual_summary(m)
    assert row["residual_at_cap"] == pytest.approx(0.5)
    assert residual_stats(residual, 0.3)["residual_at_cap"] == 0.0  # the mean-force rule sees none
    assert row["residual_torque_peak_p95"] == pytest.approx(np.percentile(peak[:, 1], 95))
    line = residual_line(m.residual, 0.3, None, held, peak)
    assert "held at a cap (force 0.30 W, lift or torque) in 50.0 % of frames" in line and "peak p95" in line
    assert residual_stats(residual, 0.0, held)["residual_at_cap"] == 0.0  # no hand: nothing to be held by
