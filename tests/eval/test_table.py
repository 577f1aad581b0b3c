"""The evaluation table: mode parsing, the real-data row, and a quick run with real (tiny) models."""

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.eval.table import REAL, EvaluateConfig, evaluate, table_paths
from physmotion.generate import GenerateConfig
from physmotion.physics.projection import ProjectionConfig
from physmotion.pipelines.modes import PhysicsMode, parse_modes


def test_parse_modes_keeps_schedule_commas_and_spells_back():
    modes = parse_modes("none,none+floor,post:1,post,physdiff:end:4,space:1,physdiff")
    assert [str(m) for m in modes] == ["none", "none+floor", "post:1", "post:1", "physdiff:end:4,space:1",
                                       "physdiff:end:2,space:1,fly:last"]  # fmt: skip
    assert [str(m) for m in parse_modes("physdiff:start:2,end:2, physdiff:uniform:4")] == [
        "physdiff:start:2,end:2", "physdiff:uniform:4"]  # fmt: skip
    assert PhysicsMode.parse("post:4") == PhysicsMode("post", projections=4)
    assert str(PhysicsMode()) == "physdiff:end:2,space:1,fly:last"  # the last 2 of the default 10 steps
    with pytest.raises(PhysmotionError):
        parse_modes(" , ")


@pytest.fixture(scope="module")
def quick_table(tiny_model, tiny_evaluator, built_dir):
    # P resets at once where the tiny model's motions fall (nearly every step) rather than searching there
    base = GenerateConfig(sampler=SamplerConfig(steps=5), projection=ProjectionConfig.sampling(recover=False))
    cfg = EvaluateConfig(modes=("none", "none+floor", "post:1", "physdiff:end:1,space:1"), repeats=2,
                         max_motions=32, base=base)
    return evaluate(tiny_model, tiny_evaluator, built_dir, cfg)


def test_quick_table_has_every_row_and_metric(quick_table):
    assert list(quick_table.rows) == [REAL, "none", "none+floor", "post:1", "physdiff:end:1,space:1"]
    for name, row in quick_table.rows.items():
        for key in ("R@1", "R@2", "R@3", "FID", "MM-Dist", "Diversity", "penetrate", "float", "skate", "phys_err"):
            mean, half = row[key]
            assert np.isfinite(mean) and half >= 0, (name, key)
        assert row["R@1"][0] <= row["R@2"][0] <= row["R@3"][0]
        if name != REAL:
            assert row["sec/motion"][0] > 0
            assert 0 < row["MModality"][0] < 2  # unit embeddings: distances below 2
    for name in ("post:1", "physdiff:end:1,space:1"):  # P's outputs: their resets and outside help are counted
        row = quick_table.rows[name]
        assert 0 <= row["reset_rate"][0] <= 1 and row["resets"][0] >= 0
        assert 0 <= row["fell"][0] <= 1
        # the residual is bounded by the sampling preset's caps (0.3 W, 1 W m); a tiny model's motions need it
        assert 0 < row["residual_force"][0] <= row["residual_force_p95"][0] <= 0.3 + 1e-6
        assert 0 < row["residual_torque"][0] <= row["residual_torque_p95"][0] <= 1.0 + 1e-6
        # frames held at a cap (force, lift or torque): some wherever the force's p95 sits at its 0.3 W cap
        at_cap = row["residual_at_cap"][0]
        assert 0 <= at_cap <= 1 and (at_cap > 0.05 or row["residual_force_p95"][0] <= 0.297)
        assert 0 <= row["step_jumps"][0] <= 1 and row.get("flight_kept", (1.0, 0))[0] >= 0
        assert 0 <= row["step_jumps_p"][0] <= 1  # present in every mode with P
    # post:1's one P is given the plain sample itself: its jumps past P's input are its jumps past the sample
    assert quick_table.rows["post:1"]["step_jumps_p"] == quick_table.rows["post:1"]["step_jumps"]
    # post:1 projects each output once, and a projection that fell is one with a reset
    assert quick_table.rows["post:1"]["fell"][0] == pytest.approx(quick_table.rows["post:1"]["reset_rate"][0])
    for name in (REAL, "none", "none+floor"):
        row = quick_table.rows[name]
        assert "reset_rate" not in row and "residual_force" not in row and "ifr" not in row
    # against the plain samples: a constant shift onto the floor keeps all flight and adds no jump
    floor = quick_table.rows["none+floor"]
    assert floor["step_jumps"][0] == 0.0 and floor.get("flight_kept", (1.0, 0))[0] == pytest.approx(1.0)
    assert "step_jumps" not in quick_table.rows["none"] and "step_jumps" not in quick_table.rows[REAL]
    assert "step_jumps_p" not in floor and "step_jumps_p" not in quick_table.rows["none"]
    # the metrics' floor convention: real motions grounded on the body surface sink nowhere, and
    # none+floor never penetrates more than none
    assert quick_table.rows[REAL]["penetrate"][0] < 2.0
    assert quick_table.rows["none+floor"]["penetrate"][0] <= quick_table.rows["none"]["penetrate"][0] + 1e-9
    assert quick_table.meta["motions"] == 32 and quick_table.meta["repeats"] == 2
    made = {"physmotion", "commit", "dirty", "cpu", "date", "torch", "mujoco"}  # physmotion.provenance
    assert set(quick_table.meta["made"]) >= made


