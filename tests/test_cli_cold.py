"""The command line's cold start and ``generate --prompts`` (issue 51, items 1 and 3).

Cold start: ``--help`` and an argument error import neither torch nor numpy's heavy company; the checks
run in a fresh interpreter (a fraction of a second each). --prompts runs in-process (tests/cli_runner.py)
with the shipped model at 2 sampling steps."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from physmotion.cli.io import RIG_NAMES
from tests.cli_runner import invoke

HEAVY = ("torch", "transformers", "diffusers", "mujoco", "scipy", "sentence_transformers")


def _modules_after(*argv: str) -> tuple[set[str], str]:
    """Run ``physmotion ARGV`` in a fresh interpreter; the heavy modules it imported, and its stderr."""
    code = ("import sys\nfrom physmotion.cli import main\nsys.argv = ['physmotion', *sys.argv[1:]]\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            f"print('heavy:', *(m for m in {HEAVY!r} if m in sys.modules), file=sys.stderr)")  # fmt: skip
    res = subprocess.run(
        [sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=120, check=False
    )
    *lines, last = res.stderr.strip().splitlines()
    assert last.startswith("heavy:"), res.stderr
    return set(last.split()[1:]), "\n".join(lines)


def test_rig_names_match_the_tables() -> None:
    from physmotion.io.rigs import RIGS

    assert tuple(RIGS) == RIG_NAMES


def test_help_imports_nothing_heavy() -> None:
    heavy, _ = _modules_after("--help")
    assert heavy == set()
    heavy, _ = _modules_after("generate", "--help")
    assert heavy == set()


def test_python_m_runs_the_package_with_commands_in_help_order() -> None:
    """``python -m physmotion.cli`` (the package's __main__.py) is the console script; its --help lists the
    commands in the order the command modules register them (physmotion/cli/__init__.py's imports)."""
    res = subprocess.run([sys.executable, "-m", "physmotion.cli", "--help"], capture_output=True, text=True,
                         timeout=120, check=False)  # fmt: skip
    assert res.returncode == 0 and res.stdout.startswith("Usage: python -m physmotion.cli "), res.stderr
    listed = [line.split()[0] for line in res.stdout.split("Commands:\n", 1)[1].splitlines() if line.strip()]
    assert listed == ["import", "export", "project", "metrics", "refine", "generate", "evaluate", "render",
                      "view", "serve", "data", "train", "morph"]  # fmt: skip


def test_argument_errors_come_before_torch(tmp_path: Path) -> None:
    heavy, err = _modules_after("generate", "a person walks", "--seconds", "20")
    assert "error: --seconds must be between 2 and 9.8 (the model's range), got 20" in err and heavy == set()
    prompts = tmp_path / "p.txt"
    prompts.write_text("a person walks\na person jumps | 12\n", encoding="utf-8")
    heavy, err = _modules_after("generate", "--prompts", str(prompts))
    assert f"error: {prompts}:2: the length must be between 2 and 9.8 seconds" in err and heavy == set()
    for argv, message in [(("generate", "walk", "--steps", "0"), "steps must be between 1 and 1000, got 0"),
                          (("generate", "walk", "--num", "0"), "--num must be between 1 and 256, got 0"),
                          (("generate", "walk", "--sampler", "euler"), "unknown sampler 'euler'"),
                          (("generate", "walk", "--speed", "2"), "--phys-scale and --speed need a BioMoDiffuse")]:  # fmt: skip
        res = invoke(*argv, "-o", tmp_path / "out")
        assert res.returncode == 1 and message in res.stderr, res.stderr


def test_prompts_file_one_batch_with_seconds_per_line(tmp_path: Path) -> None:
    prompts = tmp_path / "prompts.txt"
    prompts.write_text("# three prompts\na person jumps | 2.5\n\na person waves the right hand\t3\na person walks forward\n",
                       encoding="utf-8")  # fmt: skip
    out = tmp_path / "out"
    res = invoke(
        "generate", "--prompts", prompts, "--physics", "none", "--no-preview", "--steps", "2", "-o", out
    )
    assert res.returncode == 0, res.stderr
    assert "predicted from the text" in res.stdout and "a person walks forward" in res.stdout
    assert "a person jumps" not in res.stdout.split("wrote")[0]  # lengths given in the file are not announced
    (run,) = json.loads((out / "generate.json").read_text())["runs"]
    got = [(m["prompt"], m["seconds"], m["length_source"]) for m in run["motions"]]
    assert got[:2] == [("a person jumps", 2.5, "given"), ("a person waves the right hand", 3.0, "given")]
    assert got[2][0] == "a person walks forward" and got[2][2] == "predicted"
    assert len(list(out.glob("*.npz"))) == 3


def test_prompts_with_explicit_seconds_and_errors(tmp_path: Path) -> None:
    prompts = tmp_path / "prompts.txt"
    prompts.write_text("a person jumps | 2.5\na person walks forward\n", encoding="utf-8")
    out = tmp_path / "out"
    res = invoke("generate", "--prompts", prompts, "--seconds", "2", "--physics", "none", "--no-preview",
                 "--steps", "2", "-o", out)  # fmt: skip
    assert res.returncode == 0, res.stderr
    assert "warning: --seconds 2 applies to every prompt, also to the 1 line(s)" in res.stderr
    (run,) = json.loads((out / "generate.json").read_text())["runs"]
    assert [m["seconds"] for m in run["motions"]] == [2.0, 2.0]
    res = invoke("generate", "walk", "--prompts", prompts, "-o", out)
    assert res.returncode == 1 and "not both" in res.stderr
    res = invoke("generate", "-o", out)
    assert res.returncode == 1 and "--prompts FILE" in res.stderr
    res = invoke("generate", "--prompts", tmp_path / "nope.txt", "-o", out)
    assert res.returncode == 1 and "nope.txt: no such prompt file" in res.stderr
