"""P over motion files: one output per input, atomic, resumable, in local processes or on Ray."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.errors import PhysmotionError
from physmotion.io.importer import import_clip, load_manifest
from physmotion.motion import Motion
from physmotion.physics.files import outputs_for, project_file, project_files, teacher_path
from physmotion.physics.projection import ProjectionConfig
from physmotion.physics.search import effort

CLIPS = ("bandai2_dataset-2_walk_normal_001", "bandai2_dataset-2_run_normal_001", "bandai1_dataset-1_kick_normal_001")


@pytest.fixture(scope="module")
def motion_files(mocap_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> list[Path]:
    """Three captured clips, 1 s each, as .npz files (with their licence tags)."""
    folder = tmp_path_factory.mktemp("motions")
    infos = {c.clip: c for c in load_manifest(mocap_dir)}
    paths = []
    for name in CLIPS:
        motion = import_clip(infos[name])
        motion.joints, motion.rotations = motion.joints[:21], None
        motion.save(folder / f"{name}.npz")
        paths.append(folder / f"{name}.npz")
    return paths


def test_files_are_projected_once_and_resumed(motion_files: list[Path], tmp_path: Path) -> None:
    config = ProjectionConfig()
    out = tmp_path / "projected"
    seen = []
    results = project_files(motion_files, out, config, workers=2, on_done=seen.append)
    assert [r.out for r in results] == outputs_for(motion_files, out) and len(seen) == 3
    assert not any(r.skipped for r in results)
    # In worker processes, each motion is what it is alone.
    alone = project_file(motion_files[1], tmp_path / "alone.npz", config)
    assert np.array_equal(Motion.load(results[1].out).joints, Motion.load(alone.out).joints)
    assert results[1].summary == alone.summary
    # A re-run after an interruption does only what is missing.
    results[0].out.unlink()
    again = project_files(motion_files, out, config, workers=2)
    assert [r.skipped for r in again] == [False, True, True]
    assert Motion.load(again[0].out).licence_tag == Motion.load(motion_files[0]).licence_tag
    assert not list(out.glob(".*.tmp"))  # atomic writes leave no temporary files


def test_files_of_one_stem_are_refused(motion_files: list[Path], tmp_path: Path) -> None:
    with pytest.raises(PhysmotionError, match="would both be written"):
        project_files([motion_files[0], motion_files[0]], tmp_path, ProjectionConfig())
    with pytest.raises(PhysmotionError, match="search controller"):
        project_file(motion_files[0], tmp_path / "x.npz", ProjectionConfig(), teacher=True)
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.slow
def test_ray_runs_one_task_per_motion(motion_files: list[Path], tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="Ray is the optional extra physmotion[ray]; make install has it")
    import subprocess
    import sys

    # In its own process, as a user runs it: a Ray driver's start and shutdown stay out of this test
    # process and its worker pool (physics/workers.py), which the other tests share.
    args = [str(p) for p in motion_files[:2]]
    command = [sys.executable, "-m", "physmotion.cli", "project", *args, "-o", str(tmp_path / "ray"),
               "--controller", "search", "--effort", "fast", "--teacher", "--ray", "local"]  # fmt: skip
    res = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "wrote 2 motions" in res.stdout and res.stdout.count("no outside help") == 2
    config = ProjectionConfig().with_controller("search", search=effort("fast"))
    local = project_files(motion_files[:2], tmp_path / "local", config, teacher=True, workers=1)
    for b in local:
        a = tmp_path / "ray" / b.out.name
        assert np.array_equal(Motion.load(a).joints, Motion.load(b.out).joints)
        records = np.load(teacher_path(a))
        assert records["offsets"].shape[1] == 63
        assert np.array_equal(records["offsets"], np.load(teacher_path(b.out))["offsets"])
