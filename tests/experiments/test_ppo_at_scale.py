"""experiments/ppo_at_scale.py: every row measured on both held-out sets, each PPO row with its card's budget."""

from __future__ import annotations

import json
from pathlib import Path

from experiments.ppo_at_scale import main
from physmotion.paths import WEIGHTS_DIR

SHIPPED = str(WEIGHTS_DIR / "imitator")  # a policy folder with a PPO card: stands in for a run's export


def test_rows_on_both_sets_with_each_run_s_samples(small_built_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "scale"
    payload = main(["--student", SHIPPED, "--ppo", f"shipped={SHIPPED}", "--data", str(small_built_dir),
                    "--captured-test", "1", "--max-seconds", "1", "--prompts", "1", "--workers", "1",
                    "--results", str(out), "--allow-dirty"])  # fmt: skip
    names = [r["row"] for r in payload["rows"]]
    assert names == ["tracker, hand on", "tracker, hand off", "warm start (student)", "PPO, shipped"]
    for row in payload["rows"]:
        for s in ("captured", "generated"):
            assert row[s]["motions"] == 1 and 0.0 <= row[s]["survived"] <= 1.0 and row[s]["cpu_s_per_s"] > 0
    samples = json.loads((Path(SHIPPED) / "card.json").read_text())["samples"]
    assert payload["cards"]["shipped"]["samples"] == samples
    table = out.with_suffix(".md").read_text()
    assert f"{samples:,} (" in table.splitlines()[-1]  # the PPO row names its budget; the others do not
