from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.ndimage import gaussian_filter1d

from physmotion.errors import ShapeError
from physmotion.features.humanml3d import (
    FEATURE_DIM,
    SLICES,
    UNIFORM_OFFSETS,
    extract_features,
    mirror_features,
    raise_features,
    recover_from_ric,
    recover_from_rot,
    recover_root_rot_pos,
)
from physmotion.skeleton import (
    FACE_JOINTS,
    KINEMATIC_CHAINS,
    NUM_JOINTS,
    RAW_OFFSETS,
    REST_OFFSETS,
    bone_lengths,
    facing_direction,
    mirror_joints,
)

from .conftest import make_kick, make_spin, make_walk, rot_y

# ------------------------------------------------------------------------------------------------
# An independent, literal per-step reference of HumanML3D's process_file (motion_representation.ipynb,
# common/skeleton.py, common/quaternion.py): quaternions (w, x, y, z), a loop per chain, the published
# arcsin for the root angular velocity. Slow and simple; the package's vectorised code must agree.


def _qmul(q: np.ndarray, r: np.ndarray) -> np.ndarray:
    w1, x1, y1, z1 = np.moveaxis(q, -1, 0)
    w2, x2, y2, z2 = np.moveaxis(r, -1, 0)
    return np.stack(
        [
            w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2,
            w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
            w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2,
            w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2,
        ],
        -1,
    )


def _qinv(q: np.ndarray) -> np.ndarray:
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def _qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    qv = q[..., 1:]
    uv = np.cross(qv, v)
    return v + 2 * (q[..., :1] * uv + np.cross(qv, uv))


def _qbetween(v0: np.ndarray, v1: np.ndarray) -> np.ndarray:
    n0, n1 = np.linalg.norm(v0, axis=-1, keepdims=True), np.linalg.norm(v1, axis=-1, keepdims=True)
    w = n0 * n1 + (v0 * v1).sum(-1, keepdims=True)
    q = np.concatenate([w, np.cross(v0, v1)], -1)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _qmat(q: np.ndarray) -> np.ndarray:
    r, i, j, k = np.moveaxis(q, -1, 0)
    two_s = 2.0 / (q * q).sum(-1)
    m = [1 - two_s * (j * j + k * k), two_s * (i * j - k * r), two_s * (i * k + j * r),
         two_s * (i * j + k * r), 1 - two_s * (i * i + k * k), two_s * (j * k - i * r),
         two_s * (i * k - j * r), two_s * (j * k + i * r), 1 - two_s * (i * i + j * j)]  # fmt: skip
    return np.stack(m, -1).reshape(q.shape[:-1] + (3, 3))


def _chain_parents() -> list[int]:
    parents = [-1] * NUM_JOINTS
    for chain in KINEMATIC_CHAINS:
        for a, b in zip(chain[:-1], chain[1:]):
            parents[b] = a
    return parents


def _ik(joints: np.ndarray, smooth: bool) -> np.ndarray:
    l_hip, r_hip, sdr_r, sdr_l = FACE_JOINTS  # the published (swapped) unpacking
    across = (joints[:, r_hip] - joints[:, l_hip]) + (joints[:, sdr_r] - joints[:, sdr_l])
    across = across / np.linalg.norm(across, axis=-1, keepdims=True)
    forward = np.cross(np.array([[0.0, 1.0, 0.0]]), across)
    if smooth:
        forward = gaussian_filter1d(forward, 20, axis=0, mode="nearest")
    forward = forward / np.linalg.norm(forward, axis=-1, keepdims=True)
    root_quat = _qbetween(forward, np.tile([0.0, 0.0, 1.0], (len(forward), 1)))
    root_quat[0] = [1.0, 0.0, 0.0, 0.0]
    quat = np.zeros(joints.shape[:-1] + (4,))
    quat[:, 0] = root_quat
    for chain in KINEMATIC_CHAINS:
        rot = root_quat
        for a, b in zip(chain[:-1], chain[1:]):
            v = joints[:, b] - joints[:, a]
            v = v / np.linalg.norm(v, axis=-1, keepdims=True)
            rot_uv = _qbetween(np.tile(RAW_OFFSETS[b], (len(joints), 1)), v)
            local = _qmul(_qinv(rot), rot_uv)
            quat[:, b] = local
            rot = _qmul(rot, local)
    return quat


