"""Real files carry Latin-1 / cp1252 bytes in comments and names: read as UTF-8, else as Latin-1 with
one warning line per import (an AMC and its ASF together)."""

from __future__ import annotations

import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from physmotion.io import ClipInfo, import_clip
from physmotion.io.bvh import Latin1Warning
from physmotion.skeleton import JOINT_NAMES

REPO = Path(__file__).resolve().parents[2]


def _latin1(record: list[warnings.WarningMessage]) -> list[str]:
    return [str(w.message) for w in record if issubclass(w.category, Latin1Warning)]


@pytest.mark.slow
def test_every_hdm05_clip_imports_with_one_warning(hdm05_manifest: list[ClipInfo], hdm05_results) -> None:
    """HDM05's AMC headers hold a Latin-1 byte (``X:\\für Bonn``): every clip of its manifest imports."""
    failed = {k: v for k, v in hdm05_results.items() if isinstance(v, str)}
    assert not failed and len(hdm05_results) == len(hdm05_manifest)
    for info in hdm05_manifest:
        motion, _, caught = hdm05_results[info.clip]
        assert motion.licence_tag == "SA" and motion.texts == info.captions
        assert len(caught) == 1 and str(info.path) in str(caught[0].message), info.clip


def test_utf8_files_give_no_warning(clip) -> None:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        import_clip(clip("cmu_02_01"))  # ASF/AMC
        import_clip(clip("bandai1_dataset-1_bow_active_001"))  # BVH
    assert not _latin1(caught)


def test_latin1_asf_and_amc_give_one_line(hdm05_manifest: list[ClipInfo], tmp_path: Path) -> None:
    """An ASF and its AMC both in Latin-1 (comments, the ASF's name): one warning naming both files."""
    info = hdm05_manifest[0]
    asf = tmp_path / "skel.asf"
    asf.write_bytes(b"# Skelett f\xfcr Sch\xfcler\n" + Path(info.skeleton).read_bytes())
    amc = tmp_path / "take.amc"
    amc.write_bytes(info.path.read_bytes())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = import_clip(amc, asf=asf, fps=120)
    lines = _latin1(caught)
    assert len(lines) == 1 and str(asf) in lines[0] and str(amc) in lines[0] and "\n" not in lines[0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        assert np.allclose(motion.joints, import_clip(info).joints, atol=1e-6)


def _latin1_bvh(clip, tmp_path: Path) -> tuple[Path, Path]:
    """The Bandai walk with its hips renamed ``Hüfte`` and written in Latin-1 (cp1252 quote marks in a
    joint name too), and a UTF-8 mapping file naming those joints."""
    text = clip("bandai2_dataset-2_walk_normal_001").path.read_text()
    text = text.replace("JOINT Hips", "JOINT Hüfte").replace("ROOT Hips", "ROOT Hüfte")
    text = text.replace("JOINT Head", "JOINT Head\x93main\x94")
    path = tmp_path / "hüfte.bvh"
    path.write_bytes(text.encode("latin-1"))
    example = json.loads((REPO / "docs" / "examples" / "mapping_bandai.json").read_text())
    joints = json.loads(json.dumps(example["joints"]).replace('"Hips"', '"Hüfte"'))
    joints["head"] = "Head\x93main\x94"
    mapping = tmp_path / "map.json"
    mapping.write_text(json.dumps({**example, "joints": joints}), encoding="utf-8")
    return path, mapping


def test_latin1_bvh_with_latin1_joint_names(clip, tmp_path: Path) -> None:
    path, mapping = _latin1_bvh(clip, tmp_path)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        motion = import_clip(path, mapping=mapping)
    assert len(_latin1(caught)) == 1
    assert motion.joints.shape[1:] == (len(JOINT_NAMES), 3)


@pytest.mark.slow  # starts processes
@pytest.mark.parametrize("command", ["import", "metrics"])
def test_cli_prints_one_warning_line(clip, tmp_path: Path, command: str) -> None:
    path, mapping = _latin1_bvh(clip, tmp_path)
    args = [str(path), "--mapping", str(mapping)]
    args += ["-o", str(tmp_path / "out.npz")] if command == "import" else ["--json"]
    done = subprocess.run([sys.executable, "-m", "physmotion.cli", command, *args], capture_output=True,
                          text=True, cwd=tmp_path, check=False)  # fmt: skip
    assert done.returncode == 0, done.stderr
    lines = [ln for ln in done.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("warning: ") and "Latin-1" in lines[0], done.stderr


def test_a_bare_hdm05_file_finds_its_actors_asf(hdm05_manifest: list[ClipInfo]) -> None:
    """``import HDM_bd_..._120.amc`` alone: its skeleton is ``asf/HDM_bd.asf`` of the collection."""
    info = hdm05_manifest[-1]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        bare, listed = import_clip(info.path, fps=120), import_clip(info)
    assert np.array_equal(bare.joints, listed.joints) and Path(info.skeleton).name.startswith("HDM_")
