"""The searching controller: P with no outside hand, on captured motion from the shared mocap."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.io.importer import import_clip, load_manifest
from physmotion.physics.policy import NUM_ACTIONS, OBS_DIM
from physmotion.physics.projection import ProjectionConfig, prepare_motion, project
from physmotion.physics.search import EFFORTS, SearchConfig, SearchController, effort, no_hand, search_humanoid
from physmotion.physics.sim import simulate
from physmotion.physics.tracking import ModelBasedTracker, prepare_reference

RUN = "bandai2_dataset-2_run_normal_001"  # a captured run, 3.3 s: the tracker with its hand off falls in it


@pytest.fixture(scope="module")
def captured_run(mocap_dir: Path) -> np.ndarray:
    """The run through the importer, P's input convention: joints (T, 22, 3) float64 at 20 fps."""
    clips = {c.clip: c for c in load_manifest(mocap_dir)}
    return import_clip(clips[RUN], floor="frame0").joints.astype(np.float64)


@pytest.fixture(scope="module")
def searched(captured_run: np.ndarray):
    """The run projected by the search at the default effort, and its config."""
    config = ProjectionConfig().with_controller("search", search=effort("default", seed=3))
    return project(captured_run, 20.0, config), config


def test_the_search_runs_on_its_own_humanoid() -> None:
    # The elliptic cone and a hand to the knuckles for the search; the tracker keeps the preset's body.
    plain = ProjectionConfig()
    searching = plain.with_controller("search").humanoid
    assert searching == search_humanoid(plain.humanoid) != plain.humanoid
    assert (searching.cone, searching.impratio, searching.hand_length) == ("elliptic", 10.0, 0.08)
    assert plain.with_controller("tracker").humanoid == plain.humanoid


def test_the_tracker_alone_falls_without_its_hand(captured_run: np.ndarray) -> None:
    # What the search is for: the same tracker with its outside hand off does not carry this run.
    config = ProjectionConfig()
    prep = prepare_motion(captured_run, 20.0, config)
    ref = prepare_reference(prep.model, prep.target, config.humanoid.control_dt, config.tracking)
    tracker = ModelBasedTracker(prep.model, no_hand(config.tracking))
    roll = simulate(prep.model, ref, tracker, config.humanoid, fail_mpjpe=0.5)
    assert roll.failed_at is not None and roll.failed_at < len(ref.qpos) // 2


def test_search_carries_the_run_with_no_outside_help(searched, captured_run: np.ndarray) -> None:
    result, _ = searched
    assert bool(result.success) and bool(result.selected) and int(result.resets) == 0
    # No outside hand at all: the root residual is exactly zero and no joint passed its actuator's limit.
    assert np.all(result.residual_force == 0.0) and np.all(result.residual_torque == 0.0)
    assert not result.over_limit.any()
    # The body performs the run: pelvis-relative body positions stay near the input's.
    sim = result.simulated.astype(np.float64)
    rel = np.linalg.norm((sim - sim[:, :1]) - (captured_run - captured_run[:, :1]), axis=-1).mean()
    assert rel < 0.08, rel
    # and it runs: the pelvis covers most of the input's horizontal distance.
    travel_in = np.linalg.norm(captured_run[-1, 0, [0, 2]] - captured_run[0, 0, [0, 2]])
    travel_out = np.linalg.norm(sim[-1, 0, [0, 2]] - sim[0, 0, [0, 2]])
    assert travel_out > 0.8 * travel_in > 1.0


def test_teacher_records_per_control_step(searched) -> None:
    result, config = searched
    steps = result.teacher_obs.shape[0]
    assert result.teacher_obs.shape == (steps, OBS_DIM) and result.teacher_offsets.shape == (steps, NUM_ACTIONS)
    assert steps == round((len(result.joints) - 1) / 20.0 * 30.0) + 1  # the control rate, 30 Hz
    assert np.all(np.isfinite(result.teacher_obs))
    # Offsets are what the search chose: non-zero, and within a few spreads of the widest retry.
    widest = config.search.harder(config.search.retries).sigma
    assert np.abs(result.teacher_offsets[:-1]).max() > 0.0
    assert np.abs(result.teacher_offsets).max() < 6 * widest


def test_search_is_deterministic_under_its_seed(captured_run: np.ndarray, searched) -> None:
    result, config = searched
    short = captured_run[:12]
    a = project(short, 20.0, config)
    b = project(short, 20.0, config)
    assert np.array_equal(a.simulated, b.simulated) and np.array_equal(a.teacher_offsets, b.teacher_offsets)
    other = project(short, 20.0, replace(config, search=replace(config.search, seed=4)))
    assert not np.array_equal(a.teacher_offsets, other.teacher_offsets)
    # A batch gives what its motions give one by one (worker processes, one rollout thread each).
    batch = project(np.stack([short, short]), 20.0, config)
    assert np.array_equal(batch.simulated[1], a.simulated)


def test_a_fall_is_reset_under_generation_preset(captured_run: np.ndarray) -> None:
    # A search too weak to carry the run (one candidate round, no lookahead to speak of) falls; generation's
    # preset puts the humanoid back and counts it, and the plain preset keeps the input, flagged.
    weak = SearchConfig(candidates=2, rounds=1, elites=1, horizon=1, sigma=1e-6, retries=0, rollback=0)
    plain = project(captured_run, 20.0, ProjectionConfig().with_controller("search", search=weak))
    assert not bool(plain.success) and not bool(plain.selected)
    assert np.array_equal(plain.joints, captured_run.astype(np.float32))
    sampling = ProjectionConfig.sampling().with_controller("search", search=weak)
    reset = project(captured_run, 20.0, sampling)
    assert int(reset.resets) >= 1 and bool(reset.selected)