def _fk(quat: np.ndarray, root: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    joints = np.zeros(quat.shape[:-1] + (3,))
    joints[:, 0] = root
    for chain in KINEMATIC_CHAINS:
        rot = quat[:, 0]
        for a, b in zip(chain[:-1], chain[1:]):
            rot = _qmul(rot, quat[:, b])
            joints[:, b] = _qrot(rot, np.tile(offsets[b], (len(quat), 1))) + joints[:, a]
    return joints


def reference_process_file(positions: np.ndarray, feet_thre: float = 0.002) -> np.ndarray:
    positions = positions.astype(np.float64)
    parents = _chain_parents()
    first = positions[0]
    src_len = [0.0] + [np.linalg.norm(first[j] - first[parents[j]]) for j in range(1, NUM_JOINTS)]
    tgt_len = np.linalg.norm(UNIFORM_OFFSETS, axis=-1)
    scale = (tgt_len[5] + tgt_len[8]) / (src_len[5] + src_len[8])
    positions = _fk(_ik(positions, smooth=False), positions[:, 0] * scale, UNIFORM_OFFSETS)

    positions[:, :, 1] -= positions.min(axis=0).min(axis=0)[1]
    init = positions[0]
    positions = positions - init[0] * np.array([1, 0, 1])
    r_hip, l_hip, sdr_r, sdr_l = FACE_JOINTS  # process_file's (correct) unpacking
    across = (init[r_hip] - init[l_hip]) + (init[sdr_r] - init[sdr_l])
    forward = np.cross(np.array([0.0, 1.0, 0.0]), across / np.linalg.norm(across))
    quat_init = _qbetween(forward / np.linalg.norm(forward), np.array([0.0, 0.0, 1.0]))
    positions = _qrot(np.broadcast_to(quat_init, positions.shape[:-1] + (4,)), positions)
    glob = positions.copy()

    def contact(fid: list[int]) -> np.ndarray:
        return (((glob[1:, fid] - glob[:-1, fid]) ** 2).sum(-1) < feet_thre).astype(np.float64)

    quat = _ik(positions, smooth=True)
    cont6d = np.concatenate([_qmat(quat)[..., 0], _qmat(quat)[..., 1]], -1)
    r_rot = quat[:, 0].copy()
    velocity = _qrot(r_rot[1:], positions[1:, 0] - positions[:-1, 0])
    r_velocity = _qmul(r_rot[1:], _qinv(r_rot[:-1]))
    positions[..., 0] -= positions[:, 0:1, 0]
    positions[..., 2] -= positions[:, 0:1, 2]
    positions = _qrot(np.repeat(r_rot[:, None], NUM_JOINTS, axis=1), positions)
    n = len(positions)
    rot_vel = np.arcsin(r_velocity[:, 2:3])
    root_data = np.concatenate([rot_vel, velocity[:, [0, 2]], positions[:-1, 0, 1:2]], -1)
    local_vel = _qrot(np.repeat(r_rot[:-1, None], NUM_JOINTS, axis=1), glob[1:] - glob[:-1])
    ric = positions[:-1, 1:].reshape(n - 1, -1)
    rot = cont6d[:-1, 1:].reshape(n - 1, -1)
    vel = local_vel.reshape(n - 1, -1)
    return np.concatenate([root_data, ric, rot, vel, contact([7, 10]), contact([8, 11])], -1)


# ------------------------------------------------------------------------------------------------


def test_slices_partition_the_263_vector() -> None:
    spans = sorted((s.start, s.stop) for s in SLICES.values())
    assert spans[0][0] == 0 and spans[-1][1] == FEATURE_DIM == 263
    assert all(a[1] == b[0] for a, b in zip(spans[:-1], spans[1:]))
    sizes = {k: s.stop - s.start for k, s in SLICES.items()}
    assert sizes == {"root_rot_vel": 1, "root_lin_vel": 2, "root_y": 1, "ric": 63, "rot6d": 126,
                     "local_vel": 66, "foot_contact": 4}  # fmt: skip


def test_shapes_and_dtypes(walk: np.ndarray) -> None:
    feats, canon = extract_features(walk)
    assert feats.shape == (len(walk) - 1, 263) and feats.dtype == np.float32
    assert canon.shape == walk.shape and canon.dtype == np.float32
    assert np.isfinite(feats).all()
    assert set(np.unique(feats[:, SLICES["foot_contact"]])) <= {0.0, 1.0}


@pytest.mark.parametrize("clip", [make_walk(), make_kick(), make_walk(80, turn_deg=-60.0)])
def test_matches_literal_reference_of_published_process_file(clip: np.ndarray) -> None:
    feats, _ = extract_features(clip)
    ref = reference_process_file(clip)
    err = np.abs(feats - ref).max(axis=0)
    assert err.max() < 1e-6, {k: float(err[s].max()) for k, s in SLICES.items()}  # float32 rounding


def test_round_trip_recover_from_ric(walk: np.ndarray) -> None:
    feats, canon = extract_features(walk)
    rec = recover_from_ric(feats)
    assert rec.shape == (len(walk) - 1, 22, 3) and rec.dtype == np.float32
    err = np.linalg.norm(rec - canon[:-1], axis=-1)
    print(f"\nround trip recover_from_ric: mean {err.mean() * 1e3:.2e} mm, max {err.max() * 1e3:.2e} mm")
    assert err.mean() < 1e-3  # the bound (1 mm)
    assert err.max() < 1e-5  # what float32 features actually give


def test_floor_false_keeps_the_heights(walk: np.ndarray) -> None:
    # The features store absolute heights: without the re-flooring, a motion 3 cm above HumanML3D's floor
    # comes back 3 cm above it, and everything but the heights is the floored features' own.
    floored, canon = extract_features(walk)
    lifted = walk - np.array([0.0, walk[..., 1].min() - 0.03, 0.0])  # lowest joint at y = 3 cm
    kept, kept_canon = extract_features(lifted, floor=False)
    np.testing.assert_allclose(kept_canon[..., 1], canon[..., 1] + 0.03, atol=1e-6)
    np.testing.assert_allclose(recover_from_ric(kept), kept_canon[:-1], atol=1e-5)
    np.testing.assert_allclose(kept, raise_features(floored, 0.03), atol=1e-6)


def test_raise_features_moves_only_the_heights(walk: np.ndarray) -> None:
    feats, _ = extract_features(walk)
    up = raise_features(feats, 0.025)
    moved = np.abs(up - feats).max(axis=0) > 1e-6
    assert moved.sum() == NUM_JOINTS  # root y and the 21 ric heights, nothing else
    np.testing.assert_allclose(recover_from_ric(up), recover_from_ric(feats) + [0.0, 0.025, 0.0], atol=1e-6)
    as_torch = raise_features(torch.from_numpy(feats), 0.025)
    assert isinstance(as_torch, torch.Tensor) and np.allclose(as_torch.numpy(), up)
    assert np.array_equal(feats, extract_features(walk)[0])  # the input is not changed


@pytest.mark.parametrize("clip", [make_spin(), make_walk(200, turn_deg=400.0)])
def test_round_trip_through_180_degree_heading(clip: np.ndarray) -> None:
    # The published arcsin(q_y) flips sign on the frame where the heading crosses 180 degrees; on these
    # clips that bends the recovered motion by 10-26 cm. The wrapped half-angle keeps it exact.
    feats, canon = extract_features(clip)
    assert np.abs(recover_from_ric(feats) - canon[:-1]).max() < 1e-5


def test_canonical_frame(walk: np.ndarray) -> None:
    _, canon = extract_features(walk)
    assert canon[..., 1].min() == pytest.approx(0.0, abs=1e-7)  # lowest joint of the clip on the floor
    np.testing.assert_allclose(canon[0, 0, [0, 2]], 0.0, atol=1e-7)  # root XZ of frame 0 at the origin
    np.testing.assert_allclose(facing_direction(canon[0].astype(np.float64)), [0, 0, 1], atol=1e-6)
    target = np.linalg.norm(UNIFORM_OFFSETS, axis=-1)
    np.testing.assert_allclose(bone_lengths(canon), np.broadcast_to(target, canon.shape[:2]), atol=1e-6)


def test_features_do_not_depend_on_placement(walk: np.ndarray) -> None:
    moved = (rot_y(np.array(1.0)) @ walk[..., None])[..., 0] + np.array([3.0, 0.5, -2.0])
    f0, c0 = extract_features(walk)
    f1, c1 = extract_features(moved)
    np.testing.assert_allclose(f1, f0, atol=2e-5)
    np.testing.assert_allclose(c1, c0, atol=2e-5)


def test_uniform_skeleton_rescales_a_smaller_body(walk: np.ndarray) -> None:
    small = 0.8 * walk
    f_small, c_small = extract_features(small)
    f_ref, c_ref = extract_features(walk)
    np.testing.assert_allclose(c_small, c_ref, atol=1e-5)
    np.testing.assert_allclose(f_small, f_ref, atol=1e-5)
    _, c_raw = extract_features(small, uniform=False)
    np.testing.assert_allclose(bone_lengths(c_raw), 0.8 * bone_lengths(c_ref), atol=1e-5)


def test_default_body_is_already_uniform(walk: np.ndarray) -> None:
    np.testing.assert_allclose(extract_features(walk, uniform=False)[0], extract_features(walk)[0], atol=1e-5)


def _translate(speed: float, n: int = 30) -> np.ndarray:
    stand = make_kick(n)[:1]  # standing pose
    steps = np.arange(n)[:, None, None] * np.array([0.0, 0.0, speed])
    return stand + steps


@pytest.mark.parametrize(("speed", "contact"), [(0.04, 1.0), (0.05, 0.0)])
def test_straight_translation_values(speed: float, contact: float) -> None:
    feats, canon = extract_features(_translate(speed))
    np.testing.assert_allclose(feats[:, SLICES["root_rot_vel"]], 0.0, atol=1e-7)
    lin_vel = feats[:, SLICES["root_lin_vel"]]
    np.testing.assert_allclose(lin_vel, np.tile([0.0, speed], (len(feats), 1)), atol=1e-7)
    np.testing.assert_allclose(feats[:, SLICES["root_y"]], canon[0, 0, 1], atol=1e-7)
    vel = feats[:, SLICES["local_vel"]].reshape(-1, 22, 3)
    np.testing.assert_allclose(vel, np.broadcast_to([0.0, 0.0, speed], vel.shape), atol=1e-7)
    # squared step 0.0016 < 0.002 is contact, 0.0025 is not
    assert np.all(feats[:, SLICES["foot_contact"]] == contact)


def test_foot_contacts_follow_the_feet(kick: np.ndarray) -> None:
    contacts = extract_features(kick)[0][:, SLICES["foot_contact"]]
    left, right = contacts[:, :2], contacts[:, 2:]
    assert np.all(left == 1.0)  # the standing foot never moves
    moving = np.zeros(len(contacts), dtype=bool)
    moving[20:25] = moving[40:45] = True  # the fast kick and the fast return
    assert np.all(right[moving] == 0.0)
    assert np.all(right[~moving] == 1.0)


def test_feet_threshold_is_applied(walk: np.ndarray) -> None:
    assert np.all(extract_features(walk, feet_thre=0.0)[0][:, SLICES["foot_contact"]] == 0.0)
    assert np.all(extract_features(walk, feet_thre=1.0)[0][:, SLICES["foot_contact"]] == 1.0)


def test_root_rotation_velocity_is_a_signed_half_angle(spin: np.ndarray) -> None:
    feats, canon = extract_features(spin)
    # Left turn at 4 deg/frame: -2 deg (half-angle, world -> root frame) away from the smoothing's edges.
    np.testing.assert_allclose(feats[80:120, 0], -np.deg2rad(2.0), atol=1e-5)
    quat, r_pos = recover_root_rot_pos(feats)
    assert quat.shape == (len(feats), 4) and r_pos.shape == (len(feats), 3)
    np.testing.assert_allclose(np.linalg.norm(quat, axis=-1), 1.0, atol=1e-6)
    np.testing.assert_allclose(quat[:, [1, 3]], 0.0)
    np.testing.assert_allclose(r_pos, canon[:-1, 0], atol=1e-6)
    # r_rot turns the body's facing onto +Z (frames where the smoothing window is complete).
    yaw = 2 * np.arctan2(quat[80:120, 2], quat[80:120, 0])
    facing = facing_direction(canon[80:120].astype(np.float64))
    turned = (rot_y(yaw) @ facing[..., None])[..., 0]
    np.testing.assert_allclose(turned, np.tile([0.0, 0.0, 1.0], (40, 1)), atol=1e-4)


@pytest.mark.parametrize("clip", [make_walk(), make_spin()])
def test_rot6d_block_reproduces_the_joints_by_forward_kinematics(clip: np.ndarray) -> None:
    feats, canon = extract_features(clip)
    six = feats[:, SLICES["rot6d"]].reshape(-1, 21, 2, 3).astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(six, axis=-1), 1.0, atol=1e-6)
    np.testing.assert_allclose(np.sum(six[:, :, 0] * six[:, :, 1], -1), 0.0, atol=1e-6)
    assert np.abs(recover_from_rot(feats) - canon[:-1]).max() < 1e-5


