"""The old-against-new table reads both models' evaluate tables, holds the new model against the old one's
intervals and writes its table with the meta block (no model run: tables made up here)."""

import json
from pathlib import Path

import pytest

from experiments.retrained_default import LABELS, MODES, main, rows
from physmotion.errors import PhysmotionError

DATA = "data_build/all"


def _figure(mean: float, ci: float = 0.0) -> dict:
    return {"mean": mean, "ci95": ci}


def _tables(folder: Path, fid: dict[str, float], r3: dict[str, float]) -> None:
    """One evaluate table per model label: every mode's FID and R@3 from ``fid`` and ``r3`` by label."""
    for label in LABELS:
        meta = {"split": "test", "repeats": 3, "seed": 0, "motions": 116, "modes": list(MODES), "data": DATA,
                "model_trained_on": f"data_build/{label}", "model_steps": 10, "model_licence": "NC",
                "sampler": {"sampler": "dpmpp", "steps": 10, "eta": 0.0, "cfg_scale": 2.5}}  # fmt: skip
        figures = {
            "FID": _figure(fid[label], 0.01),
            "R@3": _figure(r3[label], 0.02),
            "phys_err": _figure(7.0, 0.3),
        }
        table = {"real": {"FID": _figure(0.001), "R@3": _figure(0.8, 0.03)}} | {m: figures for m in MODES}
        (folder / f"{label}.json").write_text(json.dumps({"meta": meta, "rows": table}))


def test_new_rows_are_held_against_the_old_intervals(tmp_path: Path) -> None:
    _tables(tmp_path, {"old": 0.20, "new": 0.205}, {"old": 0.80, "new": 0.77})
    found = {label: json.loads((tmp_path / f"{label}.json").read_text()) for label in LABELS}
    table = rows(found)
    assert table[0]["model"] == "real"
    new = [r for r in table if r["model"] == "new"]
    assert len(new) == len(MODES)
    assert all(r["FID_within"] for r in new)  # 0.205 <= 0.20 + 0.01
    assert not any(r["R@3_within"] for r in new)  # 0.77 < 0.80 - 0.02
    assert all("FID_within" not in r for r in table if r["model"] == "old")


def test_main_writes_the_table_and_its_acceptance(tmp_path: Path) -> None:
    _tables(tmp_path, {"old": 0.20, "new": 0.15}, {"old": 0.80, "new": 0.85})
    out = tmp_path / "cmp"
    argv = [
        "--data",
        DATA,
        "--old",
        "o",
        "--new",
        "n",
        "--evaluator",
        "e",
        "--tables",
        str(tmp_path),
        "--out",
        str(out),
        "--allow-dirty",
    ]
    assert main(argv) == 0
    data = json.loads(out.with_name("cmp.json").read_text())
    assert {"preset", "commit", "cpu", "date", "command"} <= set(data["meta"])
    assert data["acceptance"] == {"FID_within": True, "R@3_within": True}
    assert "| new | none | 0.150 ± 0.010 |" in out.with_name("cmp.md").read_text()


def test_a_table_of_another_computation_is_refused(tmp_path: Path) -> None:
    from experiments.retrained_default import tables

    _tables(tmp_path, {"old": 0.2, "new": 0.2}, {"old": 0.8, "new": 0.8})
    with pytest.raises(PhysmotionError, match="not this experiment's run"):
        tables({"old": "o", "new": "n"}, "e", "data_build/mocap", tmp_path)


def test_a_mode_only_one_table_has_gets_only_that_row(tmp_path: Path) -> None:
    _tables(tmp_path, {"old": 0.2, "new": 0.2}, {"old": 0.8, "new": 0.8})
    found = {label: json.loads((tmp_path / f"{label}.json").read_text()) for label in LABELS}
    found["new"]["rows"]["morph"] = found["new"]["rows"]["none"]  # the Morph-tuned model's own mode
    table = rows(found, ("none", "morph"))
    assert [(r["model"], r["physics"]) for r in table] == [("real", "-"), ("old", "none"), ("new", "none"),
                                                           ("new", "morph")]  # fmt: skip
    assert "FID_within" not in table[-1]  # nothing of the old model's to hold it against
