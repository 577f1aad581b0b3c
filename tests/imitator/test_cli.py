"""The imitator on the command line: ``train imitator`` and ``--controller`` on ``project``."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from physmotion.motion import Motion
from tests.cli_runner import invoke


def test_train_imitator_needs_data(tmp_path: Path) -> None:
    res = invoke("train", "imitator", "-o", tmp_path / "run", "--iterations", "1")
    assert res.returncode == 1 and res.stderr.strip() == "error: give at least one --data, --motions or --teacher folder"
    res = invoke("train", "imitator", "--data", tmp_path / "nothing", "-o", tmp_path / "run", "--iterations", "1")
    assert res.returncode == 1 and "not a dataset folder" in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "run").exists()


def test_train_imitator_on_teacher_records_from_a_warm_start(teacher_dir: Path, tmp_path: Path) -> None:
    from tests.imitator.test_train import _policy_folder

    _policy_folder(tmp_path / "student")
    res = invoke("train", "imitator", "--teacher", teacher_dir, "--data", teacher_dir, "-o", tmp_path / "run",
                 "--iterations", "1")  # fmt: skip
    assert res.returncode == 1 and "without --data or --motions" in res.stderr
    assert not (tmp_path / "run").exists()
    res = invoke("train", "imitator", "--teacher", teacher_dir, "--warm-start", tmp_path / "nothing",
                 "-o", tmp_path / "run", "--iterations", "1")  # fmt: skip
    assert res.returncode == 1 and "not an imitation policy folder" in res.stderr
    assert "Traceback" not in res.stderr and not (tmp_path / "run").exists()
    res = invoke("train", "imitator", "--teacher", teacher_dir, "--warm-start", tmp_path / "student",
                 "-o", tmp_path / "run", "--iterations", "1", "--envs", "2", "--workers", "1")  # fmt: skip
    assert res.returncode == 0, res.stderr
    card = json.loads((tmp_path / "run" / "policy" / "card.json").read_text())
    settings = json.loads((tmp_path / "run" / "policy" / "settings.json").read_text())
    assert card["warm_start"] == str(tmp_path / "student") and card["train_config"]["init_std"] == 0.1
    assert settings["action_scale"] == 0.4 and settings["cap"] == 0.0


def test_project_with_the_policy_reports_the_residual(small_built_dir: Path, tmp_path: Path) -> None:
    joints = np.load(next((small_built_dir / "new_joints").glob("bandai2_dataset-2_walk_normal_001_*.npy")))
    Motion(joints=joints.astype(np.float32), texts=["a walk"]).save(tmp_path / "walk.npz")
    res = invoke("project", tmp_path / "walk.npz", "-o", tmp_path / "sim.npz", "--controller", "policy")
    assert res.returncode == 0, res.stderr
    assert "(policy)" in res.stdout and "root residual force mean" in res.stdout and "p95" in res.stdout
    out = Motion.load(tmp_path / "sim.npz")
    assert out.residual is not None and float(out.residual[:, 0].max()) <= 0.05 + 1e-6  # the policy's cap
    res = invoke("project", tmp_path / "walk.npz", "-o", tmp_path / "x.npz", "--controller", "pid")
    assert res.returncode == 1 and "controller must be one of tracker, policy, search" in res.stderr
    assert not (tmp_path / "x.npz").exists()


def test_train_teacher_and_student_from_the_command_line(small_built_dir: Path, tmp_path: Path) -> None:
    res = invoke("train", "teacher", "-o", tmp_path / "t")
    assert res.returncode == 1 and res.stderr.strip() == "error: give at least one --data or --motions folder"
    res = invoke("train", "teacher", "--data", small_built_dir, "-o", tmp_path / "t", "--jobs", "1",
                 "--effort", "fast", "--perturbed", "0")  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "1 of 1 searches" in res.stdout
    assert len(list((tmp_path / "t").glob("*.npz"))) == 1 and (tmp_path / "t" / "index.json").is_file()
    res = invoke("train", "student", "--teacher", tmp_path / "nothing", "-o", tmp_path / "s")
    assert res.returncode == 1 and "no teacher records" in res.stderr and "Traceback" not in res.stderr
    res = invoke("train", "student", "--teacher", tmp_path / "t", "-o", tmp_path / "s", "--dagger-rounds", "1",
                 "--steps", "50")  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "DAgger 1" in res.stdout and (tmp_path / "s" / "dagger1" / "policy.safetensors").is_file()
    res = invoke("train", "student", "--teacher", tmp_path / "t", "-o", tmp_path / "s")
    assert res.returncode == 1 and "Traceback" not in res.stderr  # an output folder in use is never replaced
