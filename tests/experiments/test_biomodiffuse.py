"""BioMoDiffuse's ablation: the row comparisons, and one row evaluated with a real (tiny) biomo model."""

import numpy as np
import pytest

from experiments.biomodiffuse import ROWS, RUNS, evaluate_row, markdown_table, separated, wins
from physmotion.diffusion.samplers import BIOMO_SAMPLER


def test_rows_are_the_papers_and_guidance_samples_the_dropout_model():
    assert [r.name for r in ROWS] == ["UNet baseline (263-d)", "+ L_accel (329-d)", "+ PhysNet",
                                      "+ PhysNet (P_c 10 %)", "+ physics guidance"]  # fmt: skip
    assert [RUNS[r.run]["arch"] for r in ROWS] == ["unet", "unet", "biomo", "biomo", "biomo"]
    assert [RUNS[r.run]["features"] for r in ROWS] == [263, 329, 329, 329, 329]
    assert RUNS[ROWS[2].run]["phys_drop"] == 0.0  # the paper's "+ PhysNet": no dropout, no guidance
    assert ROWS[3].run == ROWS[4].run and RUNS[ROWS[4].run]["phys_drop"] == 0.1  # guidance needs P_c
    assert ROWS[2].sampler().phys_scale is None and ROWS[3].sampler().phys_scale is None
    assert ROWS[4].sampler().phys_scale == BIOMO_SAMPLER.phys_scale
    assert {r.sampler().sampler for r in ROWS} == {"dpmpp-sde"} and {r.sampler().steps for r in ROWS} == {10}


def test_separated_needs_disjoint_intervals():
    a = {"x": (1.0, 0.1), "y": (1.0, 0.1), "z": (1.0, 0.1)}
    b = {"x": (1.3, 0.1), "y": (0.85, 0.1), "z": (0.75, 0.1)}
    assert separated(a, b, ("x", "y", "z")) == {"x": ">", "y": "~", "z": "<"}
    # a column one row lacks (MModality of a 1-repeat run) is left out, not a KeyError
    assert separated(a, {"x": b["x"]}, ("x", "y")) == {"x": ">"}


def test_wins_follow_each_metrics_better_direction():
    real = {"vc": (0.9, 0.0), "skate_ratio": (0.01, 0.0), "smoothness": (100.0, 0.0)}
    base = {"vc": (0.3, 0.01), "skate_ratio": (0.5, 0.01), "smoothness": (2000.0, 10.0)}
    # vc closer to the real 0.9 wins; a lower skate ratio wins; a smoothness still inside the noise does not
    row = {"vc": (0.5, 0.01), "skate_ratio": (0.4, 0.01), "smoothness": (1995.0, 10.0)}
    assert wins(base, row, real, ("vc", "skate_ratio", "smoothness")) == ["vc", "skate_ratio"]
    # moving vc past the real value by more than the baseline's distance is not closer
    assert wins(base, {**row, "vc": (1.6, 0.01)}, real, ("vc",)) == []


def test_markdown_table_has_a_line_per_row():
    text = markdown_table({"a": {"FID": (0.1234, 0.01)}, "b": {"FID": (12.34, 0.5)}}, ("FID",))
    lines = text.splitlines()
    assert lines[0] == "| row | FID |" and len(lines) == 4
    assert "0.123 ± 0.010" in lines[2] and "12.3 ± 0.5" in lines[3]


@pytest.mark.slow
def test_a_biomo_row_is_measured_without_the_real_row(tiny_biomo, tiny_evaluator, built_dir):
    """A 329-d model is measured on the 263-d build's split; the real row is left out when asked."""
    from dataclasses import replace

    sampler = replace(ROWS[-1].sampler(), steps=3)
    row, real = evaluate_row(tiny_biomo, tiny_evaluator, built_dir, sampler, repeats=1, real_row=False)
    assert real is None
    for key in ("FID", "R@3", "vc", "ac", "speed", "smoothness", "float_ratio", "skate_ratio", "phys_err"):
        assert np.isfinite(row[key][0]), key
