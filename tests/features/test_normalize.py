from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.errors import MotionFormatError, PhysmotionError, ShapeError
from physmotion.features.biomech import SLICES_BIOMECH, extract_features_329
from physmotion.features.humanml3d import SLICES, extract_features, mirror_features
from physmotion.features.normalize import Normalizer, compute_mean_std

from .conftest import make_kick, make_spin, make_walk


@pytest.fixture(scope="module")
def feature_list() -> list[np.ndarray]:
    clips = [make_walk(), make_kick(), make_spin(), make_walk(90, turn_deg=-120.0)]
    feats = [extract_features(c)[0] for c in clips]
    return feats + [mirror_features(f) for f in feats]


def test_mean_std_follow_humanml3d(feature_list: list[np.ndarray]) -> None:
    mean, std = compute_mean_std(feature_list)
    assert mean.shape == std.shape == (263,) and mean.dtype == std.dtype == np.float32
    data = np.concatenate(feature_list).astype(np.float64)
    np.testing.assert_allclose(mean, data.mean(0), atol=1e-6)
    raw_std = data.std(0)
    for name, group in SLICES.items():
        # one std per group: the mean of its members' stds
        np.testing.assert_allclose(std[group], raw_std[group].mean(), rtol=1e-5, err_msg=name)
    assert len(np.unique(std)) == len(SLICES)


def test_feat_bias_weights_root_and_contacts(feature_list: list[np.ndarray]) -> None:
    _, std1 = compute_mean_std(feature_list)
    _, std5 = compute_mean_std(feature_list, feat_bias=5.0)
    for name, group in SLICES.items():
        factor = 5.0 if name in ("root_rot_vel", "root_lin_vel", "root_y", "foot_contact") else 1.0
        np.testing.assert_allclose(std5[group], std1[group] / factor, rtol=1e-6, err_msg=name)


def test_mean_std_for_329(walk: np.ndarray) -> None:
    feats = [extract_features_329(c)[0] for c in (walk, make_kick(), make_spin())]
    mean, std = compute_mean_std(feats)
    assert mean.shape == std.shape == (329,)
    acc = SLICES_BIOMECH["joint_acc"]
    raw = np.concatenate(feats).astype(np.float64).std(0)
    np.testing.assert_allclose(std[acc], raw[acc].mean(), rtol=1e-5)
    mean263, std263 = compute_mean_std([f[:, :263] for f in feats])
    np.testing.assert_allclose(std[:263], std263, rtol=1e-6)
    np.testing.assert_allclose(mean[:263], mean263, rtol=1e-6)


def test_constant_groups_get_unit_std(kick: np.ndarray) -> None:
    # A clip standing still except one leg: root velocities and height are constant -> std 0 -> 1.
    feats, _ = extract_features(kick)
    mean, std = compute_mean_std([feats])
    for name in ("root_rot_vel", "root_lin_vel", "root_y"):
        assert np.all(std[SLICES[name]] == 1.0), name
    z = Normalizer(mean, std).normalize(feats)
    assert np.isfinite(z).all()


def test_normalizer_round_trip_numpy_and_torch(feature_list: list[np.ndarray]) -> None:
    norm = Normalizer(*compute_mean_std(feature_list))
    x = feature_list[0]
    z = norm.normalize(x)
    np.testing.assert_allclose(z, (x - norm.mean) / norm.std, rtol=1e-6)
    np.testing.assert_allclose(norm.denormalize(z), x, atol=1e-5)
    # the whole set comes out centred
    allz = norm.normalize(np.concatenate(feature_list))
    np.testing.assert_allclose(allz.mean(0), 0.0, atol=1e-4)
    for dtype in (torch.float32, torch.float64):
        t = torch.from_numpy(x).to(dtype)[None]  # batch of one
        zt = norm.normalize(t)
        assert isinstance(zt, torch.Tensor) and zt.dtype == dtype and zt.shape == t.shape
        np.testing.assert_allclose(zt[0].numpy(), z, atol=1e-5)
        np.testing.assert_allclose(norm.denormalize(zt).numpy(), t.numpy(), atol=1e-5)


