"""The student learned from the search: its data, its fit, its episodes with no outside hand, its DAgger labels."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from physmotion.imitator.clips import ClipSource
from physmotion.imitator.student import (Carried, Expert, Labeller, StudentConfig, card, carry, dagger_labels,
                                         dagger_steps, fit_student, save_student, student_policy, student_settings,
                                         teacher_pairs)  # fmt: skip
from physmotion.imitator.teacher import TeacherConfig, load_teacher_set
from physmotion.physics.policy import load_policy
from physmotion.physics.projection import prepare_motion
from physmotion.physics.search import SearchConfig, no_hand
from physmotion.physics.tracking import ModelBasedTracker, prepare_reference


@pytest.fixture(scope="module")
def records(teacher_set) -> list[dict]:
    return load_teacher_set(teacher_set[0])


@pytest.fixture(scope="module")
def fitted(records):
    config = StudentConfig(hidden=(64,), steps=300, validation=0.5, seed=4)
    x, y, g = teacher_pairs(records, config.action_scale)
    weights, stats = fit_student(x, y, g, config)
    return config, weights, stats, (x, y, g)


def _prepared(joints: np.ndarray, fps: float):
    pconf = TeacherConfig().projection()
    prep = prepare_motion(joints.astype(np.float64), fps, pconf)
    return prep.model, prepare_reference(prep.model, prep.target, pconf.humanoid.control_dt, pconf.tracking), pconf


def test_pairs_are_the_committed_steps_before_a_fall(records) -> None:
    x, y, g = teacher_pairs(records, 0.3)
    expected = sum(len(r["offsets"]) - 1 if int(r["failed_at"]) < 0 else min(len(r["offsets"]) - 1, int(r["failed_at"]))
                   for r in records)  # fmt: skip
    assert len(x) == len(y) == len(g) == expected
    assert np.all(np.abs(y) <= 1.0)
    first = records[0]["offsets"][: np.count_nonzero(g == 0)] / 0.3
    inside = np.abs(first) < 1.0
    np.testing.assert_allclose(y[g == 0][inside], first[inside], rtol=1e-6)  # scaled, clipped only past 1


def test_the_fit_learns_the_labels_and_saves_a_policy_p_loads(fitted, records, tmp_path) -> None:
    config, weights, stats, (x, y, g) = fitted
    # A fit learns its training pairs: far below predicting nothing (the bare tracker).
    assert stats["train_mse"] < 0.5 * stats["train_mse_zero"]
    settings = student_settings(config)
    assert settings.cap == 0.0 and settings.tracking == no_hand(settings.tracking)
    folder = save_student(tmp_path / "student", weights, settings, card(config, "BC", records, stats))
    loaded = load_policy(folder)
    np.testing.assert_allclose(loaded.network(x[:20]), student_policy(weights, settings).network(x[:20]), rtol=1e-6)
    assert loaded.settings == settings
    assert loaded.card["licence_tags"] == [str(records[0]["licence_tag"])]
    # No outside hand under P: the controller's tracker has every help off.
    model, ref, pconf = _prepared(records[0]["joints"], float(records[0]["fps"]))
    ctrl = loaded.controller(model)
    assert ctrl.caps() == (0.0, 0.0, 0.0)


def test_selecting_on_validation_keeps_the_least_held_out_error(fitted) -> None:
    config, _, last, (x, y, g) = fitted
    weights, kept = fit_student(x, y, g, replace(config, select_on_validation=True))
    assert last["steps_kept"] == config.steps and 0 <= kept["steps_kept"] <= config.steps
    assert kept["steps_kept"] % 25 == 0 or kept["steps_kept"] == config.steps  # checked every 25 steps
    # step 0 (a zero last layer: the bare tracker) is among the candidates: never worse than predicting 0
    assert kept["val_mse"] <= kept["val_mse_zero"] + 1e-6
    # the returned weights are the kept step's, not the last: their held-out error is the one reported
    names = np.unique(g)  # fit_student's split: whole records drawn with the config's seed
    held = np.random.default_rng(config.seed).choice(names, size=max(1, round(config.validation * len(names))),
                                                     replace=False)  # fmt: skip
    val = np.isin(g, held)
    err = ((student_policy(weights, student_settings(config)).network(x) - y) ** 2).mean(axis=1)
    assert err[val].mean() == pytest.approx(kept["val_mse"], rel=1e-4)


def test_carry_ends_at_the_search_s_fall(run_clip: ClipSource) -> None:
    model, ref, pconf = _prepared(run_clip.joints, run_clip.fps)
    off = carry(model, ref, ModelBasedTracker(model, no_hand(pconf.tracking)), pconf.humanoid)
    on = carry(model, ref, ModelBasedTracker(model, pconf.tracking), pconf.humanoid)
    assert not off.completed and off.survived < off.steps // 2  # the hand off: it falls in the run
    assert on.completed and on.survived == on.steps and on.mpjpe < 0.1  # the hand on carries it
    assert off.states.shape == (off.survived + 1, on.states.shape[1])
    assert np.isfinite(off.mpjpe_rel) and off.mpjpe_rel <= off.mpjpe + 1e-9


def test_dagger_spends_its_labels_near_the_fall() -> None:
    fell = Carried(steps=100, survived=60, completed=False, mpjpe=0.0, mpjpe_rel=0.0, states=np.zeros((61, 1)))
    steps = dagger_steps(fell, near=30, every_near=3, every_far=10)
    assert steps == [0, 10, 20] + list(range(30, 61, 3))
    done = Carried(steps=100, survived=100, completed=True, mpjpe=0.0, mpjpe_rel=0.0, states=np.zeros((101, 1)))
    assert dagger_steps(done, near=30, every_near=3, every_far=10) == list(range(0, 101, 10))


def test_dagger_labels_are_local_and_seeded(fitted, records) -> None:
    config, weights, _, _ = fitted
    policy = student_policy(weights, student_settings(config))
    r = records[0]
    model, ref, pconf = _prepared(r["joints"], float(r["fps"]))
    c = carry(model, ref, policy.controller(model), pconf.humanoid, push=r["push"])
    label = Labeller(SearchConfig(candidates=6, rounds=1, elites=2, horizon=4, retries=0, rollback=0), None, 3)
    steps = dagger_steps(c, near=9, every_near=3, every_far=6)[:4]
    x1, y1 = dagger_labels(model, ref, policy, c.states, steps, label, pconf.humanoid, config.action_scale)
    _, y2 = dagger_labels(model, ref, policy, c.states, steps, label, pconf.humanoid, config.action_scale)
    assert x1.shape == (len(steps), 599) and y1.shape == (len(steps), 63)
    np.testing.assert_array_equal(y1, y2)
    assert np.all(np.abs(y1) <= 1.0)
    # The label is the search's choice around the student's proposal: it differs from the proposal somewhere.
    proposal = np.clip(policy.network(x1), -1.0, 1.0)
    assert np.abs(y1 - proposal).max() > 1e-3


def test_p_runs_an_amortized_search_with_the_student_proposing(fitted, records, run_clip, tmp_path) -> None:
    from physmotion.physics.projection import ProjectionConfig, project

    config, weights, stats, _ = fitted
    folder = save_student(tmp_path / "student", weights, student_settings(config), card(config, "BC", records, stats))
    tiny = SearchConfig(candidates=2, rounds=1, elites=1, horizon=3, retries=0, rollback=0, seed=1)
    joints = run_clip.joints[:20].astype(np.float64)
    alone = project(joints, 20.0, ProjectionConfig().with_controller("search", search=tiny))
    guided = project(joints, 20.0, ProjectionConfig().with_controller("search", policy=str(folder), search=tiny))
    assert np.all(guided.residual_force == 0.0) and np.all(guided.residual_torque == 0.0)  # still no hand
    # With two candidates, the first is the student's proposal: the committed offsets change with it.
    assert np.abs(guided.teacher_offsets - alone.teacher_offsets).max() > 1e-3


def test_mppi_labels_are_a_smooth_function_of_the_state(run_clip: ClipSource) -> None:
    # Common random numbers and averaged candidates: a state moved a little gets a label moved a little, where
    # the best candidate of a random search jumps (the naive labels' noise).
    model, ref, pconf = _prepared(run_clip.joints[:30], run_clip.fps)
    c = carry(model, ref, ModelBasedTracker(model, pconf.tracking), pconf.humanoid)
    near = c.states[6].copy()
    near[1 + model.nq : 1 + model.nq + 6] += 0.01  # the root's velocity, 1 cm/s and 0.01 rad/s more
    states = np.stack([c.states[6], near])
    effort = SearchConfig(candidates=16, rounds=1, elites=2, horizon=8, retries=0, rollback=0)
    labels = []
    for s in states:
        _, y = dagger_labels(model, ref, None, np.stack([s] * 7), [6], Labeller(effort, 0.1, 0), pconf.humanoid)
        labels.append(y[0])
    moved = float(np.abs(labels[0] - labels[1]).max())
    assert np.abs(labels[0]).max() > 0.05 and moved < 0.25 * float(np.abs(labels[0]).max()), moved


def test_the_expert_carries_further_than_the_bare_tracker(run_clip: ClipSource) -> None:
    model, ref, pconf = _prepared(run_clip.joints[:50], run_clip.fps)
    off = carry(model, ref, ModelBasedTracker(model, no_hand(pconf.tracking)), pconf.humanoid)
    effort = SearchConfig(candidates=16, rounds=1, elites=2, horizon=10, retries=0, rollback=0)
    expert = Expert(model, Labeller(effort, 0.1, 0), pconf.humanoid, pconf.tracking)
    on = carry(model, ref, expert, pconf.humanoid)
    assert on.survived > off.survived, (on.survived, off.survived)
    last = on.survived if not on.completed else on.steps - 1  # the last control step it acted at
    assert sorted(expert.labels) == list(range(0, last + 1, 3))  # a label every window of 3 steps
