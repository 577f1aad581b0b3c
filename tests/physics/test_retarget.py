"""Retargeting joints <-> qpos: round trips, continuity, batching, velocities, errors."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.errors import ShapeError
from physmotion.physics.humanoid import body_from_joints, build_model, foot_lift, layout
from physmotion.physics.retarget import NQ, NV, joints_to_qpos, qpos_to_joints, qvel_from_qpos, reach_arm_ends
from physmotion.skeleton import (
    JOINT_INDEX,
    REST_OFFSETS,
    bone_lengths,
    forward_kinematics,
    offsets_from_joints,
    unit_vectors,
)

from .conftest import gait_joints, gait_rotations, shrunk_upper_arms, wrist_error

DT = 1.0 / 20.0
_REST_QPOS = np.tile(np.r_[0.0, 0.0, 0.9, 1.0, np.zeros(66)], (4, 1))  # (4, 70) valid qpos


def _max_err(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.linalg.norm(a - b, axis=-1).max())


def _jump(qpos: np.ndarray) -> float:
    """Largest frame-to-frame change of any hinge angle (rad)."""
    return float(np.abs(np.diff(qpos[..., 7:], axis=-2)).max())


def _limit_violation(model, qpos: np.ndarray) -> float:
    """Largest excursion (rad) of any hinge beyond its range."""
    lo, hi = model.jnt_range[1:, 0], model.jnt_range[1:, 1]
    adr = model.jnt_qposadr[1:]
    q = qpos[..., adr]
    return float(max(0.0, (lo - q).max(), (q - hi).max()))


def test_round_trip_own_body_is_exact(walk: np.ndarray) -> None:
    model = build_model(offsets_from_joints(walk))
    qpos = joints_to_qpos(walk, model)
    assert qpos.shape == (len(walk), NQ) and qpos.dtype == np.float64
    back = qpos_to_joints(qpos, model)
    assert _max_err(back, walk) < 1e-6
    # MuJoCo's own kinematics agrees with ours
    assert _max_err(qpos_to_joints(qpos, model, method="mujoco"), back) < 1e-9
    # root = pelvis joint, in MuJoCo axes
    assert np.allclose(qpos[:, :3], walk[:, 0][:, [2, 0, 1]])
    assert np.allclose(np.linalg.norm(qpos[:, 3:7], axis=-1), 1.0)


def test_round_trip_with_offsets_instead_of_model(walk: np.ndarray) -> None:
    offsets = offsets_from_joints(walk)
    q_model = joints_to_qpos(walk, build_model(offsets))
    q_offsets = joints_to_qpos(walk, offsets)
    assert np.allclose(q_model, q_offsets)
    assert _max_err(qpos_to_joints(q_offsets, offsets), walk) < 1e-6


def test_default_body_on_another_body(walk: np.ndarray, default_model) -> None:
    """Bone lengths differ (0-10 %), so positions cannot match; bone directions do."""
    back = qpos_to_joints(joints_to_qpos(walk, default_model), default_model)
    err = np.linalg.norm(back - walk, axis=-1)
    assert err.mean() < 0.10  # measured 0.04-0.05 m on this body (see the module report)
    assert np.allclose(bone_lengths(back), np.linalg.norm(REST_OFFSETS, axis=-1)[None], atol=1e-9)
    bones = (("left_knee", "left_ankle"), ("right_shoulder", "right_elbow"), ("left_elbow", "left_wrist"))
    for a, b in bones:
        i, j = JOINT_INDEX[a], JOINT_INDEX[b]
        d0 = walk[:, j] - walk[:, i]
        d1 = back[:, j] - back[:, i]
        cos = np.sum(d0 * d1, -1) / np.linalg.norm(d0, axis=-1) / np.linalg.norm(d1, axis=-1)
        assert np.degrees(np.arccos(np.clip(cos, -1, 1))).max() < 1.0


def test_knees_and_elbows_bend_about_their_hinge(walk: np.ndarray) -> None:
    model = build_model(offsets_from_joints(walk))
    lay = layout(model)
    qpos = joints_to_qpos(walk, model)
    hinges = (("left_knee", "y"), ("right_knee", "y"), ("left_elbow", "z"), ("right_elbow", "z"))
    for name, bend_axis in hinges:
        j = JOINT_INDEX[name]
        for k, axis in enumerate(lay.hinge_order[j]):
            angle = np.degrees(np.abs(qpos[:, lay.hinge_qpos[j, k]]))
            if axis == bend_axis:
                assert angle.max() > 20.0
            else:
                assert angle.max() < 5.0, (name, axis, angle.max())
    # positions are the same with or without the twist choice
    plain = joints_to_qpos(walk, model, anatomical=False)
    assert _max_err(qpos_to_joints(plain, model), walk) < 1e-6


def test_batched_equals_one_by_one(walk: np.ndarray) -> None:
    offsets = offsets_from_joints(walk)
    batch = np.stack([walk, walk[::-1], walk + np.array([0.5, 0.0, -1.0])])  # (3, T, 22, 3)
    qpos = joints_to_qpos(batch, offsets)
    assert qpos.shape == (3, len(walk), NQ)
    for b in range(3):
        assert np.allclose(qpos[b], joints_to_qpos(batch[b], offsets))
    back = qpos_to_joints(qpos, offsets)
    assert back.shape == batch.shape
    assert _max_err(back, batch) < 1e-6
    vel = qvel_from_qpos(qpos, DT)
    assert vel.shape == (3, len(walk), NV)
    assert np.allclose(vel[1], qvel_from_qpos(qpos[1], DT))


def test_angles_stay_continuous_through_flips() -> None:
    """A root spinning twice and an arm circling overhead: no 2 pi jumps, no Euler branch flips."""
    frames = 120
    rot, root = gait_rotations(frames)
    t = np.arange(frames) / frames
    spin = Rotation.from_euler("y", 4 * np.pi * t[:, None]).as_matrix()  # two full turns about the vertical
    rot[:, 0] = spin @ rot[:, 0]
    circle = Rotation.from_euler("xz", np.stack([2 * np.pi * t, np.full(frames, -0.3)], -1)).as_matrix()
    rot[:, JOINT_INDEX["left_shoulder"]] = circle
    joints = forward_kinematics(rot, root, REST_OFFSETS)
    qpos = joints_to_qpos(joints, REST_OFFSETS)
    assert _max_err(qpos_to_joints(qpos, REST_OFFSETS), joints) < 1e-6
    assert _jump(qpos) < 0.5
    quat = qpos[:, 3:7]
    assert np.all(np.sum(quat[1:] * quat[:-1], -1) > 0.9)  # one hemisphere, no sign flips


def test_an_arm_bent_slightly_backwards_keeps_its_twist() -> None:
    """An elbow bent 10 degrees the wrong way (generated arms are often a little over-straight), its bend
    axis a degree either side of straight backwards from frame to frame: the upper arm is not turned
    from one end of its twist range to the other (measured before the fix: 100 degrees in one frame)."""
    frames = 40
    rot, root = gait_rotations(frames)
    wobble = np.radians(np.where(np.arange(frames) % 2 == 0, 1.0, -1.0))
    rotvec = np.stack([np.zeros(frames), np.full(frames, np.radians(10.0)), wobble], -1)
    rot[:, JOINT_INDEX["left_elbow"]] = Rotation.from_rotvec(rotvec).as_matrix()
    joints = forward_kinematics(rot, root, REST_OFFSETS)
    qpos = joints_to_qpos(joints, REST_OFFSETS)
    assert _max_err(qpos_to_joints(qpos, REST_OFFSETS), joints) < 1e-6
    assert _jump(qpos) < np.radians(20.0)


def test_real_walk_round_trip_and_continuity(real_walk: np.ndarray, default_model) -> None:
    """Bandai's normal walk through physmotion.io.importer (needs the importer)."""
    model = build_model(offsets_from_joints(real_walk))
    qpos = joints_to_qpos(real_walk, model)
    assert _max_err(qpos_to_joints(qpos, model), real_walk) < 0.01
    assert _jump(qpos) < 0.5  # rad per frame at 20 fps
    assert _limit_violation(model, qpos) == 0.0
    # the default body on this subject: reported, loosely bounded
    back = qpos_to_joints(joints_to_qpos(real_walk, default_model), default_model)
    assert np.linalg.norm(back - real_walk, axis=-1).mean() < 0.15


