import shutil
from pathlib import Path

import numpy as np
import pytest
import torch

from physmotion.conventions import MAX_FRAMES, MIN_FRAMES
from physmotion.data.dataset import MotionDataset, collate, read_captions
from physmotion.errors import PhysmotionError
from physmotion.features.normalize import Normalizer

pytestmark = pytest.mark.slow


def test_items_are_cropped_to_whole_units(built_dir: Path) -> None:
    ds = MotionDataset(built_dir, "train")
    for i in range(0, len(ds), 7):
        item = ds[i]
        assert item["length"] % 4 == 0 and MIN_FRAMES - 4 <= item["length"] <= MAX_FRAMES
        assert item["motion"].shape == (item["length"], 263)
        assert item["text"] in ds.items[i].captions


def test_normalised_with_the_folder_statistics(built_dir: Path) -> None:
    raw = MotionDataset(built_dir, "val", normalize=False, random_crop=False)
    norm = MotionDataset(built_dir, "val", random_crop=False)
    stats = Normalizer.load(built_dir)
    x = raw[0]["motion"].numpy()
    np.testing.assert_allclose(norm[0]["motion"].numpy(), stats.normalize(x), rtol=1e-5, atol=1e-5)
    train = MotionDataset(built_dir, "train", normalize=True, random_crop=False)
    allf = torch.cat([train[i]["motion"] for i in range(len(train))])
    assert abs(float(allf[:, 4:67].mean())) < 0.2  # ric block is centred by the train statistics


def test_same_seed_same_epoch_same_items(built_dir: Path) -> None:
    a, b = MotionDataset(built_dir, "train", seed=3), MotionDataset(built_dir, "train", seed=3)
    for i in range(0, len(a), 11):
        assert a[i]["length"] == b[i]["length"] and torch.equal(a[i]["motion"], b[i]["motion"])
    crops = [(a[i]["length"], float(a[i]["motion"][0, 3])) for i in range(len(a))]
    a.set_epoch(1)
    assert crops != [(a[i]["length"], float(a[i]["motion"][0, 3])) for i in range(len(a))]


def test_collate_pads_and_masks(built_dir: Path) -> None:
    ds = MotionDataset(built_dir, "train")
    batch = collate([ds[i] for i in range(6)])
    lengths = batch["lengths"]
    assert batch["motion"].shape == (6, int(lengths.max()), 263)
    assert torch.equal(batch["mask"].sum(1), lengths)
    for i in range(6):
        assert torch.all(batch["motion"][i, lengths[i]:] == 0)


def test_reads_a_humanml3d_folder_with_timed_captions(built_dir: Path, tmp_path: Path) -> None:
    """A real HumanML3D folder: captions as caption#tokens#start#end, sub-spans become their own items."""
    root = tmp_path / "HumanML3D"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    long_id = next(p.stem for p in sorted((built_dir / "new_joint_vecs").glob("*.npy"))
                   if np.load(p).shape[0] >= 150)
    shutil.copy(built_dir / "new_joint_vecs" / f"{long_id}.npy", root / "new_joint_vecs" / "000001.npy")
    for name in ("Mean.npy", "Std.npy"):
        shutil.copy(built_dir / name, root / name)
    (root / "texts" / "000001.txt").write_text(
        "a person walks.#a/DET person/NOUN walk/VERB#0.0#0.0\n"
        "a person starts.#a/DET person/NOUN start/VERB#0.0#2.5\n"
        "too short.#too/ADV short/ADJ#1.0#2.0\n"
    )
    (root / "train.txt").write_text("000001\n000002\n")  # 000002 has no files: skipped, as HumanML3D does
    assert read_captions(root / "texts" / "000001.txt")[1] == ("a person starts.", 0.0, 2.5)
    ds = MotionDataset(root, "train", random_crop=False, normalize=False)
    by_id = {item.id: item for item in ds.items}
    assert set(by_id) == {"000001", "000001#1"}
    assert by_id["000001#1"].features.shape[0] == 50
    assert by_id["000001"].captions == ["a person walks."]


def test_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="no such dataset folder"):
        MotionDataset(tmp_path / "nope")
    with pytest.raises(PhysmotionError, match="no split file"):
        MotionDataset(tmp_path)


def test_crop_shortens_windows_without_dropping_motions(built_dir: Path) -> None:
    """Training on 120-frame windows keeps the motions of 124 to 196 frames and crops them."""
    whole = MotionDataset(built_dir, "train")
    cropped = MotionDataset(built_dir, "train", crop=120)
    assert len(cropped) == len(whole)
    assert max(len(item.features) for item in cropped.items) > 124  # long motions are still there
    assert max(cropped[i]["length"] for i in range(len(cropped))) <= 120
    with pytest.raises(PhysmotionError, match="crop"):
        MotionDataset(built_dir, "train", crop=0)


