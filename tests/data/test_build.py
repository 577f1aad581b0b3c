import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.conventions import MAX_FRAMES, MIN_FRAMES
from physmotion.data.build import (
    SPLITS,
    BuildConfig,
    build_activations,
    build_dataset,
    load_activations,
    mirror_text,
    split_of,
    windows,
)
from physmotion.data.stats import dataset_stats
from tests.conftest import WHOLE_BUILD
from physmotion.errors import PhysmotionError, ShapeError
from physmotion.features.humanml3d import FEATURE_DIM, recover_from_ric
from physmotion.io.importer import load_manifest
from physmotion.physics.activations import ACTIVATION_CHANNELS, activations
from tests.cli_runner import invoke


def _index(root: Path) -> list[dict]:
    with open(root / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_layout_and_counts(built_dir: Path, built) -> None:
    for sub in ("new_joints", "new_joint_vecs", "texts"):
        assert (built_dir / sub).is_dir()
    for name in ("Mean.npy", "Std.npy", "index.csv", "build_info.json", "train.txt", "val.txt", "test.txt"):
        assert (built_dir / name).is_file()
    mean, std = np.load(built_dir / "Mean.npy"), np.load(built_dir / "Std.npy")
    assert mean.shape == std.shape == (FEATURE_DIM,)
    assert np.all(std > 0) and np.all(np.isfinite(mean))
    ids = [line for s in SPLITS for line in (built_dir / f"{s}.txt").read_text().split()]
    assert len(ids) == len(set(ids)) == len(_index(built_dir))
    assert all(n > 0 for n in built.num_items.values())
    assert built.minutes > 30  # the collection holds about 38 minutes; short clips cost a little
    print(f"\nbuilt {sum(built.num_items.values())} items {built.num_items}, {built.minutes:.2f} min, "
          f"skipped {len(built.skipped)}: {built.skipped}")


def test_every_skip_has_a_reason(built) -> None:
    assert all(isinstance(r, str) and r and "\n" not in r for r in built.skipped.values())


def test_splits_keep_takes_and_clips_on_one_side(built_dir: Path) -> None:
    side_of_take: dict[str, str] = {}
    side_of_clip: dict[str, str] = {}
    for row in _index(built_dir):
        assert side_of_take.setdefault(row["take"], row["split"]) == row["split"]
        assert side_of_clip.setdefault(row["clip"], row["split"]) == row["split"]
    assert set(side_of_take.values()) == set(SPLITS)


def test_window_lengths(built_dir: Path) -> None:
    for path in (built_dir / "new_joint_vecs").glob("*.npy"):
        feats = np.load(path)
        joints = np.load(built_dir / "new_joints" / path.name)
        assert MIN_FRAMES <= feats.shape[0] <= MAX_FRAMES
        assert feats.shape == (joints.shape[0], FEATURE_DIM)


def test_features_to_joints_round_trip_over_whole_dataset(built_dir: Path) -> None:
    errors = []
    for path in sorted((built_dir / "new_joint_vecs").glob("*.npy")):
        rec = recover_from_ric(torch.from_numpy(np.load(path))).numpy()
        ref = np.load(built_dir / "new_joints" / path.name)
        errors.append(np.linalg.norm(rec - ref, axis=-1).mean())
    mean_mm = float(np.mean(errors)) * 1000
    print(f"\nround trip features -> joints over {len(errors)} items: mean {mean_mm:.4f} mm, "
          f"worst item {max(errors) * 1000:.4f} mm")
    assert mean_mm < 1.0


def test_licence_tags_follow_the_manifest(built_dir: Path, mocap_dir: Path) -> None:
    tag_of = {c.clip: c.licence_tag for c in load_manifest(mocap_dir)}
    rows = _index(built_dir)
    assert all(row["licence_tag"] == tag_of[row["clip"]] for row in rows)
    assert {row["licence_tag"] for row in rows} == {"", "NC"}
    info = json.loads((built_dir / "build_info.json").read_text())
    assert info["licence_tags"] == ["NC", "open"]


def test_mirrored_copies_have_mirrored_captions(built_dir: Path) -> None:
    rows = {r["id"]: r for r in _index(built_dir)}
    mirrored = [i for i, r in rows.items() if r["mirrored"] == "1"]
    assert mirrored and all(i[1:] in rows for i in mirrored)
    assert mirror_text("Turns Left then right") == "Turns Right then left"


@pytest.mark.slow  # a second build of the whole collection
def test_two_builds_are_identical(built_dir: Path, mocap_dir: Path, tmp_path: Path) -> None:
    again = build_dataset(mocap_dir, tmp_path / "again", WHOLE_BUILD, progress=False).out
    for name in ("train.txt", "val.txt", "test.txt", "index.csv", "Mean.npy", "Std.npy"):
        assert (again / name).read_bytes() == (built_dir / name).read_bytes(), name
    a, b = dataset_stats(built_dir), dataset_stats(again)
    assert (a.items, a.minutes, a.vocabulary) == (b.items, b.minutes, b.vocabulary)


@pytest.mark.slow  # builds every CMU clip of the collection
def test_exclude_non_commercial(mocap_dir: Path, tmp_path: Path) -> None:
    out = build_dataset(mocap_dir, tmp_path / "open", BuildConfig(exclude_licences=("NC",)), progress=False).out
    rows = _index(out)
    assert rows and all(r["licence_tag"] == "" for r in rows)
    assert all(not r["source"].startswith("bandai") for r in rows)


def test_refuses_to_overwrite_a_foreign_folder(mocap_dir: Path, tmp_path: Path) -> None:
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "precious.txt").write_text("keep me")
    with pytest.raises(PhysmotionError, match="not a physmotion dataset build"):
        build_dataset(mocap_dir, tmp_path / "mine", progress=False)
    assert (tmp_path / "mine" / "precious.txt").read_text() == "keep me"


