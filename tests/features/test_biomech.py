from __future__ import annotations

import numpy as np
import pytest
import torch

from physmotion.errors import ShapeError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH, extract_features_329, to_263
from physmotion.features.humanml3d import (
    SLICES,
    extract_features,
    mirror_features,
    recover_from_ric,
    recover_root_rot_pos,
)
from physmotion.skeleton import mirror_joints

from .conftest import make_kick, make_spin, make_walk, rot_y

ACC = SLICES_BIOMECH["joint_acc"]


def test_layout() -> None:
    assert FEATURE_DIM_BIOMECH == 329
    assert ACC == slice(263, 329)
    assert {k: v for k, v in SLICES_BIOMECH.items() if k != "joint_acc"} == SLICES


@pytest.mark.parametrize("clip", [make_walk(), make_kick(), make_spin()])
def test_first_263_dims_are_the_humanml3d_features(clip: np.ndarray) -> None:
    f329, canon329 = extract_features_329(clip)
    f263, canon263 = extract_features(clip)
    assert f329.shape == (len(clip) - 1, 329) and f329.dtype == np.float32
    np.testing.assert_array_equal(f329[:, :263], f263)
    np.testing.assert_array_equal(to_263(f329), f263)
    np.testing.assert_array_equal(canon329, canon263)
    np.testing.assert_array_equal(recover_from_ric(f329), recover_from_ric(f263))


def _stand_moving(z_of_t: np.ndarray) -> np.ndarray:
    stand = make_kick(len(z_of_t))[:1]
    return stand + z_of_t[:, None, None] * np.array([0.0, 0.0, 1.0])


def test_constant_velocity_has_zero_acceleration() -> None:
    feats, _ = extract_features_329(_stand_moving(0.03 * np.arange(30)))
    np.testing.assert_allclose(feats[:, ACC], 0.0, atol=1e-7)


def test_constant_acceleration_is_recovered_per_frame_squared() -> None:
    a = 0.002  # metres / frame^2 (0.8 m/s^2 at 20 fps)
    t = np.arange(30, dtype=np.float64)
    feats, _ = extract_features_329(_stand_moving(0.5 * a * t**2))
    acc = feats[:, ACC].reshape(-1, 22, 3)
    np.testing.assert_allclose(acc, np.broadcast_to([0.0, 0.0, a], acc.shape), atol=1e-7)


def test_acceleration_frame_convention(walk: np.ndarray) -> None:
    # joint_acc[t] = r_rot[t] (p[t+1] - 2 p[t] + p[t-1]), frame 0 borrowing frame 1's second difference;
    # r_rot[t] from the features themselves (recover_root_rot_pos), p the canonical joints.
    feats, canon = extract_features_329(walk)
    canon = canon.astype(np.float64)
    second = canon[2:] - 2 * canon[1:-1] + canon[:-2]
    expected_world = np.concatenate([second[:1], second])  # (T-1, 22, 3)
    quat, _ = recover_root_rot_pos(feats.astype(np.float64))
    yaw = 2 * np.arctan2(quat[:, 2], quat[:, 0])
    expected = (rot_y(yaw)[:, None] @ expected_world[..., None])[..., 0]
    np.testing.assert_allclose(feats[:, ACC].reshape(-1, 22, 3), expected, atol=1e-6)
    assert np.abs(expected).max() > 1e-3  # the walk does accelerate


def test_accelerations_do_not_depend_on_heading(walk: np.ndarray) -> None:
    turned = (rot_y(np.array(2.0)) @ walk[..., None])[..., 0]
    np.testing.assert_allclose(extract_features_329(turned)[0], extract_features_329(walk)[0], atol=2e-5)


@pytest.mark.parametrize("clip", [make_walk(), make_spin()])
def test_mirror_329(clip: np.ndarray) -> None:
    feats, _ = extract_features_329(clip)
    mirrored, _ = extract_features_329(mirror_joints(clip))
    np.testing.assert_allclose(mirror_features(feats), mirrored, atol=1e-5)
    np.testing.assert_array_equal(mirror_features(mirror_features(feats)), feats)


def test_to_263_on_torch_and_bad_input(walk: np.ndarray) -> None:
    feats = torch.from_numpy(extract_features_329(walk)[0])
    assert torch.equal(to_263(feats), feats[:, :263])
    with pytest.raises(ShapeError):
        to_263(np.zeros((5, 263)))


def test_too_few_frames_or_bad_joints_raise() -> None:
    with pytest.raises(ShapeError):
        extract_features_329(make_walk(10)[:2])
    with pytest.raises(ShapeError):
        extract_features_329(np.full((10, 22, 3), np.nan))