def test_a_captured_clips_arms_are_left_as_they_are(real_walk: np.ndarray) -> None:
    """Rigid captured bones are within the length tolerance: the fit returns the clip bit for bit."""
    model = build_model(body_from_joints(real_walk))
    assert np.array_equal(reach_arm_ends(real_walk, layout(model).offsets), real_walk)


def test_arms_whose_bones_change_length_are_refitted_with_their_wrists_kept(real_walk: np.ndarray) -> None:
    """Elbows slid 8 cm up their upper arms for four frames of a real walk: the fit puts them back where
    the walk had them (the two-bone solution nearest the moved elbow), so the humanoid's wrists stay on the
    motion's; copying the moved bones' directions puts its wrists 3-4 cm off."""
    model = build_model(body_from_joints(real_walk))
    moved = shrunk_upper_arms(real_walk)
    fitted = reach_arm_ends(moved, layout(model).offsets)
    assert _max_err(fitted, real_walk) < 1e-5
    copied = qpos_to_joints(joints_to_qpos(moved, model), model)
    assert wrist_error(copied, moved) > 0.03
    kept = qpos_to_joints(joints_to_qpos(fitted, model), model)
    assert wrist_error(kept, moved) < 1e-4


def test_a_straight_arm_too_short_for_the_body_is_not_bent() -> None:
    """Straight arms 10 % shorter than the body's: the body's arm stays straight (pointing at the wrist,
    reaching past it) rather than bending in a plane the motion does not show."""
    joints = gait_joints(REST_OFFSETS, 30)
    for side in ("left", "right"):
        s, e, w = (JOINT_INDEX[f"{side}_{part}"] for part in ("shoulder", "elbow", "wrist"))
        along = unit_vectors(joints[:, e] - joints[:, s])
        joints[:, e] = joints[:, s] + 0.9 * np.linalg.norm(REST_OFFSETS[e]) * along
        joints[:, w] = joints[:, e] + 0.9 * np.linalg.norm(REST_OFFSETS[w]) * along
    fitted = reach_arm_ends(joints, REST_OFFSETS)
    for side in ("left", "right"):
        s, e, w = (JOINT_INDEX[f"{side}_{part}"] for part in ("shoulder", "elbow", "wrist"))
        upper, fore = fitted[:, e] - fitted[:, s], fitted[:, w] - fitted[:, e]
        assert np.allclose(unit_vectors(upper), unit_vectors(fore), atol=1e-6)
        assert np.allclose(np.linalg.norm(upper, axis=-1), np.linalg.norm(REST_OFFSETS[e]))
        assert np.allclose(np.linalg.norm(fore, axis=-1), np.linalg.norm(REST_OFFSETS[w]))