def test_torch_and_numpy_agree(walk: np.ndarray) -> None:
    feats, _ = extract_features(walk)
    tf = torch.from_numpy(feats)
    for fn in (recover_from_ric, recover_from_rot, mirror_features):
        out = fn(tf)
        assert isinstance(out, torch.Tensor) and out.dtype == torch.float32
        np.testing.assert_allclose(out.numpy(), fn(feats), atol=1e-5)
    quat_t, pos_t = recover_root_rot_pos(tf)
    quat_n, pos_n = recover_root_rot_pos(feats)
    np.testing.assert_allclose(quat_t.numpy(), quat_n, atol=1e-5)
    np.testing.assert_allclose(pos_t.numpy(), pos_n, atol=1e-5)


def test_batch_equals_one_by_one() -> None:
    clips = [make_walk(60), make_spin(60), make_kick(60), make_walk(60, turn_deg=-200.0)]
    feats = np.stack([extract_features(c)[0] for c in clips])  # (4, 59, 263)
    for fn in (recover_from_ric, recover_from_rot):
        single = np.stack([fn(f) for f in feats])
        np.testing.assert_array_equal(fn(feats), single)
        nested = fn(feats.reshape(2, 2, 59, 263))
        np.testing.assert_array_equal(nested, single.reshape((2, 2) + single.shape[1:]))
        np.testing.assert_allclose(fn(torch.from_numpy(feats)).numpy(), single, atol=1e-5)
    quat, pos = recover_root_rot_pos(feats)
    for i, f in enumerate(feats):
        np.testing.assert_array_equal(quat[i], recover_root_rot_pos(f)[0])
        np.testing.assert_array_equal(pos[i], recover_root_rot_pos(f)[1])


