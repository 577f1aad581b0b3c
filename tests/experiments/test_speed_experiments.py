"""The speed benchmarks and the imitator study run end to end on tiny inputs and write their tables with
the meta block (their timings are not checked)."""

import json
from pathlib import Path

import pytest


def _written(out: Path) -> dict:
    assert out.with_suffix(".md").read_text().startswith("# ")
    data = json.loads(out.with_suffix(".json").read_text())
    assert {"preset", "commit", "cpu", "date", "command"} <= set(data["meta"])
    return data


def test_physics_raw_speed(tmp_path: Path) -> None:
    from experiments.physics_raw_speed import main

    main(["--allow-dirty", "--seconds", "0.1", "--repeats", "1", "--out", str(tmp_path / "raw")])
    data = _written(tmp_path / "raw")
    assert data["meta"]["preset"] == "plain" and len(data["rows"]) == 5
    assert all(r["per_second"] > 0 for r in data["rows"])


@pytest.mark.slow  # P on a 1 s walk eleven times, and a worker pool started (20 s)
def test_physics_speed(mocap_dir: Path, tmp_path: Path) -> None:
    from experiments.physics_speed import main

    main(["--allow-dirty", "--mocap", str(mocap_dir), "--batch", "2", "--seconds", "1", "--preset", "fine",
          "--out", str(tmp_path / "p")])
    data = _written(tmp_path / "p")
    assert data["meta"]["preset"] == "fine" and data["figures"]["latency_s"] > 0


@pytest.mark.slow  # samples and projects two motions with the tiny model (half a minute)
def test_morph_synth_speed(small_built_dir: Path, tiny_model_dir: Path, tmp_path: Path) -> None:
    from experiments.morph_synth_speed import main

    main(["--allow-dirty", "--model", str(tiny_model_dir), "--data", str(small_built_dir), "--captions", "2",
          "--steps", "3",
          "--workers", "1", "--batch-size", "2", "--out", str(tmp_path / "m")])  # fmt: skip
    data = _written(tmp_path / "m")
    assert data["meta"]["preset"] == "plain" and data["figures"]["motions"] == 2


@pytest.mark.slow  # two captured clips under each of P's three controllers (half a minute)
def test_imitator_captured(small_mocap_dir: Path, tmp_path: Path) -> None:
    from experiments.imitator import CONTROLLERS, main

    main(["--allow-dirty", "captured", "--mocap", str(small_mocap_dir), "--limit", "2",
          "--out", str(tmp_path / "i")])
    data = _written(tmp_path / "i")
    assert data["meta"]["preset"] == "plain" and data["meta"]["policy"] == "shipped"
    assert {r["controller"] for r in data["rows"]} == set(CONTROLLERS)
