"""experiments/refine.py on one test clip with the tiny model: every noise level and variant, both files."""

import json
from pathlib import Path

import pytest

from experiments.refine import SIGMAS_CM, main


@pytest.mark.slow  # a real table run: 16 variants of the clip, 6 of them refined (about a minute)
def test_refine_table_writes_every_row_and_its_meta(small_built_dir: Path, tiny_model_dir: Path,
                                                     tmp_path: Path) -> None:  # fmt: skip
    out = tmp_path / "refine"
    main(["--data", str(small_built_dir), "--model", str(tiny_model_dir), "--limit", "1", "-o", str(out),
          "--allow-dirty"])
    data = json.loads(out.with_suffix(".json").read_text())
    assert data["meta"]["preset"] is None and data["meta"]["clips"] == 1  # no projection in refinement
    assert data["meta"]["command"].startswith("python -m experiments.refine --data")
    settings = [r["setting"] for r in data["rows"]]
    assert settings[0] == "clean" and len(settings) == 1 + 5 * len(SIGMAS_CM)  # noisy, 2 filters, refine and plain
    assert "| 2 cm | refine 0.3 |" in out.with_suffix(".md").read_text()
