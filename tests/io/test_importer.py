"""The manifest and import_clip's options: bare paths, user mappings, overrides."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from physmotion.conventions import FPS
from physmotion.errors import PhysmotionError
from physmotion.io import RIGS, import_clip, import_clip_with_report
from physmotion.motion import Motion


def test_manifest_rows(manifest, mocap_dir: Path) -> None:
    with open(mocap_dir / "manifest.csv", newline="", encoding="utf-8") as f:
        assert len(manifest) == len(list(csv.DictReader(f)))  # every row, in file order
    first = manifest[0]
    assert (
        first.clip == "bandai1_dataset-1_bow_active_001" and first.fps == 30.0 and first.licence_tag == "NC"
    )
    assert first.captions == ["a person bows in an active manner", "bow active"]
    assert all(c.path.is_file() for c in manifest)
    amc = [c for c in manifest if c.format == "amc"]
    assert amc and all(Path(c.skeleton).suffix == ".asf" for c in amc)
    assert {c.take for c in manifest if c.clip == "cmuiclone_02_01"} == {"cmu_02_01"}


def test_import_clip_fields(clip) -> None:
    info = clip("cmu_02_01")
    motion = import_clip(info)
    assert isinstance(motion, Motion) and motion.fps == FPS
    assert motion.joints.shape[1:] == (22, 3) and motion.joints.dtype == np.float32
    assert motion.rotations.shape == motion.joints.shape[:2] + (3, 3) and motion.offsets.shape == (22, 3)
    assert motion.texts == info.captions and motion.source == "cmu_02_01" and motion.licence_tag == ""
    assert motion.num_frames == int((343 - 1) / 120 * FPS) + 1  # 343 frames at 120 fps
    assert import_clip(clip("bandai1_dataset-1_bow_active_001")).licence_tag == "NC"


def test_bare_paths_with_explicit_options(clip) -> None:
    info = clip("cmuiclone_02_01")
    reference = import_clip(info)
    # the iClone header says 59.9988 fps, close to the true 60
    bare = import_clip(info.path, rig="cmu_iclone_cc_base", fps=60, units="cm")
    assert np.abs(bare.joints - reference.joints).max() < 1e-5 and bare.texts == []
    detected = import_clip(info.path)  # rig found from its joint names, units from its table
    assert np.abs(detected.joints - reference.joints).max() < 1e-3
    amc = clip("cmu_02_01")
    assert np.allclose(import_clip(amc.path, fps=120).joints, import_clip(amc).joints)  # 02.asf found


def test_manifest_fps_beats_the_header(clip) -> None:
    info = clip("cmuiclone_02_01")
    motion, report = import_clip_with_report(info)
    assert report.source_fps == 60.0 and report.rig == "cmu_iclone_cc_base"
    slower = import_clip(info, fps=30)  # claiming half the rate doubles the duration
    assert abs(slower.num_frames - 2 * motion.num_frames) <= 2


def test_user_mapping_with_units(clip) -> None:
    info = clip("cmubvhm_131_02")  # a level floor: like the floor, levelling one depends on the body's size
    mapping = dict(RIGS["cmu_bvh_cgspeed_max_scaled_m"].joints)
    motion = import_clip(info.path, mapping=mapping, units="m", fps=120)
    assert np.abs(motion.joints - import_clip(info).joints).max() < 1e-5
    cm = import_clip(info.path, mapping=mapping, units=0.01, fps=120)
    # the same motion at 1/100 the size; its floor need not scale (the humanoid's surface does not)
    diff = cm.joints - motion.joints / 100
    assert np.allclose(diff[..., [0, 2]], 0, atol=1e-6) and np.ptp(diff[..., 1]) < 1e-6


def test_same_take_in_cmu_units_and_metres_agrees(clip) -> None:
    a, b = import_clip(clip("cmubvh_131_01")), import_clip(clip("cmubvhm_131_01"))
    n = min(a.num_frames, b.num_frames)  # the metre copy has one frame more
    assert np.abs(a.joints[:n] - b.joints[:n]).mean() < 0.01


def test_rig_errors(clip) -> None:
    info = clip("cmubvh_131_01")
    with pytest.raises(PhysmotionError, match="unknown rig 'nope'"):
        import_clip(info.path, rig="nope", fps=120)
    with pytest.raises(PhysmotionError, match="differ in units"):
        import_clip(info.path, fps=120)  # cgspeed's joint names fit both of its tables
    with pytest.raises(PhysmotionError, match="does not fit"):
        import_clip(info.path, rig="bandai", fps=120)
    with pytest.raises(PhysmotionError, match="no frame rate"):
        import_clip(clip("cmu_02_01").path)


def test_motion_is_consistent_with_its_rotations(clip) -> None:
    from physmotion.skeleton import forward_kinematics

    for clip_id in ("cmu_02_06", "cmuiclone_06_06", "bandai1_dataset-1_bow_active_001"):
        m = import_clip(clip(clip_id))
        fk = forward_kinematics(m.rotations.astype(np.float64), m.joints[:, 0].astype(np.float64), m.offsets)
        assert np.abs(fk - m.joints).max() < 1e-4, clip_id


def test_iclone_frames_are_y_up_although_the_rest_pose_is_z_up(manifest) -> None:
    """The manifest says Z for the iClone files (their rest pose: CC_Base_Hip OFFSET 0 0 105), but
    RL_BoneRoot's animated rotation stands every frame up along +Y, so the rig table says Y."""
    from physmotion.io.bvh import read_bvh

    iclone = [c for c in manifest if c.source == "cmu_iclone"]
    assert {c.up_axis for c in iclone} == {"Z"} and RIGS["cmu_iclone_cc_base"].up_axis == "Y"
    for info in iclone[::6]:
        rig = read_bvh(info.path, keep={"CC_Base_Head", "CC_Base_L_Foot"})
        pos = rig.forward_kinematics()
        up = (pos[:, rig.index("CC_Base_Head")] - pos[:, rig.index("CC_Base_L_Foot")]).mean(axis=0)
        assert up[1] > 0.9 * np.linalg.norm(up), info.clip