def test_real_row_fid_is_near_zero_and_physics_lowers_phys_err(quick_table):
    real_fid = quick_table.rows[REAL]["FID"][0]
    assert real_fid < 0.2 * quick_table.rows["none"]["FID"][0]
    # A 5-step tiny model makes motions far from physical; one projection fixes much of it.
    assert quick_table.rows["post:1"]["phys_err"][0] < quick_table.rows["none"]["phys_err"][0]


def test_table_writes_markdown_and_json(quick_table, tmp_path):
    md, js = quick_table.write(tmp_path / "results" / "quick")
    text = md.read_text()
    assert "| real |" in text and "| physdiff:end:1,space:1 |" in text and "FID ↓" in text
    data = json.loads(js.read_text())
    assert data["rows"]["none"]["FID"]["mean"] == pytest.approx(quick_table.rows["none"]["FID"][0])
    assert not list(tmp_path.rglob("*.tmp"))


def test_table_paths_keep_a_dotted_stem(tmp_path):
    # "-o runs/eval_0.5" once wrote runs/eval_0.md, where "-o runs/eval_0.25" wrote too
    assert table_paths(tmp_path / "eval_0.5") == (tmp_path / "eval_0.5.md", tmp_path / "eval_0.5.json")
    assert table_paths(tmp_path / "eval.md") == (tmp_path / "eval.md", tmp_path / "eval.json")
    assert table_paths("results/evaluate") == (Path("results/evaluate.md"), Path("results/evaluate.json"))


def test_bad_modes_fail_before_any_work(tiny_model, tiny_evaluator, built_dir):
    for modes in (("walk",), ("physdiff:end:60,space:1",), ("post:x",)):
        with pytest.raises(PhysmotionError):
            evaluate(tiny_model, tiny_evaluator, built_dir, EvaluateConfig(modes=modes))
    with pytest.raises(PhysmotionError, match="no split"):
        evaluate(tiny_model, tiny_evaluator, built_dir, EvaluateConfig(split="nosuch"))


def test_a_killed_evaluation_resumes_from_its_finished_runs(quick_table, tiny_model, tiny_evaluator,
                                                           built_dir, tmp_path):
    """A run stopped after its plain modes resumes from the saved runs: it generates only the rest, and its
    table is the uninterrupted one's (seconds per motion aside, which are timed anew)."""
    from physmotion.eval.parts import count_parts

    base = GenerateConfig(sampler=SamplerConfig(steps=5), projection=ProjectionConfig.sampling(recover=False))
    cfg = EvaluateConfig(modes=tuple(m for m in quick_table.rows if m != REAL), repeats=2, max_motions=32,
                         base=base)
    plain_work = 2 * 2 * 32  # none and none+floor, 2 repeats of 32 motions

    class Killed(Exception):
        pass

    def kill_after_the_plain_modes(done: int, total: int) -> None:
        if done > plain_work:
            raise Killed

    parts = tmp_path / "eval.parts"
    with pytest.raises(Killed):
        evaluate(tiny_model, tiny_evaluator, built_dir, cfg, on_progress=kill_after_the_plain_modes,
                 parts=parts)
    assert count_parts(parts) == 4
    seen: list[int] = []
    table = evaluate(tiny_model, tiny_evaluator, built_dir, cfg, on_progress=lambda d, t: seen.append(d),
                     parts=parts)
    assert seen[:4] == [32, 64, 96, 128]  # the four saved runs, each reported whole, none generated
    assert count_parts(parts) == 8
    for row, values in quick_table.rows.items():
        for metric, value in values.items():
            if metric != "sec/motion":
                assert table.rows[row][metric] == pytest.approx(value, rel=1e-9, abs=1e-12), (row, metric)
    # Another seed decides other runs: none of the saved ones is reused.
    seen.clear()
    evaluate(tiny_model, tiny_evaluator, built_dir, replace(cfg, seed=1, modes=("none",), repeats=1),
             on_progress=lambda d, t: seen.append(d), parts=parts)
    assert seen == [16, 32]  # generated again, in two sampling batches
