"""Morph's multi-round loop with a stand-in synthesis (real built items in the SYNTH/ layout)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from physmotion.checkpoint import weights_sha256
from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.morph.finetune import FinetuneConfig
from physmotion.morph.loop import run_rounds
from tests.morph.fake_synth import make_synth


def test_rounds_chain_weights_and_resume_by_round(tiny_model_dir: Path, built_dir: Path, tmp_path: Path) -> None:
    calls: list[Path] = []

    def fake_synthesize(model_dir, data_dir, out_dir, config, progress):
        calls.append(Path(model_dir))
        make_synth(Path(data_dir), Path(model_dir), Path(out_dir), n=4, failed=1)

    ft = FinetuneConfig(model="", synth="", data="", out="", steps=2, checkpoint_minutes=60.0)
    out = tmp_path / "run"
    rows = run_rounds(tiny_model_dir, built_dir, out, 2, None, ft, progress=False, synthesize_fn=fake_synthesize)
    assert [r.round for r in rows] == [1, 2] and calls == [tiny_model_dir, out / "round_1" / "model"]
    assert rows[0].synthetic_items == 4 and rows[0].refined == 3 and rows[0].inputs == 1 and rows[0].ifr == 0.25
    assert rows[1].finetune_steps == 2
    # Round 2's synthetic set was made by round 1's weights, and its model counts two rounds.
    info = json.loads((out / "round_2" / "synth" / "synth.json").read_text())
    assert info["model_sha256"] == weights_sha256(out / "round_1" / "model")
    assert MotionDiffusion.load(out / "round_2" / "model").info["morph"]["rounds"] == 2
    table = json.loads((out / "rounds.json").read_text())
    assert [r["round"] for r in table["rounds"]] == [1, 2]
    assert "IFR" in (out / "rounds.md").read_text()
    # Finished rounds are skipped; a third round starts from round 2's weights. A note written by hand into
    # the record is kept and does not stop the run.
    table["rounds"][0]["note"] = "made by hand"
    (out / "rounds.json").write_text(json.dumps(table))
    calls.clear()
    rows = run_rounds(tiny_model_dir, built_dir, out, 3, None, ft, progress=False, synthesize_fn=fake_synthesize)
    assert calls == [out / "round_2" / "model"] and [r.round for r in rows] == [1, 2, 3]
    assert json.loads((out / "rounds.json").read_text())["rounds"][0]["note"] == "made by hand"
    # Another base model's run folder is refused.
    other = tmp_path / "other_model"
    other.mkdir()
    for f in ("config.json", "model.safetensors"):
        (other / f).write_bytes((out / "round_1" / "model" / f).read_bytes())
    with pytest.raises(PhysmotionError, match="another base model"):
        run_rounds(other, built_dir, out, 1, None, ft, progress=False, synthesize_fn=fake_synthesize)


def test_run_passes_the_controller_and_the_caption_subset_to_every_round(monkeypatch, tmp_path: Path) -> None:
    """``morph run --controller search --captions N``: each round's synthesis gets them (the rounds stand in)."""
    import physmotion.morph.loop as loop
    from tests.cli_runner import invoke

    seen = {}

    def fake_rounds(model, data, out, rounds, synth_cfg, ft_cfg, progress):
        seen.update(controller=synth_cfg.controller, captions=synth_cfg.captions, rounds=rounds)
        raise PhysmotionError("stopped here")

    monkeypatch.setattr(loop, "run_rounds", fake_rounds)
    common = ("morph", "run", "--model", "base", "--data", tmp_path, "--rounds", "1")
    res = invoke(*common, "-o", tmp_path / "run", "--controller", "search", "--captions", "7")
    assert seen == {"controller": "search", "captions": 7, "rounds": 1} and "stopped here" in res.stderr
    res = invoke(*common, "-o", tmp_path / "run2", "--controller", "walker")
    assert res.returncode == 1 and res.stderr.strip().splitlines() == [
        "error: --controller must be one of tracker, policy, search, got 'walker'"]
