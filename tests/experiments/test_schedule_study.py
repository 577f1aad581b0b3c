"""The projection-schedule study (PhysDiff Fig. 4) end to end on a tiny model: rows, files, the plot."""

import shutil
from pathlib import Path

import pytest
from PIL import Image

from experiments.schedule_study import main, mode_for, schedule_study, write_study
from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.eval.table import EvaluateConfig
from physmotion.generate import GenerateConfig
from physmotion.physics.projection import ProjectionConfig


def test_mode_for_counts():
    assert mode_for(0) == "none"
    assert mode_for(4) == "physdiff:end:4,space:1"


def test_study_writes_table_json_and_png(tiny_model, tiny_evaluator, built_dir, tmp_path):
    # P resets at once where the tiny model's motions fall (nearly every step) rather than searching there
    base = GenerateConfig(sampler=SamplerConfig(steps=4), projection=ProjectionConfig.sampling(recover=False))
    cfg = EvaluateConfig(repeats=1, max_motions=32, base=base)
    table = schedule_study(tiny_model, tiny_evaluator, built_dir, [0, 2], cfg)
    assert list(table.rows) == ["real", "0", "2"]
    assert table.rows["2"]["phys_err"][0] < table.rows["0"]["phys_err"][0]
    md, js, png = write_study(table, tmp_path / "study")
    assert md.read_text().count("\n| ") >= 6 and js.stat().st_size > 0
    with Image.open(png) as img:
        assert img.format == "PNG" and img.size[0] > 400


def test_counts_outside_the_sampling_steps_are_refused(tiny_model, tiny_evaluator, built_dir):
    cfg = EvaluateConfig(repeats=1, base=GenerateConfig(sampler=SamplerConfig(steps=4)))
    with pytest.raises(PhysmotionError, match="0..4"):
        schedule_study(tiny_model, tiny_evaluator, built_dir, [0, 5], cfg)


def test_plot_only_redraws_the_committed_study(tmp_path: Path) -> None:
    """The driver's --plot-only redraws <out>.png from the committed results/schedule_study.json."""
    shutil.copy(Path(__file__).parents[2] / "results" / "schedule_study.json", tmp_path / "study.json")
    assert main(["--allow-dirty", "--data", "unused", "--out", str(tmp_path / "study"), "--plot-only"]) == 0
    with Image.open(tmp_path / "study.png") as img:
        assert img.format == "PNG" and img.size[0] > 400
