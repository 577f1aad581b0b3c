"""The few-step sampling study reads its evaluate tables, holds each row against DDIM 50's intervals and
writes its table with the meta block (no model run: tables made up here, timing skipped)."""

import json
from pathlib import Path

import pytest

from experiments.sampling_steps import BASELINE, PHYSDIFF_BASE, RUNS, acceptance, main, table_rows
from physmotion.errors import PhysmotionError


def _figure(mean: float, ci: float = 0.0) -> dict:
    return {"mean": mean, "ci95": ci}


def _tables(folder: Path, fid: dict[str, float]) -> None:
    """One evaluate table per run of RUNS; every mode's FID from ``fid`` (by run name), R@3 0.85 ± 0.02."""
    for run in RUNS:
        meta = {"split": "test", "repeats": 3, "seed": 0, "motions": 58, "modes": list(run.modes),
                "sampler": {"sampler": run.sampler, "steps": run.steps, "eta": 0.0, "cfg_scale": 2.5}}  # fmt: skip
        rows = {m: {"FID": _figure(fid[run.name], 0.005), "R@3": _figure(0.85, 0.02), "phys_err": _figure(7.0, 0.3),
                    "sec/motion": _figure(1.0, 0.01)} for m in run.modes}  # fmt: skip
        (folder / f"{run.name}.json").write_text(json.dumps({"meta": meta, "rows": rows}))


def test_rows_are_held_against_ddim50(tmp_path: Path) -> None:
    fid = {r.name: 0.130 for r in RUNS} | {"ddim10": 0.2, "dpmpp15": 0.10}
    _tables(tmp_path, fid)
    tables = {r.name: json.loads((tmp_path / f"{r.name}.json").read_text()) for r in RUNS}
    times = {("dpmpp", 10, "none"): [0.2, 0.15], ("dpmpp", 10, "physdiff:end:2,space:1"): [0.5, 0.3]}
    rows = {(r["sampler"], r["steps"], r["physics"]): r for r in table_rows(RUNS, tables, times)}
    assert not rows[("ddim", 10, "none")]["FID_within"]  # 0.2 > 0.130 + 0.005
    assert rows[("dpmpp", 15, "none")]["FID_within"]  # better than the interval counts as within
    assert rows[("dpmpp", 10, "physdiff:end:2,space:1")]["warm_over_plain"] == pytest.approx(2.0)
    lines = {(a["sampler"], a["steps"], a["physics"]): a for a in acceptance(list(rows.values()))}
    assert ("ddim", 50, "none") not in lines
    assert lines[("dpmpp", 10, "none")]["plain_at_most_0.2_s"] is True
    assert lines[("dpmpp", 10, "physdiff:end:2,space:1")]["physdiff_at_most_1.5x_plain"] is False
    assert lines[("dpmpp", 20, "none")]["plain_at_most_0.2_s"] is None  # not timed


def test_main_writes_the_table_and_meta(tmp_path: Path) -> None:
    _tables(tmp_path, {r.name: 0.13 for r in RUNS})
    out = tmp_path / "study"
    assert main(["--allow-dirty", "--tables", str(tmp_path), "--skip-timing", "--out", str(out)]) == 0
    data = json.loads(out.with_name("study.json").read_text())
    assert {"preset", "commit", "cpu", "date", "command"} <= set(data["meta"])
    assert len(data["rows"]) == sum(len(r.modes) for r in RUNS)
    assert f"| ddim | 50 | {PHYSDIFF_BASE} |" in out.with_name("study.md").read_text()


def test_the_model_and_evaluator_given_are_named(tmp_path: Path) -> None:
    from experiments.sampling_steps import evaluate_command

    run = RUNS[0]
    assert "--model" not in evaluate_command(run, "data_build/mocap", tmp_path)
    given = evaluate_command(run, "data_build/mocap", tmp_path, "runs/old", "runs/old_evaluator")
    assert given.startswith("physmotion evaluate --data data_build/mocap --model runs/old "
                            "--evaluator runs/old_evaluator ")
    _tables(tmp_path, {r.name: 0.13 for r in RUNS})
    out = tmp_path / "study"
    argv = ["--allow-dirty", "--tables", str(tmp_path), "--skip-timing", "--out", str(out),
            "--model", "runs/old", "--evaluator", "runs/old_evaluator"]  # fmt: skip
    assert main(argv) == 0
    meta = json.loads(out.with_name("study.json").read_text())["meta"]
    assert (meta["model"], meta["evaluator"]) == ("runs/old", "runs/old_evaluator")
    assert "--model runs/old" in meta["evaluate_commands"][BASELINE]
    assert "model runs/old, evaluator runs/old_evaluator" in out.with_name("study.md").read_text()


def test_a_table_of_another_run_is_refused(tmp_path: Path) -> None:
    from experiments.sampling_steps import eval_tables

    _tables(tmp_path, {r.name: 0.13 for r in RUNS})
    (tmp_path / "dpmpp10.json").write_text((tmp_path / f"{BASELINE}.json").read_text())
    with pytest.raises(PhysmotionError, match="not the run dpmpp10"):
        eval_tables(RUNS, "data_build/mocap", tmp_path)
