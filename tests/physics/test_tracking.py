"""The simulation core and the model-based tracker on a real standing pose: standing still on real mocap
feet, determinism, failure detection, the residual bound and its update rate. Tracking real
walks is tested through the projection (test_projection.py).
"""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from physmotion.errors import ShapeError
from physmotion.physics.humanoid import HumanoidConfig, body_from_joints, build_model, foot_lift
from physmotion.physics.retarget import joints_to_qpos
from physmotion.physics.sim import simulate
from physmotion.physics.surface import lowest_point
from physmotion.physics.tracking import ModelBasedTracker, TrackingConfig, prepare_reference
from physmotion.skeleton import offsets_from_joints


def _standing_reference(real_walk: np.ndarray, seconds: float = 2.0):
    """The humanoid of the real walk, asked to hold the walk's first frame (30 Hz control)."""
    offsets = body_from_joints(real_walk)
    model = build_model(offsets)
    qpos = joints_to_qpos(real_walk[:1], model, lift=foot_lift(offsets))
    ref = prepare_reference(model, np.repeat(qpos, int(seconds * 30), 0), 1 / 30)
    return model, ref


def _heels_and_lowest(offsets: np.ndarray, joints: np.ndarray) -> tuple[float, float]:
    """Highest heel-box bottom and lowest body point (m) of the humanoid posed on frame 0."""
    model = build_model(offsets)
    data = mujoco.MjData(model)
    data.qpos[:] = joints_to_qpos(joints[:1], model, lift=foot_lift(offsets))[0]
    mujoco.mj_kinematics(model, data)
    heels = [data.geom_xpos[model.geom(f"{s}_ankle").id][2] - model.geom(f"{s}_ankle").size[2]
             for s in ("left", "right")]  # fmt: skip
    return max(heels), lowest_point(model, data)


def test_feet_of_the_motion_body_stand_flat(real_walk: np.ndarray) -> None:
    """Bandai's standing foot is pitched ~40 degrees; with the default 23 degree foot the humanoid
    stood on its toe boxes, heels in the air."""
    heel, lowest = _heels_and_lowest(body_from_joints(real_walk), real_walk)
    assert abs(lowest) < 0.01 and heel - lowest < 0.015, (heel, lowest)
    heel, lowest = _heels_and_lowest(offsets_from_joints(real_walk), real_walk)
    assert heel - lowest > 0.02, (heel, lowest)


def test_tracker_holds_a_real_standing_pose(real_walk: np.ndarray) -> None:
    """With the residual recomputed every simulation step the body stands still on both feet."""
    model, ref = _standing_reference(real_walk, seconds=3.0)
    roll = simulate(model, ref, ModelBasedTracker(model), HumanoidConfig(residual_every=1))
    assert roll.failed_at is None
    assert roll.mpjpe[5:].max() < 0.01  # metres
    assert roll.contacts[5:].any(axis=1).all() and roll.contacts[5:, :2].any(axis=1).all()  # heels down
    assert roll.residual_force.mean() < 0.1  # fractions of body weight: the feet do the work


def test_residual_held_over_two_steps_stands_over_four_rocks(real_walk: np.ndarray) -> None:
    """The default holds the residual over 2 simulation steps (180 Hz) and stands as still as every-step
    updates. Held over 4 (90 Hz, the sampling preset's) with the tracker of that measurement it rocks a
    standing body: MPJPE peaks near 34 mm after 2 s (12 mm on an Intel Xeon, 2026-12) and then settles,
    where every-step updates hold 4 mm (docs/decisions/projection.md: "held root residual"), guarded at
    that level. How the rocking body's feet touch down is chaotic and differs by CPU (toes down in 94 % of
    steps on an Intel Xeon, 62 % on CI's machine), so it is not checked; that it stays up, within 40 mm,
    and settles, is."""
    model, ref = _standing_reference(real_walk, seconds=3.0)
    every_step = simulate(model, ref, ModelBasedTracker(model), HumanoidConfig(residual_every=1))
    default = simulate(model, ref, ModelBasedTracker(model), HumanoidConfig())
    assert HumanoidConfig().residual_every == 2
    assert default.failed_at is None and default.mpjpe[5:].max() < 0.01
    assert default.contacts[5:, :2].any(axis=1).all()  # a heel down throughout: standing, not rocking
    before = TrackingConfig(residual_force=0.3, feet_torque_weight=1.0)  # the tracker of that figure
    held = simulate(model, ref, ModelBasedTracker(model, before), HumanoidConfig(residual_every=4))
    assert held.failed_at is None
    assert held.mpjpe[5:].max() < 0.04 and held.mpjpe[-10:].max() < held.mpjpe[5:].max()  # settling
    assert held.residual_force.mean() < 0.25
    assert not np.array_equal(every_step.qpos, held.qpos)  # the setting reached the loop
    with pytest.raises(ShapeError, match="residual_every"):
        HumanoidConfig(residual_every=5)  # 12 simulation steps per control step at 360 Hz


def test_simulation_is_deterministic(real_walk: np.ndarray) -> None:
    """The same episode twice on one model (each has its own MjData): identical states and contacts."""
    model, ref = _standing_reference(real_walk, seconds=1.0)
    one = simulate(model, ref, ModelBasedTracker(model))
    again = simulate(model, ref, ModelBasedTracker(model))
    np.testing.assert_array_equal(one.qpos, again.qpos)
    np.testing.assert_array_equal(one.contacts, again.contacts)


