"""What made a result (physmotion.provenance): the checkout's state read from a real git repository, and
the record ``physmotion evaluate`` writes into its table's meta."""

from __future__ import annotations

from datetime import datetime
from pathlib import Path

import mujoco
import torch

from physmotion import __version__
from physmotion.provenance import Checkout, checkout, provenance
from tests.conftest import run_git


def test_checkout_reads_tracked_changes_only(git_repo: Path) -> None:
    head = run_git(git_repo, "rev-parse", "--short", "HEAD")
    assert checkout(git_repo) == Checkout(head, False)
    (git_repo / "notes.txt").write_text("untracked\n")  # untracked: still clean
    assert checkout(git_repo) == Checkout(head, False)
    (git_repo / "code.py").write_text("x = 2\n")
    assert checkout(git_repo) == Checkout(head + "+dirty", True)


def test_outside_a_checkout_there_is_no_commit(tmp_path: Path, git_repo: Path) -> None:
    beside = tmp_path / "elsewhere"  # a folder beside the repository, in none
    beside.mkdir()
    assert checkout(beside) == Checkout(None, True)
    inside = git_repo / "venv" / "site-packages"  # a wheel installed into a venv inside some repository
    inside.mkdir(parents=True)
    assert checkout(inside) == Checkout(None, True)
    assert checkout(tmp_path / "missing") == Checkout(None, True)


def test_provenance_names_this_code_and_machine() -> None:
    made = provenance()
    root = Path(__file__).resolve().parents[1]
    head = run_git(root, "rev-parse", "--short", "HEAD")  # the tests run from the project's checkout
    assert made["commit"] in (head, head + "+dirty") and made["dirty"] == made["commit"].endswith("+dirty")
    assert made["physmotion"] == __version__ and made["cores"] >= 1 and made["cpu"].strip()
    assert made["torch"] == torch.__version__
    assert made["mujoco"] == mujoco.__version__
    assert datetime.fromisoformat(made["date"]).tzinfo is not None