def test_save_and_load(tmp_path: Path, feature_list: list[np.ndarray]) -> None:
    norm = Normalizer(*compute_mean_std(feature_list))
    norm.save(tmp_path / "ds")
    # no temporary files left behind
    assert sorted(p.name for p in (tmp_path / "ds").iterdir()) == ["Mean.npy", "Std.npy"]
    assert np.load(tmp_path / "ds" / "Mean.npy").dtype == np.float32
    back = Normalizer.load(tmp_path / "ds")
    np.testing.assert_array_equal(back.mean, norm.mean)
    np.testing.assert_array_equal(back.std, norm.std)


def test_failed_save_leaves_old_files_intact(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    Normalizer(np.zeros(263), np.ones(263)).save(tmp_path)
    calls = {"n": 0}
    real_save = np.save

    def flaky_save(f: object, arr: np.ndarray) -> None:
        calls["n"] += 1
        real_save(f, arr[:10])  # a partial write ...
        raise OSError("disk full")  # ... then a failure

    monkeypatch.setattr(np, "save", flaky_save)
    with pytest.raises(OSError):
        Normalizer(np.full(263, 5.0), np.full(263, 2.0)).save(tmp_path)
    monkeypatch.setattr(np, "save", real_save)
    assert calls["n"] == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Mean.npy", "Std.npy"]
    back = Normalizer.load(tmp_path)
    np.testing.assert_array_equal(back.mean, np.zeros(263))


def test_load_missing_raises_user_error(tmp_path: Path) -> None:
    with pytest.raises(MotionFormatError) as info:
        Normalizer.load(tmp_path)
    assert isinstance(info.value, PhysmotionError) and "Mean.npy" in str(info.value)
    (tmp_path / "Mean.npy").write_bytes(b"not numpy")
    (tmp_path / "Std.npy").write_bytes(b"not numpy")
    with pytest.raises(MotionFormatError):
        Normalizer.load(tmp_path)


def test_bad_statistics_and_inputs_raise() -> None:
    with pytest.raises(ShapeError):
        Normalizer(np.zeros(263), np.ones(262))
    with pytest.raises(ShapeError):
        Normalizer(np.zeros(3), -np.ones(3))
    with pytest.raises(ShapeError):
        Normalizer(np.zeros(3), np.array([1.0, np.nan, 1.0]))
    norm = Normalizer(np.zeros(263), np.ones(263))
    with pytest.raises(ShapeError):
        norm.normalize(np.zeros((4, 329)))
    with pytest.raises(ShapeError):
        compute_mean_std([np.zeros((4, 100))])
    with pytest.raises(ShapeError):
        compute_mean_std([np.zeros((4, 263)), np.zeros((4, 329))])
    with pytest.raises(ShapeError):
        compute_mean_std([])
    with pytest.raises(ShapeError):
        compute_mean_std([np.zeros((4, 263))], feat_bias=0.0)


def test_zero_std_is_guarded() -> None:
    norm = Normalizer(np.zeros(4), np.array([0.0, 1e-9, 2.0, 1.0]))
    np.testing.assert_array_equal(norm.std, [1.0, 1.0, 2.0, 1.0])
    assert np.isfinite(norm.normalize(np.ones((2, 4)))).all()


def test_nan_clips_are_skipped(feature_list: list[np.ndarray]) -> None:
    bad = feature_list[0].copy()
    bad[3, 7] = np.nan
    with pytest.warns(UserWarning, match="NaN"):
        mean, std = compute_mean_std([bad] + feature_list[1:])
    ref_mean, ref_std = compute_mean_std(feature_list[1:])
    np.testing.assert_array_equal(mean, ref_mean)
    np.testing.assert_array_equal(std, ref_std)
