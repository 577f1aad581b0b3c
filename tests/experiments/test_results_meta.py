"""Figures from clean trees (issue 62 item 6): an experiment refuses a checkout whose tracked files differ
from HEAD unless given --allow-dirty, and its meta then says "dirty": true. Run against a real temporary
git repository standing in for the project's checkout (experiments._results.ROOT)."""

import json
from pathlib import Path

import pytest

from experiments import _results
from experiments._results import Tree, tree_state
from tests.conftest import run_git


def test_tree_state_reads_tracked_changes_only(git_repo: Path) -> None:
    head = run_git(git_repo, "rev-parse", "--short", "HEAD")
    assert tree_state(git_repo) == Tree(head, False)
    (git_repo / "notes.txt").write_text("untracked\n")  # untracked: still clean
    assert tree_state(git_repo) == Tree(head, False)
    (git_repo / "code.py").write_text("x = 2\n")  # a tracked file edited
    assert tree_state(git_repo) == Tree(head + "+dirty", True)
    run_git(git_repo, "add", "code.py")  # staged but not committed: still dirty
    assert tree_state(git_repo).dirty
    run_git(git_repo, "commit", "-q", "-m", "second")
    assert tree_state(git_repo) == Tree(run_git(git_repo, "rev-parse", "--short", "HEAD"), False)


def test_outside_a_checkout_counts_as_dirty(tmp_path: Path) -> None:
    assert tree_state(tmp_path) == Tree("unknown+dirty", True)


def test_a_dirty_tree_is_refused_before_any_work(git_repo: Path, tmp_path: Path, monkeypatch) -> None:
    from experiments.physics_raw_speed import main

    monkeypatch.setattr(_results, "ROOT", git_repo)
    (git_repo / "code.py").write_text("x = 2\n")
    out = tmp_path / "raw"
    with pytest.raises(SystemExit) as exc:
        main(["--seconds", "0.1", "--repeats", "1", "--out", str(out)])
    message = str(exc.value.code)
    assert message.startswith("error: ") and "\n" not in message
    assert "tracked files differ from HEAD" in message and "--allow-dirty" in message
    assert not list(tmp_path.glob("raw*"))  # nothing written


def test_allow_dirty_runs_and_records_it(git_repo: Path, tmp_path: Path, monkeypatch) -> None:
    from experiments.physics_raw_speed import main

    monkeypatch.setattr(_results, "ROOT", git_repo)
    head = run_git(git_repo, "rev-parse", "--short", "HEAD")
    (git_repo / "code.py").write_text("x = 2\n")
    main(["--seconds", "0.1", "--repeats", "1", "--out", str(tmp_path / "raw"), "--allow-dirty"])
    meta = json.loads((tmp_path / "raw.json").read_text())["meta"]
    assert meta["dirty"] is True and meta["commit"] == head + "+dirty"
    assert meta["command"].endswith("--allow-dirty")


def test_a_clean_tree_runs_without_the_flag(git_repo: Path, tmp_path: Path, monkeypatch) -> None:
    from experiments.physics_raw_speed import main

    monkeypatch.setattr(_results, "ROOT", git_repo)
    main(["--seconds", "0.1", "--repeats", "1", "--out", str(tmp_path / "raw")])
    meta = json.loads((tmp_path / "raw.json").read_text())["meta"]
    assert meta["dirty"] is False and meta["commit"] == run_git(git_repo, "rev-parse", "--short", "HEAD")


def test_every_experiment_that_writes_a_meta_takes_the_flag() -> None:
    """The shared flag reaches every script that records a meta: each parses through _results.parse_args."""
    scripts = [p for p in (_results.ROOT / "experiments").glob("*.py") if "run_meta(" in p.read_text()]
    scripts = [p for p in scripts if p.name != "_results.py"]
    assert len(scripts) >= 19
    for path in scripts:
        text = path.read_text()
        assert "parse_args(parser, argv)" in text or "parse_args(ap, argv)" in text, path.name
        assert ".parse_args(argv)" not in text, path.name
