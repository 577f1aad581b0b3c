"""The data experiments on the small collection: where imported motion meets the floor
(experiments/import_floor.py) and the metrics in the data convention (experiments/data_convention.py)."""

import json
from pathlib import Path

import pytest


def test_import_floor_writes_each_source(small_mocap_dir: Path, tmp_path: Path) -> None:
    from experiments.import_floor import main

    out = tmp_path / "floor"
    main(["--allow-dirty", "--source", str(small_mocap_dir), "--round-trip-every", "8", "--out", str(out)])
    data = json.loads(out.with_suffix(".json").read_text())
    assert data["meta"]["preset"] is None and data["meta"]["round_trip_every"] == 8
    assert sum(s["clips"] for s in data["sources"].values()) == 23
    assert all(s["round_trip_max_mm"] < 1.0 for s in data["sources"].values())
    # the small collection stands on level ground (CMU's uneven-terrain walks are not in it)
    for s in data["sources"].values():
        assert s["not_level"] == 0 and s["penetrate_level_mean"] == pytest.approx(s["penetrate_mean"])
    assert "| source | clips |" in out.with_suffix(".md").read_text()


@pytest.mark.slow  # every motion of both splits of the small build measured twice (15 s)
def test_data_convention_measures_both_splits(small_built_dir: Path, tmp_path: Path) -> None:
    from experiments.data_convention import main

    out = tmp_path / "convention"
    main(["--allow-dirty", "--data", str(small_built_dir), "--out", str(out)])
    sets = json.loads(out.with_suffix(".json").read_text())["sets"]
    assert list(sets) == ["captured, test split", "captured, train split"]
    for row in sets.values():
        assert row["n"] > 0 and row["phys_err_grounded"] < row["phys_err"]  # grounding helps captured motion