def test_failure_ends_the_episode(real_walk: np.ndarray) -> None:
    """A reference that jumps 2 m away cannot be followed: MPJPE passes 0.5 m and the episode ends."""
    model, ref = _standing_reference(real_walk, seconds=1.0)
    jump = 15
    ref.qpos[jump:, 0] += 2.0
    ref.joints_mj[jump:, :, 0] += 2.0
    roll = simulate(model, ref, ModelBasedTracker(model))
    assert roll.failed_at == jump
    assert np.all(roll.qpos[jump:] == roll.qpos[jump])


@pytest.mark.parametrize("bound", [0.02, 0.1])
def test_commanded_residual_respects_its_bound(real_walk: np.ndarray, bound: float) -> None:
    model, ref = _standing_reference(real_walk, seconds=0.5)
    """The bound on the residual itself: the feet carry nothing here (feet_balance off), so the root PD's
    pull is clipped to the bound, and its upward part to the lift cap."""
    ref.qpos[:, 2] += 0.2  # ask for a float: the root PD pulls up as hard as it may
    tracker = ModelBasedTracker(model, TrackingConfig(residual_force=bound, residual_torque=bound,
                                                      feet_balance=False))  # fmt: skip
    data = mujoco.MjData(model)
    data.qpos[:] = ref.qpos[0] - np.r_[0, 0, 0.2, np.zeros(model.nq - 3)]
    mujoco.mj_forward(model, data)
    wrench = tracker.residual(data, ref, 1, 2)
    assert np.linalg.norm(wrench[:3]) == pytest.approx(bound * tracker.weight, rel=1e-6)
    assert np.linalg.norm(wrench[3:6]) <= bound * tracker.weight + 1e-9
    capped = ModelBasedTracker(model, TrackingConfig(residual_force=bound, residual_lift=0.01,
                                                     feet_balance=False))  # fmt: skip
    assert capped.residual(data, ref, 1, 2)[2] == pytest.approx(0.01 * capped.weight)  # upward cap


def test_feet_on_the_floor_carry_the_root_wrench(real_walk: np.ndarray) -> None:
    """Standing on both feet, asked to rise 2 cm: without feet_balance the residual lifts the root (up to
    its 0.1 W cap); with it, the legs push the floor and the residual is nothing (measured 1e-7 W, joint
    torques up to 6.6 N m), within the actuators' limits."""
    model, ref = _standing_reference(real_walk, seconds=0.5)
    data = mujoco.MjData(model)
    data.qpos[:] = ref.qpos[0]
    mujoco.mj_forward(model, data)
    assert data.ncon > 0
    ref.qpos[:, 2] += 0.02
    plain = ModelBasedTracker(model, TrackingConfig(feet_balance=False)).residual(data, ref, 1, 2)
    tracker = ModelBasedTracker(model, TrackingConfig(feet_balance=True))
    carried = tracker.residual(data, ref, 1, 2)
    assert plain[2] == pytest.approx(0.1 * tracker.weight) and not plain[6:].any()
    assert np.linalg.norm(carried[:3]) < 1e-3 * tracker.weight
    joint = carried[6:]
    assert np.abs(joint).max() > 1.0  # N m: the legs do the work
    assert np.all(np.abs(joint) <= np.abs(model.actuator_forcerange[:, 1]) + 1e-9)
    data.qpos[2] += 0.3  # in the air: nothing to push on, the residual is all there is
    mujoco.mj_forward(model, data)
    assert data.ncon == 0
    airborne = tracker.residual(data, ref, 1, 2)
    assert not airborne[6:].any() and airborne[2] < 0.0


def test_humanoid_surface_reads_the_geoms(real_walk: np.ndarray) -> None:
    """The metrics' body surface from MuJoCo: soles under the toe joints by the sole depth."""
    from physmotion.metrics import physical_metrics
    from physmotion.physics.surface import HumanoidSurface

    body = body_from_joints(real_walk)
    surface = HumanoidSurface(body)
    low = surface.lowest_height(real_walk[:20])
    feet = surface.foot_heights(real_walk[:20])
    assert low.shape == (20,) and feet.shape == (20, 4)
    assert np.all(low <= feet.min(axis=1) + 1e-9)
    # Data convention (toe joints on the floor): the soles sink by the sole depth.
    assert np.median(low) == pytest.approx(-foot_lift(body), abs=0.006)
    raised = real_walk + np.array([0.0, foot_lift(body), 0.0])
    # Real capture on our feet: a few mm of penetration remain (2.6 mm here, after the 5 mm tolerance).
    assert physical_metrics(raised.astype(np.float32), body=surface)["penetrate"] < 5.0  # mm


def test_feet_balance_through_the_actuators_keeps_every_hinge_within_its_limit(mocap_dir) -> None:
    """A captured run under the plain P: the feet balance's joint torques applied beside the actuators put
    a hinge past its actuator's limit in a quarter of the frames (measured 12 of 48); sent through the
    actuators' targets, where the force range clips the total, in none, and the run is still carried to the
    end (MPJPE 62 -> 84 mm on this clip; over the first 3 s of 9 captured runs, 51 -> 53 mm mean, and the
    frames over a limit 13 % -> 0)."""
    from dataclasses import replace

    from physmotion.io.importer import import_clip, load_manifest
    from physmotion.physics.projection import ProjectionConfig, project

    clip = {c.clip: c for c in load_manifest(mocap_dir)}["bandai1_dataset-1_run_active_001"]
    run = import_clip(clip, floor="frame0").joints.astype(np.float64)[None, :60]
    plain = ProjectionConfig()
    beside = project(run, config=plain)
    through_actuators = replace(plain.tracking, feet_through_actuators=True)
    through = project(run, config=replace(plain, tracking=through_actuators))
    assert beside.over_limit.mean() > 0.1 and not through.over_limit.any()
    assert beside.success.all() and through.success.all() and through.mpjpe.mean() < 0.1
    assert np.abs(through.residual_force).max() <= plain.tracking.residual_force + 1e-6
