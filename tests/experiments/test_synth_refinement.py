"""Two refinements of the same synthetic inputs compared item by item: real built motions as the inputs,
an identity "refinement" and one that raises every motion 2 cm (tests/morph/fake_synth.py)."""

import json
import shutil
from pathlib import Path

import numpy as np

from experiments.synth_refinement import main
from physmotion.paths import WEIGHTS_DIR
from tests.morph.fake_synth import make_synth


def test_a_paired_comparison_of_two_refinements(built_dir: Path, tmp_path: Path) -> None:
    raised = make_synth(built_dir, WEIGHTS_DIR / "morph", tmp_path / "raised", n=6, failed=1)
    same = tmp_path / "same"
    shutil.copytree(raised, same)
    for path in (same / "input_joints").iterdir():
        shutil.copy(path, same / "new_joints" / path.name)  # refined = input
    out = tmp_path / "table"
    assert main([str(same), str(raised), "--names", "same,raised", "--out", str(out), "--allow-dirty"]) == 0
    rows = {r["name"]: r for r in json.loads(out.with_suffix(".json").read_text())["rows"]}
    a, b = rows["same"], rows["raised"]
    assert a["items"] == b["items"] == 6 and a["refined"] == b["refined"] == 5 and a["fell"] == b["fell"] == 1
    assert a["output"] == a["input"] == b["input"] and a["mpjpe_mm"] == 0.0
    assert a["flight_kept"] in (None, 1.0)
    # raised 2 cm (and jittered 5 mm): the refined motion sinks less, floats more and is about 2 cm off
    assert b["output"]["penetrate"] < b["input"]["penetrate"] - 10.0
    assert b["output"]["float"] > b["input"]["float"]
    assert 20.0 <= b["mpjpe_mm"] <= 30.0


def test_folders_of_other_items_are_refused(built_dir: Path, tmp_path: Path, capsys) -> None:
    a = make_synth(built_dir, WEIGHTS_DIR / "morph", tmp_path / "a", n=3)
    b = make_synth(built_dir, WEIGHTS_DIR / "morph", tmp_path / "b", n=3)
    np.save(b / "input_joints" / "s0000.npy", np.load(b / "input_joints" / "s0000.npy") + 0.1)
    assert main([str(a), str(b), "--out", str(tmp_path / "t"), "--allow-dirty"]) == 1
    assert "generated inputs differ" in capsys.readouterr().err
    c = make_synth(built_dir, WEIGHTS_DIR / "morph", tmp_path / "c", n=2)
    assert main([str(a), str(c), "--out", str(tmp_path / "t"), "--allow-dirty"]) == 1
    assert "holds other items" in capsys.readouterr().err
    assert not (tmp_path / "t.json").exists()