def test_torch_recovery_is_differentiable(walk: np.ndarray) -> None:
    feats = torch.from_numpy(extract_features(walk)[0]).double().requires_grad_(True)
    recover_from_ric(feats[None]).square().sum().backward()
    assert feats.grad is not None and torch.isfinite(feats.grad).all()
    assert feats.grad[:, SLICES["ric"]].abs().sum() > 0 and feats.grad[:, 0].abs().sum() > 0


@pytest.mark.parametrize("clip", [make_walk(), make_kick(), make_spin(), make_walk(120, turn_deg=-250.0)])
def test_mirror_features_equals_features_of_mirrored_joints(clip: np.ndarray) -> None:
    feats, _ = extract_features(clip)
    mirrored, _ = extract_features(mirror_joints(clip))
    np.testing.assert_allclose(mirror_features(feats), mirrored, atol=1e-5)


def test_mirror_features_is_an_involution(walk: np.ndarray) -> None:
    feats, _ = extract_features(walk)
    assert not np.allclose(mirror_features(feats), feats)
    np.testing.assert_array_equal(mirror_features(mirror_features(feats)), feats)
    tf = torch.from_numpy(feats)
    assert torch.equal(mirror_features(mirror_features(tf)), tf)
    np.testing.assert_array_equal(mirror_features(feats[3]), mirror_features(feats)[3])  # a single vector


