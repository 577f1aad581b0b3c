"""Rig mapping JSON files (physmotion.io.mapping), ``import --mapping`` and ``import --rig list``."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import PhysmotionError
from physmotion.io import RIGS, import_clip
from physmotion.io.mapping import MappingError, load_mapping
from physmotion.motion import Motion
from physmotion.skeleton import JOINT_NAMES
from tests.cli_runner import invoke

REPO = Path(__file__).resolve().parents[2]
EXAMPLE = REPO / "docs" / "examples" / "mapping_bandai.json"
WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"


def _cli(*args: object) -> subprocess.CompletedProcess:
    """``physmotion ARGS...`` in this process (see tests/cli_runner.py)."""
    return invoke(*args)


def _write(tmp_path: Path, data: object, name: str = "map.json") -> Path:
    path = tmp_path / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


def _example() -> dict:
    return json.loads(EXAMPLE.read_text())


def test_example_file_is_the_bandai_table() -> None:
    loaded = load_mapping(EXAMPLE)
    assert set(loaded.joints) == set(JOINT_NAMES)
    assert loaded.joints == dict(RIGS["bandai"].joints)
    assert (loaded.units, loaded.up_axis, loaded.fps) == (0.01, "Y", 30.0)


def test_example_mapping_imports_like_the_rig(mocap_dir: Path, tmp_path: Path) -> None:
    by_rig, by_map = tmp_path / "rig.npz", tmp_path / "map.npz"
    # --fps 30 as the example file says: the header's Frame Time 0.0333333 reads as 30.00003 fps
    res = _cli("import", mocap_dir / WALK, "-o", by_rig, "--rig", "bandai", "--fps", "30")
    assert res.returncode == 0, res.stderr
    res = _cli("import", mocap_dir / WALK, "-o", by_map, "--mapping", EXAMPLE)
    assert res.returncode == 0, res.stderr
    a, b = Motion.load(by_rig), Motion.load(by_map)
    assert a.joints.shape == b.joints.shape and a.num_frames > 100
    np.testing.assert_allclose(b.joints, a.joints, atol=1e-5)


def test_flags_override_the_file(mocap_dir: Path, tmp_path: Path) -> None:
    data = _example() | {"fps": 60, "units": "m"}  # both wrong for this clip
    path = _write(tmp_path, data)
    wrong = import_clip(mocap_dir / WALK, mapping=path)
    right = import_clip(mocap_dir / WALK, mapping=path, fps=30, units="cm")
    reference = import_clip(mocap_dir / WALK, rig="bandai", fps=30)
    assert abs(2 * wrong.num_frames - reference.num_frames) <= 2  # the file's 60 fps was used
    assert wrong.joints[0, :, 1].max() > 50  # and its metres: a 150 m tall walker
    np.testing.assert_allclose(right.joints, reference.joints, atol=1e-5)


@pytest.mark.parametrize(
    ("content", "match"),
    [
        (None, "no such file"),
        ("{not json", "not valid JSON (Expecting property name"),
        ("[1, 2]", "expected a JSON object"),
        ('{"joints": {}, "fps": NaN}', "NaN is not a JSON number"),
        ({"units": "cm"}, 'no "joints" object'),
        ({"joints": ["Hips"]}, '"joints" must be an object'),
        ({"joints": {"tail": "Hips"}}, "unknown joint name(s) 'tail'; ours are pelvis, left_hip"),
        ({"joints": {"pelvis": "Hips"}}, "\"joints\" lacks 'left_hip'"),
        (
            "joint_number",
            "neck must map to a joint name or a list of [joint name, weight] pairs, got a number",
        ),
        ("blend_weights", "the weights of spine2 must be >= 0 and sum to 1"),
        ("units", "unknown units 'furlongs'"),
        ("units_bool", '"units" must be a name'),
        ("up_axis", '"up_axis" must be one of X, Y, Z, got "W"'),
        ("fps", '"fps" must be a positive number, got -3'),
        ("extra_key", "unknown key(s) 'scale'"),
    ],
)
def test_bad_mapping_files(content: object, match: str, tmp_path: Path) -> None:
    joints = _example()["joints"]
    cases = {
        "joint_number": {"joints": {**joints, "neck": 3}},
        "blend_weights": {"joints": {**joints, "spine2": [["Spine", 0.9], ["Chest", 0.9]]}},
        "units": {"joints": joints, "units": "furlongs"},
        "units_bool": {"joints": joints, "units": True},
        "up_axis": {"joints": joints, "up_axis": "W"},
        "fps": {"joints": joints, "fps": -3},
        "extra_key": {"joints": joints, "scale": 2},
    }
    path = (
        tmp_path / "absent.json"
        if content is None
        else _write(tmp_path, cases[content] if isinstance(content, str) and content in cases else content)
    )
    with pytest.raises(MappingError) as info:
        load_mapping(path)
    message = str(info.value)
    assert match in message and str(path) in message and "\n" not in message, message


def test_file_joint_not_in_the_file(mocap_dir: Path, tmp_path: Path) -> None:
    path = _write(tmp_path, _example() | {"joints": {**_example()["joints"], "left_knee": "LeftLeg"}})
    with pytest.raises(PhysmotionError) as info:
        import_clip(mocap_dir / WALK, mapping=path)
    message = str(info.value)
    assert "mapping: left_knee -> 'LeftLeg' not found in dataset-2_walk_normal_001.bvh (joints: " in message
    assert "joint_Root, Hips, Spine" in message  # the file's own names, unpruned, so the user can fix it


def test_zero_length_bone_is_named(mocap_dir: Path, tmp_path: Path) -> None:
    path = _write(tmp_path, _example() | {"joints": {**_example()["joints"], "left_knee": "UpperLeg_L"}})
    with pytest.raises(PhysmotionError, match="zero-length bone left_hip -> left_knee"):
        import_clip(mocap_dir / WALK, mapping=path)


def test_rig_and_mapping_together_is_an_error(mocap_dir: Path) -> None:
    with pytest.raises(PhysmotionError, match="not both"):
        import_clip(mocap_dir / WALK, rig="bandai", mapping=EXAMPLE)


def test_rig_list_and_help_come_from_the_registry() -> None:
    res = _cli("import", "--rig", "list")
    assert res.returncode == 0, res.stderr
    lines = res.stdout.strip().splitlines()
    assert [ln.split(":")[0] for ln in lines] == list(RIGS)
    assert lines[0].startswith("bandai: cm, Y up; Bandai")
    assert "cmu_asf: units from the file" in res.stdout
    help_text = " ".join(_cli("import", "--help").stdout.split())
    for name in RIGS:
        assert name in help_text
    assert "--mapping" in help_text


def test_unknown_rig_points_to_the_cli_words(mocap_dir: Path, tmp_path: Path) -> None:
    res = _cli("import", mocap_dir / WALK, "-o", tmp_path / "x.npz", "--rig", "nope")
    lines = res.stderr.splitlines()
    assert res.returncode == 1 and len(lines) == 1 and lines[0].startswith("error: "), res.stderr
    assert "--rig list" in lines[0] and "--mapping map.json" in lines[0]
    assert "rig=" not in lines[0] and "mapping=" not in lines[0]
    assert not (tmp_path / "x.npz").exists()


def test_cli_bad_mapping_is_one_line(mocap_dir: Path, tmp_path: Path) -> None:
    path = _write(tmp_path, "{oops")
    res = _cli("import", mocap_dir / WALK, "-o", tmp_path / "x.npz", "--mapping", path)
    lines = res.stderr.splitlines()
    assert res.returncode == 1 and len(lines) == 1 and "not valid JSON" in lines[0], res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "x.npz").exists()


def test_amc_joint_not_in_the_skeleton_lists_the_asf_bones(clip) -> None:
    info = clip("cmu_02_01")
    mapping = dict(RIGS["cmu_asf"].joints) | {"left_hip": "leftfemur"}
    with pytest.raises(PhysmotionError) as info_error:
        import_clip(info.path, mapping=mapping, asf=info.skeleton, fps=120)
    message = str(info_error.value)
    assert "mapping: left_hip -> 'leftfemur' not found in 02_01.amc (joints: root, " in message
    assert "lfemur" in message and "31 in all" in message, message
