"""The installed console script in a real process agrees with the in-process runner the CLI tests use
(tests/cli_runner.py): the same exit code, stdout and stderr for help, a one-line error, a warning, and
real work. Slow tier: each process starts Python, torch and the text encoder (3-5 s)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physmotion.motion import Motion
from tests.cli_runner import invoke

pytestmark = pytest.mark.slow

PHYSMOTION = Path(sys.executable).parent / "physmotion"
BANDAI_WALK = "bandai/Bandai-Namco-Research-Motiondataset-2/data/dataset-2_walk_normal_001.bvh"


def process(*args: object) -> subprocess.CompletedProcess:
    """The console script as a user types it, in a pipe."""
    return subprocess.run([str(PHYSMOTION), *map(str, args)], capture_output=True, text=True, timeout=600,
                          check=False)  # fmt: skip


def assert_same(*args: object) -> subprocess.CompletedProcess:
    real, here = process(*args), invoke(*args)
    assert (here.returncode, here.stdout, here.stderr) == (real.returncode, real.stdout, real.stderr), args
    return real


@pytest.mark.parametrize("command", [["--version"], ["-h"], ["generate", "--help"], ["data", "build", "-h"]])
def test_help_and_version_are_the_same(command: list[str]) -> None:
    assert assert_same(*command).returncode == 0


def test_errors_warnings_and_work_are_the_same(mocap_dir: Path, tmp_path: Path) -> None:
    res = assert_same("import", tmp_path / "missing.bvh", "-o", tmp_path / "x.npz")
    assert res.returncode == 1 and res.stderr.startswith("error: ")
    walk = tmp_path / "walk.npz"
    assert process("import", mocap_dir / BANDAI_WALK, "-o", walk).returncode == 0
    bare = tmp_path / "bare.npz"
    np.savez(bare, joints=Motion.load(walk).joints)  # no fps: one warning line
    res = assert_same("metrics", walk, bare, "--surface", "joints")
    assert res.returncode == 0 and res.stderr.startswith("warning: ") and "penetrate" in res.stdout
    assert assert_same("generate", "walk", "--seconds", "1000", "-o", tmp_path / "g").returncode == 1


def test_python_dash_m_runs_the_same_main(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, "-m", "physmotion.cli", "--version"], capture_output=True, text=True,
                         timeout=600, check=False)  # fmt: skip
    assert res.returncode == 0 and res.stdout == invoke("--version").stdout