def test_search_config_is_checked() -> None:
    assert set(EFFORTS) == {"fast", "default", "best"}
    with pytest.raises(ShapeError, match="unknown search effort"):
        effort("hardest")
    with pytest.raises(ShapeError, match="candidates"):
        SearchConfig(candidates=0)
    with pytest.raises(ShapeError, match="elites"):
        SearchConfig(candidates=4, elites=5)
    with pytest.raises(ShapeError, match="not the search"):
        replace(ProjectionConfig().with_controller("search"), ilc_passes=2)
    harder = SearchConfig().harder(1)
    assert harder.candidates == 64 and harder.horizon == 18 and harder.sigma == pytest.approx(0.2 * 4 / 3)


def test_controller_records_its_rollouts(captured_run: np.ndarray) -> None:
    config = ProjectionConfig()
    prep = prepare_motion(captured_run[:12], 20.0, config)
    ref = prepare_reference(prep.model, prep.target, config.humanoid.control_dt, config.tracking)
    search = SearchController(prep.model, effort("default"), config.humanoid, config.tracking)
    roll, record = search.run(ref)
    windows = int(np.ceil((len(ref.qpos) - 1) / search.config.window))
    assert record.rollouts >= windows * search.config.candidates * search.config.rounds
    assert roll.qpos.shape == (len(ref.qpos), prep.model.nq) and roll.failed_at is None
    assert np.all(record.effort[:-1] >= 0)


def _short_search(captured_run: np.ndarray, proposal=None) -> tuple:
    config = ProjectionConfig()
    prep = prepare_motion(captured_run[:30], 20.0, config)
    ref = prepare_reference(prep.model, prep.target, config.humanoid.control_dt, config.tracking)
    tiny = SearchConfig(candidates=4, rounds=1, elites=2, horizon=3, retries=0, rollback=0, seed=2)
    return SearchController(prep.model, tiny, config.humanoid, config.tracking, proposal), ref


def test_a_proposal_centres_every_window(captured_run: np.ndarray) -> None:
    seen: list[np.ndarray] = []

    def propose(obs: np.ndarray) -> np.ndarray:
        seen.append(obs)
        return np.full(NUM_ACTIONS, 0.05)

    search, ref = _short_search(captured_run, propose)
    roll, record = search.run(ref)
    end = len(ref.qpos) - 1 if roll.failed_at is None else roll.failed_at  # the tiny search may fall
    assert end >= 9
    windows = -(-end // search.config.window)
    assert len(seen) >= windows and all(o.shape == (OBS_DIM,) for o in seen)
    # The proposal is candidate 0 of the first round: a window where it won commits it exactly.
    assert np.isclose(record.offsets[:end], 0.05).all(axis=1).any()
    # A proposal that returns NaN falls back to the warm start; the episode stays finite.
    nan, ref = _short_search(captured_run, lambda obs: np.full(NUM_ACTIONS, np.nan))
    roll, record = nan.run(ref)
    assert np.all(np.isfinite(record.offsets)) and np.all(np.isfinite(roll.qpos))


def test_a_push_starts_the_root_faster_and_one_window_is_seeded(captured_run: np.ndarray) -> None:
    search, ref = _short_search(captured_run)
    push = np.array([0.3, -0.2, 0.0, 0.1, 0.0, -0.4])
    _, plain = search.run(ref)
    _, pushed = search.run(ref, push=push)
    np.testing.assert_allclose(pushed.qvel[0, :6] - plain.qvel[0, :6], push, atol=1e-12)
    state = np.concatenate([[0.0], plain.qpos[5], plain.qvel[5]])
    import mujoco

    full = np.zeros(mujoco.mj_stateSize(search.model, mujoco.mjtState.mjSTATE_FULLPHYSICS))
    full[: len(state)] = state  # time, qpos, qvel; no actuator activations or plugin state in this model
    a = search.window(ref, full, 5, np.zeros(NUM_ACTIONS), seed=9)
    b = search.window(ref, full, 5, np.zeros(NUM_ACTIONS), seed=9)
    assert a.shape == (NUM_ACTIONS,) and np.array_equal(a, b)


def test_the_body_velocity_cost_charges_a_step_the_reference_does_not_take(captured_run: np.ndarray) -> None:
    """Two candidates on the reference's own states, one with a single frame pushed 5 cm sideways: the
    body-velocity term (off by default) charges the pushed one's two steps into and out of that frame."""
    from physmotion.physics.search import SearchCost, SearchGoal

    search, ref = _short_search(captured_run)
    steps, k = 6, 2
    states = np.zeros((2, steps, search._nstate))
    at, nq = search._qpos_at, search.model.nq
    states[:, :, at : at + nq] = ref.qpos[k + 1 : k + 1 + steps]
    states[:, :, at + nq : at + nq + search.model.nv] = ref.qvel[k + 1 : k + 1 + steps]
    states[1, 3, at] += 0.05  # the root, and with it every body, 5 cm off at one step
    costs = {}
    for weight in (0.0, 0.1):
        search.config = replace(search.config, cost=replace(SearchCost(), body_velocity=weight))
        costs[weight], _, _ = search._cost(states, SearchGoal(ref, search.config), k)
    extra = costs[0.1] - costs[0.0]  # (2, steps): the velocity term alone
    assert np.allclose(extra[0], 0.0, atol=1e-6)  # the reference's own steps cost nothing
    assert extra[1, 3] > 0 and extra[1, 4] > 0  # into the pushed frame and out of it
    assert np.allclose(extra[1, [0, 1, 2, 5]], 0.0, atol=1e-6)
    # 5 cm in one control step is 1.5 m/s on every body: 0.1 x 1.5^2 = 0.225
    assert extra[1, 3] == pytest.approx(0.1 * (0.05 * 30) ** 2, rel=1e-3)