@pytest.mark.parametrize("frames", [41, 196, 197, 198, 400, 1000])
def test_windows_cover_the_clip_within_limits(frames: int) -> None:
    wins = windows(frames)
    assert wins[0][0] == 0 and wins[-1][1] == frames
    assert all(b == c + 1 for (_, b), (c, _) in zip(wins[:-1], wins[1:]))  # share one joint frame
    assert all(e - s - 1 <= MAX_FRAMES for s, e in wins)


def test_split_assignment_is_stable_and_salted() -> None:
    takes = [f"take_{i}" for i in range(400)]
    a = [split_of(t, BuildConfig()) for t in takes]
    assert a == [split_of(t, BuildConfig()) for t in takes]
    assert a != [split_of(t, BuildConfig(seed=1)) for t in takes]
    share = a.count("train") / len(a)
    assert 0.7 < share < 0.9


# --- activation cache, on a build of a few clips ---

_FEW_CLIPS = ("bandai2_dataset-2_walk_normal_001", "bandai2_dataset-2_run_normal_001", "bandai1_dataset-1_bow_active_001")


def _few_clips_manifest(mocap_dir: Path, out: Path) -> Path:
    """A mocap folder whose manifest lists only _FEW_CLIPS (paths made absolute)."""
    out.mkdir(parents=True)
    with open(mocap_dir / "manifest.csv", newline="") as f:
        reader = csv.DictReader(f)
        rows = [r for r in reader if r["clip"] in _FEW_CLIPS]
        fields = reader.fieldnames
    for r in rows:
        r["path"] = str(mocap_dir / r["path"])
    with open(out / "manifest.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    return out


@pytest.fixture(scope="module")
def few_clips(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _few_clips_manifest(mocap_dir, tmp_path_factory.mktemp("few") / "mocap")


@pytest.fixture(scope="module")
def small_build(few_clips: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A build of _FEW_CLIPS (mirrored copies included) with its activation cache, in 2 workers."""
    out = build_dataset(few_clips, tmp_path_factory.mktemp("small") / "data", BuildConfig(jobs=1),
                        progress=False).out  # fmt: skip
    assert build_activations(out, progress=False, jobs=2) == len(list((out / "new_joints").iterdir()))
    return out


def test_activation_cache_matches_a_fresh_computation(small_build: Path) -> None:
    ids = sorted(p.stem for p in (small_build / "new_joints").glob("*.npy"))
    assert len(ids) >= 6 and sorted(p.stem for p in (small_build / "activations").glob("*.npy")) == ids
    for i in ids:
        act = load_activations(small_build, i)
        joints = np.load(small_build / "new_joints" / f"{i}.npy")
        assert act.shape == (len(joints), len(ACTIVATION_CHANNELS)) and act.dtype == np.float32
        assert np.all(np.isfinite(act)) and act.min() >= 0 and act.max() <= 1
    for i in (ids[0], ids[-1]):  # a mirrored and a plain item
        fresh = activations(np.load(small_build / "new_joints" / f"{i}.npy"))
        assert load_activations(small_build, i).tobytes() == fresh.tobytes()
    info = json.loads((small_build / "build_info.json").read_text())
    assert info["activations"]["channels"] == list(ACTIVATION_CHANNELS)
    assert info["activations"]["items"] == len(ids) and info["items"]  # the build's own record is kept
    assert not [p for p in small_build.iterdir() if p.name.startswith(".")]  # no temporary left


def test_activation_cache_is_deterministic(small_build: Path, tmp_path: Path) -> None:
    again = tmp_path / "again"
    shutil.copytree(small_build, again)
    shutil.rmtree(again / "activations")
    build_activations(again, progress=False, jobs=1)  # in this process, where small_build used workers
    for path in sorted((small_build / "activations").glob("*.npy")):
        assert (again / "activations" / path.name).read_bytes() == path.read_bytes()


def test_a_failed_activation_build_leaves_the_old_cache(small_build: Path, tmp_path: Path) -> None:
    broken = tmp_path / "broken"
    shutil.copytree(small_build, broken)
    before = {p.name: p.read_bytes() for p in (broken / "activations").iterdir()}
    victim = max((broken / "new_joints").iterdir())
    np.save(victim, np.zeros((2, 22, 3), dtype=np.float32))  # too short for accelerations
    with pytest.raises(ShapeError, match="at least 3 frames"):
        build_activations(broken, progress=False, jobs=1)
    assert {p.name: p.read_bytes() for p in (broken / "activations").iterdir()} == before
    assert not [p for p in broken.iterdir() if p.name.startswith(".")]


def test_missing_activation_cache_is_a_one_line_error(small_build: Path, tmp_path: Path) -> None:
    bare = tmp_path / "bare"
    shutil.copytree(small_build, bare, ignore=shutil.ignore_patterns("activations"))
    with pytest.raises(PhysmotionError, match="physmotion data build --activations") as err:
        load_activations(bare, "anything")
    assert "\n" not in str(err.value)
    with pytest.raises(PhysmotionError, match="no cached activations for 'nope'"):
        load_activations(small_build, "nope")
    with pytest.raises(PhysmotionError, match="not a physmotion dataset build"):
        build_activations(tmp_path / "nothing", progress=False)


def test_cli_build_with_activations(few_clips: Path, small_build: Path, tmp_path: Path) -> None:
    out = tmp_path / "cli"
    res = invoke("data", "build", "--source", few_clips, "-o", out, "--jobs", "1", "--activations")
    assert res.returncode == 0, res.stderr
    assert "activations for" in res.stdout
    for path in (small_build / "activations").glob("*.npy"):  # the same as the library's cache
        assert (out / "activations" / path.name).read_bytes() == path.read_bytes()


# --- the 329-d build (BioMoDiffuse: the 263 HumanML3D features + 66 joint accelerations) ---


def test_329_build_extends_the_263_build(built_dir: Path, built329_dir: Path) -> None:
    for name in ("train.txt", "val.txt", "test.txt", "index.csv"):
        assert (built329_dir / name).read_bytes() == (built_dir / name).read_bytes(), name
    ids = sorted(p.stem for p in (built_dir / "new_joint_vecs").glob("*.npy"))
    assert ids == sorted(p.stem for p in (built329_dir / "new_joint_vecs").glob("*.npy"))
    for i in ids:
        f263 = np.load(built_dir / "new_joint_vecs" / f"{i}.npy")
        f329 = np.load(built329_dir / "new_joint_vecs" / f"{i}.npy")
        assert f329.shape == (len(f263), 329) and f329.dtype == np.float32, i
        np.testing.assert_array_equal(f329[:, :FEATURE_DIM], f263, err_msg=i)
        assert np.all(np.isfinite(f329[:, FEATURE_DIM:]))
        joints = np.load(built329_dir / "new_joints" / f"{i}.npy")
        np.testing.assert_array_equal(joints, np.load(built_dir / "new_joints" / f"{i}.npy"), err_msg=i)
    mean, std = np.load(built329_dir / "Mean.npy"), np.load(built329_dir / "Std.npy")
    assert mean.shape == std.shape == (329,) and np.all(std > 0) and np.all(np.isfinite(mean))
    np.testing.assert_allclose(mean[:FEATURE_DIM], np.load(built_dir / "Mean.npy"), rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(std[:FEATURE_DIM], np.load(built_dir / "Std.npy"), rtol=1e-5, atol=1e-7)
    assert np.unique(std[FEATURE_DIM:]).size == 1  # joint_acc is one group: one std (cal_mean_variance)
    assert json.loads((built329_dir / "build_info.json").read_text())["config"]["features"] == 329


def test_329_joint_accelerations_are_second_differences_of_the_joints(built329_dir: Path) -> None:
    """joint_acc (metres per frame^2, root frame): per joint, as long as the second difference of the
    stored canonical joints (frames 1 .. T-2), and frame 0 repeats frame 1's magnitude."""
    ids = sorted(p.stem for p in (built329_dir / "new_joint_vecs").glob("*.npy"))
    for i in ids[::25]:
        acc = np.load(built329_dir / "new_joint_vecs" / f"{i}.npy")[:, FEATURE_DIM:].reshape(-1, 22, 3)
        joints = np.load(built329_dir / "new_joints" / f"{i}.npy").astype(np.float64)
        second = joints[2:] - 2 * joints[1:-1] + joints[:-2]
        # atol: the stored joints are float32, a few ulp of coordinates up to ~10 m from the origin
        np.testing.assert_allclose(np.linalg.norm(acc[1:-1], axis=-1), np.linalg.norm(second, axis=-1), atol=4e-6)
        np.testing.assert_allclose(np.linalg.norm(acc[0], axis=-1), np.linalg.norm(acc[1], axis=-1), atol=1e-6)


def test_329_build_has_activations_of_every_item(built329_dir: Path) -> None:
    ids = sorted(p.stem for p in (built329_dir / "new_joint_vecs").glob("*.npy"))
    assert sorted(p.stem for p in (built329_dir / "activations").glob("*.npy")) == ids
    for i in ids[::20]:
        act = load_activations(built329_dir, i)
        assert act.shape == (len(np.load(built329_dir / "new_joint_vecs" / f"{i}.npy")), len(ACTIVATION_CHANNELS))


@pytest.mark.parametrize("features", [0, 262, 300, 330])
def test_other_feature_widths_are_refused(mocap_dir: Path, tmp_path: Path, features: int) -> None:
    with pytest.raises(PhysmotionError, match="263 or 329") as err:
        build_dataset(mocap_dir, tmp_path / "out", BuildConfig(features=features), progress=False)
    assert "\n" not in str(err.value) and not (tmp_path / "out").exists()