def test_mirror_swaps_foot_contacts(kick: np.ndarray) -> None:
    feats, _ = extract_features(kick)
    contacts = mirror_features(feats)[:, SLICES["foot_contact"]]
    np.testing.assert_array_equal(contacts[:, :2], feats[:, SLICES["foot_contact"]][:, 2:])
    np.testing.assert_array_equal(contacts[:, 2:], feats[:, SLICES["foot_contact"]][:, :2])


@pytest.mark.parametrize(
    "bad",
    [
        np.full((10, 22, 3), np.nan),
        np.concatenate([make_walk(10)[:9], np.full((1, 22, 3), np.inf)]),
        np.zeros((10, 21, 3)),
        np.zeros((22, 3)),
        np.zeros((10, 22, 2)),
        make_walk(10)[:1],
        make_walk(10)[:0],
    ],
    ids=["nan", "inf", "21-joints", "no-time-axis", "2d-points", "one-frame", "no-frames"],
)
def test_bad_joints_raise_shape_error(bad: np.ndarray) -> None:
    with pytest.raises(ShapeError):
        extract_features(bad)


def test_bone_opposite_its_rest_direction_stays_finite(walk: np.ndarray) -> None:
    # The left shin pointing straight up, exactly against t2m_raw_offsets' (0, -1, 0): qbetween's 0/0 case.
    joints = walk.copy()
    shift = joints[:, 1] + np.array([0.0, 0.4, 0.0]) - joints[:, 4]
    joints[:, [4, 7, 10]] += shift[:, None]
    feats, canon = extract_features(joints)
    assert np.isfinite(feats).all()
    assert np.abs(recover_from_rot(feats) - canon[:-1]).max() < 1e-5


def test_bad_features_raise_shape_error() -> None:
    with pytest.raises(ShapeError):
        recover_from_ric(np.zeros((10, 20)))
    with pytest.raises(ShapeError):
        recover_from_ric([[0.0] * 263])  # type: ignore[arg-type]
    with pytest.raises(ShapeError):
        mirror_features(np.zeros((10, 100)))


def test_rest_offsets_are_the_uniform_lengths() -> None:
    lengths = np.linalg.norm(UNIFORM_OFFSETS, axis=-1)
    np.testing.assert_allclose(lengths, np.linalg.norm(REST_OFFSETS, axis=-1))
    np.testing.assert_allclose(UNIFORM_OFFSETS[1:] / lengths[1:, None], RAW_OFFSETS[1:])
