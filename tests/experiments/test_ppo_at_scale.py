"""experiments/ppo_at_scale.py: every row measured on both held-out sets, each PPO row with its card's
budget; a malformed --ppo or an empty teacher folder is refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from experiments.ppo_at_scale import main
from physmotion.paths import WEIGHTS_DIR

SHIPPED = str(WEIGHTS_DIR / "imitator")  # a policy folder with a PPO card: stands in for a run's export


def test_rows_on_both_sets_with_each_run_s_samples(small_built_dir: Path, teacher_dir: Path,
                                                  tmp_path: Path) -> None:  # fmt: skip
    out = tmp_path / "scale"
    payload = main(["--teacher", str(teacher_dir), "--student", SHIPPED, "--ppo", f"shipped={SHIPPED}",
                    "--data", str(small_built_dir), "--captured-test", "1", "--max-seconds", "1",
                    "--prompts", "1", "--workers", "1", "--results", str(out), "--allow-dirty"])  # fmt: skip
    names = [r["row"] for r in payload["rows"]]
    assert names == ["tracker, hand on", "tracker, hand off", "warm start (student)", "PPO, shipped"]
    for row in payload["rows"]:
        for s in ("captured", "generated"):
            assert row[s]["motions"] == 1 and 0.0 <= row[s]["survived"] <= 1.0 and row[s]["cpu_s_per_s"] > 0
    with np.load(next(teacher_dir.glob("*.npz"))) as z:
        steps, cpu, tag = len(z["offsets"]), float(z["cpu_seconds"]), str(z["licence_tag"])
    assert payload["teacher"] == {"records": 1, "control_steps": steps, "cpu_seconds": round(cpu, 1),
                                  "licence_tags": [tag]} and steps > 20  # fmt: skip
    samples = json.loads((Path(SHIPPED) / "card.json").read_text())["samples"]
    assert payload["cards"]["shipped"]["samples"] == samples
    table = out.with_suffix(".md").read_text()
    assert f"{samples:,} (" in table.splitlines()[-1]  # the PPO row names its budget; the others do not


@pytest.mark.parametrize(("ppo", "teacher"), [("no-equals-sign", None), ("x=/nonexistent/policy", None),
                                              (f"shipped={SHIPPED}", "empty")])  # fmt: skip
def test_bad_input_is_refused_in_one_line_before_any_work(
    ppo: str, teacher: str | None, teacher_dir: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    folder = teacher_dir
    if teacher == "empty":  # a teacher folder with no records
        folder = tmp_path / "empty"
        folder.mkdir()
    with pytest.raises(SystemExit) as e:
        main(["--teacher", str(folder), "--student", SHIPPED, "--ppo", ppo,
              "--results", str(tmp_path / "r"), "--allow-dirty"])  # fmt: skip
    assert e.value.code == 2 and "error:" in capsys.readouterr().err
    assert not (tmp_path / "r.md").exists() and not (tmp_path / "r.json").exists()
