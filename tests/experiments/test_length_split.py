"""experiments/length_split on a small real build: the split by caption's table and figures."""

import json
from pathlib import Path

from experiments.length_split import main
from physmotion.text.length import length_examples


def test_main_writes_the_caption_split(small_built_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "ls"
    assert main(["--data", str(small_built_dir), "--out", str(out), "--allow-dirty"]) == 0
    data = json.loads(out.with_suffix(".json").read_text())
    split = data["caption_split"]
    assert sum(split["examples"].values()) == len(length_examples(small_built_dir))
    assert split["examples"]["train"] > 0 and split["test_captions_seen"] <= split["examples"]["test"]
    assert data["meta"]["model"] == "physmotion/weights/length" and data["meta"]["preset"] is None
    assert "| refit on its train + val (ridge" in out.with_suffix(".md").read_text()


def test_a_folder_that_is_no_build_is_one_error_line(tmp_path: Path, capsys) -> None:
    assert main(["--data", str(tmp_path), "--out", str(tmp_path / "ls"), "--allow-dirty"]) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "index.csv" in err and "\n" not in err
    assert not list(tmp_path.glob("ls*"))
