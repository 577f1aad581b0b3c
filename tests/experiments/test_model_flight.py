"""Plain samples of jump prompts per model, held against the first model: the shipped models' own samples."""

import json
from pathlib import Path

import pytest

from experiments.model_flight import main, prompts
from physmotion.paths import WEIGHTS_DIR


@pytest.mark.slow
def test_a_model_against_itself_keeps_all_its_flight(tmp_path: Path) -> None:
    base, morph = str(WEIGHTS_DIR / "base"), str(WEIGHTS_DIR / "morph")
    out = tmp_path / "flight"
    argv = ["--model", base, "--model", base, "--model", morph, "--names", "base,again,morph", "--seeds", "0",
            "--seconds", "2", "--out", str(out), "--allow-dirty"]  # fmt: skip
    assert main(argv) == 0
    rows = json.loads(out.with_suffix(".json").read_text())["rows"]
    assert [r["name"] for r in rows] == ["base", "again", "morph"]
    assert all(r["samples"] == len(prompts()) for r in rows)
    first, again, other = rows
    # the same model from the same noise: the same samples, so every flying sample keeps all its flight
    assert first["flight_each_m"] == again["flight_each_m"] and first["compared"] == first["flying"] > 0
    assert first["flight_kept"] == again["flight_kept"] == 1.0
    assert other["flight_each_m"] != first["flight_each_m"] and other["compared"] == first["flying"]
    assert all(r["phys_err"] == pytest.approx(r["penetrate"] + r["float"] + r["skate"]) for r in rows)
    table = out.with_suffix(".md").read_text()
    assert "flight kept against base" in table
    # the physical metrics are in mm already: the table shows them as they are
    assert f"| {first['phys_err']:.1f} |" in table.splitlines()[-3]


def test_names_must_match_the_models(tmp_path: Path, capsys) -> None:
    argv = ["--model", "a", "--model", "b", "--names", "x", "--out", str(tmp_path / "f"), "--allow-dirty"]
    assert main(argv) == 1
    assert "--names gives 1 names for 2 models" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())