# --- muscle activations beside the motion (BioMoDiffuse's L_emg), on the 329-d build ---

import os

from physmotion.data.build import load_activations
from physmotion.data.dataset import load_items


def _window_start(feats: np.ndarray, motion: np.ndarray) -> int:
    """Where the window ``motion`` sits in ``feats`` (found by content, not by the crop's rng)."""
    starts = [s for s in range(len(feats) - len(motion) + 1) if np.array_equal(feats[s : s + len(motion)], motion)]
    assert starts, "the window is not a slice of the motion"
    return starts[0]


@pytest.mark.parametrize("random_crop", [False, True])
def test_items_carry_the_activations_of_their_window(built329_dir: Path, random_crop: bool) -> None:
    ds = MotionDataset(built329_dir, "train", activations=True, normalize=False, crop=40, random_crop=random_crop,
                       seed=5)  # fmt: skip
    starts = set()
    for i in range(0, len(ds), 9):
        item = ds[i]
        mid = ds.items[i].id
        feats = np.load(built329_dir / "new_joint_vecs" / f"{mid}.npy")
        acts = load_activations(built329_dir, mid)
        assert item["motion"].shape == (item["length"], 329)
        start = _window_start(feats, item["motion"].numpy())
        starts.add(start)
        assert item["activations"].dtype == torch.float32
        np.testing.assert_array_equal(item["activations"].numpy(), acts[start : start + item["length"]])
    assert (starts == {0}) is (not random_crop)  # random crops do move the window


def test_collate_pads_activations(built329_dir: Path) -> None:
    ds = MotionDataset(built329_dir, "train", activations=True, crop=120)
    items = [ds[i] for i in range(8)]
    assert len({it["length"] for it in items}) > 1
    batch = collate(items)
    width = int(batch["lengths"].max())
    assert batch["activations"].shape == (8, width, 8) and batch["motion"].shape == (8, width, 329)
    for i, it in enumerate(items):
        n = it["length"]
        assert torch.equal(batch["activations"][i, :n], it["activations"])
        assert torch.all(batch["activations"][i, n:] == 0)
    plain = MotionDataset(built329_dir, "train", crop=120)  # without activations=True: none
    assert "activations" not in plain[0] and "activations" not in collate([plain[i] for i in range(3)])


def test_timed_captions_take_the_activations_of_their_span(built329_dir: Path, tmp_path: Path) -> None:
    root = tmp_path / "HumanML3D"
    for sub in ("new_joint_vecs", "texts", "activations"):
        (root / sub).mkdir(parents=True)
    paths = sorted((built329_dir / "new_joint_vecs").glob("*.npy"))
    src = next(p.stem for p in paths if np.load(p).shape[0] >= 150)
    feats = np.load(built329_dir / "new_joint_vecs" / f"{src}.npy")
    acts = load_activations(built329_dir, src)
    np.save(root / "new_joint_vecs" / "000001.npy", feats)
    np.save(root / "activations" / "000001.npy", acts)
    for name in ("Mean.npy", "Std.npy"):
        shutil.copy(built329_dir / name, root / name)
    (root / "texts" / "000001.txt").write_text("a person walks.#a/DET#0.0#0.0\na person starts.#a/DET#1.0#5.0\n")
    (root / "train.txt").write_text("000001\n")
    by_id = {item.id: item for item in load_items(root, "train", activations=True)}
    np.testing.assert_array_equal(by_id["000001"].activations, acts)
    np.testing.assert_array_equal(by_id["000001#1"].activations, acts[20:100])
    np.testing.assert_array_equal(by_id["000001#1"].features, feats[20:100])
    assert all(item.activations is None for item in load_items(root, "train"))
    np.save(root / "activations" / "000001.npy", acts[:-3])  # a stale cache: another length
    with pytest.raises(PhysmotionError, match="frames") as err:
        load_items(root, "train", activations=True)
    assert "\n" not in str(err.value)


def test_missing_activations_are_a_one_line_error(built329_dir: Path, tmp_path: Path) -> None:
    bare = tmp_path / "bare"
    bare.mkdir()
    for entry in built329_dir.iterdir():
        if entry.name != "activations":
            os.symlink(entry, bare / entry.name)
    assert len(MotionDataset(bare, "val")) > 0  # the build is fine without activations=True
    with pytest.raises(PhysmotionError, match="activation") as err:
        MotionDataset(bare, "val", activations=True)
    assert "\n" not in str(err.value)
