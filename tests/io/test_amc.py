"""ASF/AMC reader: CMU's FK convention, units, dof lists, frame numbering."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from physmotion.errors import MotionFormatError
from physmotion.io.amc import read_amc, read_asf


def _reference_bone_ends(asf: Path, amc: Path, frame: int) -> dict[str, np.ndarray]:
    """Bone end points of one frame by the textbook recursion (as CMU's viewer / AMCParser):
    G_b = G_parent C M C^-1, end_b = end_parent + G_b direction_b length_b, "XYZ" about fixed axes."""
    skel = read_asf(asf)
    lines = [ln.strip() for ln in amc.read_text().splitlines()]
    starts = [i for i, ln in enumerate(lines) if ln.isdigit()]
    body = lines[starts[frame] + 1 : starts[frame + 1]]
    values = {ln.split()[0]: [float(v) for v in ln.split()[1:]] for ln in body}

    def euler(angles: list[float] | np.ndarray) -> np.ndarray:
        return Rotation.from_euler("xyz", angles, degrees=True).as_matrix()

    glob = {"root": euler(values["root"][3:])}
    end = {"root": np.array(values["root"][:3])}
    for bone in list(skel.bones.values())[1:]:
        angles = np.zeros(3)
        for k, dof in enumerate(bone.dofs):
            angles["xyz".index(dof[1])] = values[bone.name][k]
        c = euler(bone.axis)
        glob[bone.name] = glob[bone.parent] @ c @ euler(angles) @ c.T
        end[bone.name] = end[bone.parent] + glob[bone.name] @ (bone.direction * bone.length)
    return end


@pytest.mark.parametrize(
    "amc, asf",
    [
        ("subjects/02/02_05.amc", "subjects/02/02.asf"),
        ("gsimchoni_mocap/backflip.amc", "gsimchoni_mocap/backflip.asf"),
    ],
)
def test_fk_matches_reference_recursion(mocap_dir: Path, amc: str, asf: str) -> None:
    root = mocap_dir / "cmu_amc"
    rig = read_amc(root / amc, root / asf)
    pos = rig.forward_kinematics()
    skel = read_asf(root / asf)
    for frame in (0, 7, rig.num_frames // 2):
        ref = _reference_bone_ends(root / asf, root / amc, frame)
        for bone in list(skel.bones.values())[1:]:  # a bone's node sits where its parent bone ends
            assert np.allclose(pos[frame, rig.index(bone.name)], ref[bone.parent], atol=1e-9), bone.name
        for bone in skel.bones.values():
            if f"{bone.name}_end" in rig.names:
                assert np.allclose(pos[frame, rig.index(f"{bone.name}_end")], ref[bone.name], atol=1e-9)


def test_asf_details(mocap_dir: Path) -> None:
    skel = read_asf(mocap_dir / "cmu_amc/subjects/02/02.asf")  # CRLF file
    assert skel.metres_per_unit == pytest.approx(0.0254 / 0.45) and skel.degrees
    bones = skel.bones
    assert bones["root"].dofs == ("tx", "ty", "tz", "rx", "ry", "rz")
    assert bones["ltibia"].dofs == ("rx",) and bones["lfoot"].dofs == ("rx", "rz")  # fewer than 3 dofs
    assert bones["lhipjoint"].dofs == () and bones["lfemur"].parent == "lhipjoint"
    assert bones["lhumerus"].order == "XYZ" and np.allclose(bones["lhumerus"].axis, [180, -30, -90])


def test_amc_frames_numbered_from_one(mocap_dir: Path) -> None:
    amc = mocap_dir / "cmu_amc/subjects/02/02_01.amc"
    lines = [ln.strip() for ln in amc.read_text().splitlines()]
    numbers = [int(ln) for ln in lines if ln.isdigit()]
    assert numbers[0] == 1
    rig = read_amc(amc, mocap_dir / "cmu_amc/subjects/02/02.asf")
    assert rig.num_frames == len(numbers) and rig.fps is None
    assert rig.units == pytest.approx(0.0254 / 0.45)
    first_root = [float(v) for v in lines[lines.index("1") + 1].split()[1:4]]
    assert np.allclose(rig.translations[0, 0], first_root)


def test_irregular_amc_uses_the_slow_path(mocap_dir: Path, tmp_path: Path) -> None:
    """A frame listing its bones in another order (or leaving one out) still reads."""
    asf = mocap_dir / "cmu_amc/subjects/02/02.asf"
    amc = mocap_dir / "cmu_amc/subjects/02/02_01.amc"
    lines = amc.read_text().splitlines()
    second = lines.index("2")
    lines[second + 1], lines[second + 2] = lines[second + 2], lines[second + 1]  # swap root and lowerback
    shuffled = tmp_path / "shuffled.amc"
    shuffled.write_text("\n".join(lines))
    a, b = read_amc(amc, asf), read_amc(shuffled, asf)
    assert np.allclose(a.forward_kinematics(), b.forward_kinematics())


def test_a_skeleton_of_too_many_bones_is_refused_before_it_is_parsed(mocap_dir: Path, tmp_path: Path) -> None:
    """A body has tens of bones (CMU's 30); 1,000 more, unconnected, is not a body's skeleton. Parsing the
    fuzz's 100k-bone file took 5.8 s of CPU on CI; the count is refused first, in one line."""
    text = (mocap_dir / "cmu_amc/subjects/02/02.asf").read_text()
    bone = "  begin\n     name extra{}\n     direction 0 1 0\n     length 1\n  end\n"
    extra = "".join(bone.format(i) for i in range(1000))
    path = tmp_path / "many.asf"
    path.write_text(text.replace(":bonedata\n", ":bonedata\n" + extra, 1))
    with pytest.raises(MotionFormatError, match=r"many\.asf: ASF file defines 1030 bones; at most 1000") as e:
        read_asf(path)
    assert "\n" not in str(e.value)
    assert len(read_asf(mocap_dir / "cmu_amc/subjects/02/02.asf").bones) == 31  # root and CMU's 30