def test_lift_moves_the_root_and_comes_off_again(walk: np.ndarray) -> None:
    lift = foot_lift()
    q0 = joints_to_qpos(walk, REST_OFFSETS)
    q1 = joints_to_qpos(walk, REST_OFFSETS, lift=lift)
    assert np.allclose(q1[:, 2] - q0[:, 2], lift)
    assert np.allclose(q1[:, 3:], q0[:, 3:])
    assert np.allclose(qpos_to_joints(q1, REST_OFFSETS, lift=lift), qpos_to_joints(q0, REST_OFFSETS))


def test_qvel_matches_mujoco_differentiate_pos(walk: np.ndarray) -> None:
    model = build_model(offsets_from_joints(walk))
    qpos = joints_to_qpos(walk, model)
    fwd = qvel_from_qpos(qpos, DT, scheme="forward")
    ref = np.zeros(NV)
    for t in range(len(qpos) - 1):
        mujoco.mj_differentiatePos(model, ref, DT, qpos[t], qpos[t + 1])
        assert np.allclose(fwd[t], ref, atol=1e-9)
        nxt = qpos[t].copy()
        mujoco.mj_integratePos(model, nxt, fwd[t], DT)
        assert np.allclose(nxt[:3], qpos[t + 1, :3]) and np.allclose(nxt[7:], qpos[t + 1, 7:])
        assert abs(abs(np.dot(nxt[3:7], qpos[t + 1, 3:7])) - 1.0) < 1e-9
    central = qvel_from_qpos(qpos, DT)
    bwd = qvel_from_qpos(qpos, DT, scheme="backward")
    assert np.allclose(central[1:-1, 6:], 0.5 * (fwd[1:-1, 6:] + bwd[1:-1, 6:]))
    assert np.allclose(central[1:-1, :3], 0.5 * (fwd[1:-1, :3] + bwd[1:-1, :3]))
    # the root's angular velocity is in its local frame: a pure yaw spin reads about local z
    q = np.tile(qpos[0], (3, 1))
    for k, yaw in enumerate((0.0, 0.1, 0.2)):
        q[k, 3:7] = Rotation.from_euler("z", yaw).as_quat(scalar_first=True)
    w = qvel_from_qpos(q, DT)[1, 3:6]
    assert np.allclose(w, [0.0, 0.0, 0.1 / DT])
    assert np.allclose(qvel_from_qpos(qpos[:1], DT), 0.0)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: joints_to_qpos(np.zeros((5, 21, 3))), r"joints must have shape"),
        (lambda: joints_to_qpos(np.zeros((22, 3))), r"joints must have shape"),
        (lambda: joints_to_qpos(np.zeros((0, 22, 3))), r"zero frames"),
        (lambda: joints_to_qpos(np.full((4, 22, 3), np.nan)), r"NaN"),
        (lambda: joints_to_qpos(np.zeros((4, 22, 3)), np.zeros((21, 3))), r"offsets must be"),
        (lambda: qpos_to_joints(np.zeros((4, 69))), r"qpos must have shape"),
        (lambda: qpos_to_joints(np.full((4, 70), np.inf)), r"NaN or infinite"),
        (lambda: qpos_to_joints(_REST_QPOS, method="bogus"), r"method must be"),
        (lambda: qpos_to_joints(_REST_QPOS, REST_OFFSETS, method="mujoco"), r"compiled model"),
        (lambda: qpos_to_joints(np.zeros((4, 70))), r"zero root quaternion"),
        (lambda: qvel_from_qpos(_REST_QPOS, 0.0), r"dt must be positive"),
        (lambda: qvel_from_qpos(_REST_QPOS, 0.1, scheme="x"), r"scheme must be"),
    ],
)
def test_bad_input_raises_one_line_shape_error(call, match: str) -> None:
    with pytest.raises(ShapeError, match=match) as info:
        call()
    assert "\n" not in str(info.value)


def test_synthetic_motion_is_realistic(walk: np.ndarray) -> None:
    """Guard on the fixture itself: a forward walk, upright, feet below the pelvis."""
    assert walk.shape == (60, 22, 3)
    assert (walk[:, 0, 1] > walk[:, [7, 8], 1].max(-1) + 0.6).all()
    assert walk[-1, 0, 2] - walk[0, 0, 2] > 3.0
    assert np.allclose(gait_joints(REST_OFFSETS)[:, 0], walk[:, 0])
