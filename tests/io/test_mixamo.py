"""The Mixamo rig tables (``mixamorig:Hips`` and the names without the prefix), and End Sites named in a
mapping: on a Mixamo-named BVH written here from a real clip (cm, Y up, Mixamo's joint names)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from physmotion.io import ClipInfo, import_clip, import_clip_with_report
from physmotion.io.bvh import bvh_joint_names, write_bvh
from physmotion.io.rigs import RigMotion
from physmotion.motion import Motion
from physmotion.skeleton import JOINT_NAMES, PARENTS, inverse_kinematics, offsets_from_joints

EXAMPLE = Path(__file__).resolve().parents[2] / "docs" / "examples" / "mapping_mixamo_no_toes.json"

# Mixamo's own joint names (its rig has the SMPL tree's 22 joints under these names, plus fingers and ends).
MIXAMO_NAME = {
    "pelvis": "Hips", "spine1": "Spine", "spine2": "Spine1", "spine3": "Spine2", "neck": "Neck", "head": "Head",
    **{f"{s}_{j}": f"{S}{m}" for s, S in (("left", "Left"), ("right", "Right")) for j, m in (
        ("hip", "UpLeg"), ("knee", "Leg"), ("ankle", "Foot"), ("foot", "ToeBase"), ("collar", "Shoulder"),
        ("shoulder", "Arm"), ("elbow", "ForeArm"), ("wrist", "Hand"))},
}  # fmt: skip


def _write_mixamo_bvh(motion: Motion, path: Path, prefix: str = "mixamorig:", toes_as_end_sites: bool = False) -> None:
    """``motion`` as a Mixamo-named BVH in centimetres; with ``toes_as_end_sites`` the toe joints are End
    Sites of the feet (as rigs without toe bones write them)."""
    joints = motion.joints.astype(np.float64)
    offsets = offsets_from_joints(joints)
    rotations, root = inverse_kinematics(joints, offsets)
    translations = np.broadcast_to(offsets * 100.0, joints.shape).copy()
    translations[:, 0] = root * 100.0
    toes = {"left_foot", "right_foot"} if toes_as_end_sites else set()
    rig = RigMotion(
        names=tuple(prefix + MIXAMO_NAME[j] for j in JOINT_NAMES), parents=np.array(PARENTS),
        rotations=rotations, translations=translations, is_end=tuple(j in toes for j in JOINT_NAMES),
    )  # fmt: skip
    write_bvh(path, rig, motion.fps)


@pytest.fixture(scope="module")
def hop(hdm05_manifest: list[ClipInfo]) -> Motion:
    """A real HDM05 clip through the importer: the reference the Mixamo files must come back as."""
    info = next(c for c in hdm05_manifest if "hopBothLegs" in c.clip)
    with pytest.warns(UserWarning, match="Latin-1"):
        return import_clip(info)


@pytest.mark.parametrize(("prefix", "rig"), [("mixamorig:", "mixamo"), ("", "mixamo_plain")])
def test_mixamo_bvh_is_recognised_and_imports_as_the_motion(hop: Motion, tmp_path: Path, prefix: str, rig: str) -> None:
    path = tmp_path / "mixamo.bvh"
    _write_mixamo_bvh(hop, path, prefix)
    assert f"{prefix}Hips" in bvh_joint_names(path)
    motion, report = import_clip_with_report(path)  # the rig guessed from its joint names; cm from the table
    assert report.rig == rig
    error = np.linalg.norm(motion.joints - hop.joints, axis=-1).max()
    assert error < 1e-3, f"{error * 1000:.3f} mm"


def test_an_end_site_named_in_a_mapping(hop: Motion, tmp_path: Path) -> None:
    """A rig without toe bones: its feet end in End Sites, named ``<parent>_end``; a mapping names them."""
    path = tmp_path / "no_toes.bvh"
    _write_mixamo_bvh(hop, path, toes_as_end_sites=True)
    names = bvh_joint_names(path)
    assert "mixamorig:LeftToeBase" not in names and "mixamorig:LeftFoot_end" in names
    joints = {j: "mixamorig:" + MIXAMO_NAME[j] for j in JOINT_NAMES}
    joints |= {"left_foot": "mixamorig:LeftFoot_end", "right_foot": "mixamorig:RightFoot_end"}
    assert json.loads(EXAMPLE.read_text())["joints"] == joints  # the docs' example is this mapping
    motion = import_clip(path, mapping=EXAMPLE)
    error = np.linalg.norm(motion.joints - hop.joints, axis=-1).max()
    assert error < 1e-3, f"{error * 1000:.3f} mm"
    with pytest.raises(Exception, match="mixamorig:LeftToeBase"):  # the table's toe joint is missing
        import_clip(path, rig="mixamo")
