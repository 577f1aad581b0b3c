"""Export: BVH on the 22-joint rig (metres, Y up) round-trips through the importer; .npz; atomic writes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.io import import_clip, save_bvh, save_npz
from physmotion.io.bvh import read_bvh
from physmotion.motion import Motion
from physmotion.skeleton import JOINT_NAMES

ONE_PER_SOURCE = (
    "bandai1_dataset-1_bow_active_001",
    "bandai2_dataset-2_raise-up-both-hands_active_001",
    "cmubvh_131_03",
    "cmubvhm_131_02",
    "cmu_02_06",
    "cmu_gsimchoni_backflip",
    "cmuiclone_05_06",
)


@pytest.mark.parametrize("clip_id", ONE_PER_SOURCE)
def test_bvh_round_trip_within_1mm(clip, clip_id: str, tmp_path: Path) -> None:
    motion = import_clip(clip(clip_id))
    path = tmp_path / "out.bvh"
    save_bvh(motion, path)
    back = import_clip(path, rig="smpl22")
    assert back.num_frames == motion.num_frames and back.fps == motion.fps
    error = np.linalg.norm(back.joints - motion.joints, axis=-1).max()
    assert error < 1e-3, f"{clip_id}: {error * 1000:.3f} mm"
    assert np.allclose(import_clip(path).joints, back.joints)  # the smpl22 rig is recognised by its names


def test_bvh_is_metres_y_up_smpl_hierarchy(clip, tmp_path: Path) -> None:
    motion = import_clip(clip("cmu_02_01"))
    path = tmp_path / "walk.bvh"
    save_bvh(motion, path)
    text = path.read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis\n") and "Frame Time: 0.05000000" in text
    rig = read_bvh(path)
    assert [n for n in rig.names if not n.endswith("_end")] == sorted(JOINT_NAMES, key=rig.names.index)
    pos = rig.forward_kinematics()
    height = pos[0, rig.index("head"), 1] - pos[0, rig.index("left_foot"), 1]
    assert 1.2 < height < 1.8  # metres, and Y is up
    assert rig.translations[0, 0, 1] == pytest.approx(motion.joints[0, 0, 1], abs=1e-5)


def test_save_npz(clip, tmp_path: Path) -> None:
    motion = import_clip(clip("cmu_02_01"))
    save_npz(motion, tmp_path / "m.npz")
    back = Motion.load(tmp_path / "m.npz")
    assert np.array_equal(back.joints, motion.joints) and back.texts == motion.texts


def test_failed_write_leaves_nothing(clip, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    motion = import_clip(clip("cmu_02_01"))

    def broken(*args: object, **kwargs: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(np, "savetxt", broken)  # fails after the header is written
    with pytest.raises(OSError):
        save_bvh(motion, tmp_path / "x.bvh")
    assert list(tmp_path.iterdir()) == []


def test_placed_motion_round_trips_where_it_is(clip, tmp_path: Path) -> None:
    """A real motion not at the import's placement (as P's output: turned 5 degrees, off the origin,
    12 mm up) comes back from our BVH where it was, within 1 mm mean and max (before: the importer turned
    it to face +Z, moved it to the origin and re-grounded it); the root OFFSET is 0, so importers that
    add it to the root's position channels read the same motion."""
    motion = import_clip(clip("cmu_02_06"))
    turn = np.array([[np.cos(0.09), 0.0, np.sin(0.09)], [0.0, 1.0, 0.0], [-np.sin(0.09), 0.0, np.cos(0.09)]])
    moved = Motion(joints=motion.joints.astype(np.float64) @ turn.T + [0.4, 0.012, -0.7], fps=motion.fps)
    path = tmp_path / "m.bvh"
    save_bvh(moved, path)
    assert path.read_text().splitlines()[3].split() == ["OFFSET", "0.000000", "0.000000", "0.000000"]
    error = np.linalg.norm(import_clip(path).joints - moved.joints, axis=-1)
    assert error.mean() < 1e-3 and error.max() < 1e-3, f"{error.mean() * 1000:.2f} / {error.max() * 1000:.2f} mm"
