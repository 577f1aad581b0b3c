"""The length model (physmotion/text/length.py) and `generate` without --seconds, on real captures: every
jump-captioned clip of ../shared/data/mocap and hdm05, a walk the build cuts in two windows and a short
HDM05 squat it pads, built as `data build` builds them."""

from __future__ import annotations

import csv
import json
import re
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from physmotion.conventions import FPS
from physmotion.data.build import BuildConfig, build_dataset
from physmotion.errors import PhysmotionError
from physmotion.text.length import (
    HI_SECONDS,
    LENGTH_MODEL_DIR,
    LO_SECONDS,
    LengthPredictor,
    caption_groups,
    caption_split,
    captions_matching,
    length_examples,
    predict_seconds,
    train_length,
)

DATA = Path(__file__).resolve().parents[2] / ".." / "shared" / "data"
JUMP = r"\bjump"
WALK_TWO_WINDOWS = "bandai2_dataset-2_walk_elderly_001"  # 13.75 s: two windows of at most 9.8 s
SHORT_SQUAT = "hdm05_bd_squat1Reps_001"  # 1.15 s: held still at both ends to 2 s by the build


def _rows(source: Path, keep) -> tuple[list[str], list[dict[str, str]]]:
    with open(source / "manifest.csv", newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        rows = [r for r in reader if keep(r)]
    for r in rows:  # absolute paths: the manifest is written elsewhere, nothing is copied
        r["path"] = str(source / r["path"])
        if r["format"].lower() == "amc":
            r["skeleton"] = str(source / r["skeleton"])
    return list(reader.fieldnames or []), rows


@pytest.fixture(scope="module")
def length_build(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every clip of both collections whose captions say jump, plus the walk and the squat, built."""
    tmp = tmp_path_factory.mktemp("length")
    fields, rows = [], []
    for name in ("mocap", "hdm05"):
        if not (DATA / name / "manifest.csv").is_file():
            pytest.fail(f"the {name} data is missing: expected {(DATA / name).resolve()}/manifest.csv")
        fields, found = _rows(DATA / name, lambda r: re.search(JUMP, r["captions"], re.IGNORECASE) is not None
                              or r["clip"] in (WALK_TWO_WINDOWS, SHORT_SQUAT))  # fmt: skip
        rows += found
    assert {WALK_TWO_WINDOWS, SHORT_SQUAT} <= {r["clip"] for r in rows}
    (tmp / "src").mkdir()
    with open(tmp / "src" / "manifest.csv", "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=fields)
        w.writeheader()
        w.writerows(rows)
    build_dataset(tmp / "src", tmp / "build", BuildConfig(jobs=1), progress=False)
    return tmp / "build"


def test_the_shipped_model_puts_a_jump_within_the_jump_clips_lengths(length_build: Path) -> None:
    """Issue 50's acceptance: "a person jumps" gets a length within the range of the jump captions'
    lengths in the data, whole clips (capped to the model's range) or the build's windows alike."""
    jumps = captions_matching(length_examples(length_build), JUMP)
    assert len({e.clip for e in jumps}) >= 2, "the data has lost its jump clips"
    (seconds,) = predict_seconds(["a person jumps"])
    assert min(e.seconds for e in jumps) <= seconds <= max(e.seconds for e in jumps)
    windows = [w for e in jumps for w in e.window_seconds]
    assert min(windows) <= seconds <= max(windows)
    assert abs(seconds - 6.0) > 0.5  # not the old fixed default


def test_examples_are_whole_clips_capped_without_mirrors_or_padding(length_build: Path) -> None:
    examples = length_examples(length_build)
    by_clip = {e.clip: e for e in examples}
    assert not any(e.clip.startswith("M") for e in examples)
    walk = by_clip[WALK_TWO_WINDOWS]
    assert len(walk.window_seconds) == 2 and all(w <= HI_SECONDS for w in walk.window_seconds)
    assert walk.raw_seconds == pytest.approx(sum(walk.window_seconds), abs=0.11)  # windows share a frame
    assert walk.raw_seconds > HI_SECONDS and walk.seconds == HI_SECONDS
    squat = by_clip[SHORT_SQUAT]
    assert squat.raw_seconds < LO_SECONDS and squat.seconds == LO_SECONDS  # the held frames not counted
    assert len([e for e in examples if e.clip == SHORT_SQUAT]) == 2  # its two captions, once each


def test_training_is_deterministic_and_the_card_carries_every_licence(length_build: Path, tmp_path: Path) -> None:
    a, b = train_length(length_build, tmp_path / "a"), train_length(length_build, tmp_path / "b")
    ma, mb = LengthPredictor.load(tmp_path / "a"), LengthPredictor.load(tmp_path / "b")
    assert np.array_equal(ma.weights, mb.weights) and np.array_equal(ma.centre, mb.centre) and ma.bias == mb.bias
    assert json.dumps(asdict(a)) == json.dumps(asdict(b))  # NaN where the small build has no val or test
    card = json.loads((tmp_path / "a" / "card.json").read_text())
    assert card["licence_tags"] == ["NC", "SA"]  # Bandai's walk and HDM05's squat are in this build
    seconds = ma.predict(["a person jumps", "a person squats down and stands back up"])
    assert np.all((seconds >= LO_SECONDS) & (seconds <= HI_SECONDS))


def _sides(examples, splits: list[str], key) -> dict[str, set[str]]:
    return {s: {key(e) for e, t in zip(examples, splits) if t == s} for s in set(splits)}


def _assert_disjoint(examples, splits: list[str]) -> None:
    for key in (lambda e: e.text, lambda e: e.clip):
        sides = list(_sides(examples, splits, key).values())
        assert all(not (a & b) for i, a in enumerate(sides) for b in sides[i + 1:])


def test_the_caption_split_keeps_every_caption_and_clip_on_one_side(built_all_dir: Path) -> None:
    """On the whole of ../shared/data (mocap and HDM05, built as the shipped model's data): the build's own
    splits share captions between test and train (HDM05 gives a class one caption), the split by caption
    shares none and no clip, comes near the build's 80/10/10 and is the same for the same seed."""
    examples = length_examples(built_all_dir)
    build = [e.split for e in examples]
    captions = _sides(examples, build, lambda e: e.text)
    seen = captions["test"] & (captions["train"] | captions["val"])
    assert len(seen) > len(captions["test"]) / 2  # the reason for the split by caption
    splits = caption_split(examples, seed=0)
    _assert_disjoint(examples, splits)
    shares = {s: splits.count(s) / len(examples) for s in ("train", "val", "test")}
    assert shares == pytest.approx({"train": 0.8, "val": 0.1, "test": 0.1}, abs=0.05)
    assert caption_split(examples, seed=0) == splits and caption_split(examples, seed=1) != splits
    squats = {g for g, e in zip(caption_groups(examples), examples) if e.text == "squat"}
    assert len(squats) == 1  # one class's clips, all of them, in one group


def test_training_reports_the_caption_split(length_build: Path, tmp_path: Path) -> None:
    """train_length measures a split by caption too (on this small build of jumps, a walk and a squat):
    disjoint by caption and clip, and the card gives its figures."""
    examples = length_examples(length_build)
    _assert_disjoint(examples, caption_split(examples))
    report = train_length(length_build, tmp_path / "m")
    split = report.caption_split
    assert sum(split["examples"].values()) == len(examples) and split["examples"]["train"] > 0
    assert split["test_captions_seen"] <= split["examples"]["test"]
    assert "split by caption" in (tmp_path / "m" / "README.md").read_text()


def test_the_shipped_model_and_its_card() -> None:
    card = json.loads((LENGTH_MODEL_DIR / "card.json").read_text())
    assert card["licence_tags"] == ["NC", "SA"]
    report = card["report"]
    assert report["test_mae"] < min(report["test_mae_const6"], report["test_mae_mean"])
    assert (LENGTH_MODEL_DIR / "model.safetensors").stat().st_size < 10_000
    assert "NC" in (LENGTH_MODEL_DIR / "README.md").read_text()
    squat, walk = predict_seconds(["a person squats", "a person walks forward"])
    assert squat == pytest.approx(LO_SECONDS, abs=0.5)  # HDM05's squats are single 1-2 s repetitions
    assert 3.0 <= walk <= HI_SECONDS


def test_an_empty_caption_is_refused() -> None:
    with pytest.raises(PhysmotionError, match="empty"):
        predict_seconds(["  "])


def _cli(*args: object) -> subprocess.CompletedProcess:
    try:
        from tests.cli_runner import invoke
    except ImportError:  # the CLI in a fresh process
        return subprocess.run([sys.executable, "-m", "physmotion.cli", *map(str, args)], check=False,
                              capture_output=True, text=True, timeout=600)  # fmt: skip
    return invoke(*args)


CHEAP = ("--steps", "5", "--physics", "none", "--no-preview")


def test_generate_without_seconds_predicts_prints_and_records_the_length(tmp_path: Path) -> None:
    out = tmp_path / "g"
    res = _cli("generate", "a person jumps", "a person squats", *CHEAP, "-o", out)  # the shipped model
    assert res.returncode == 0, res.stderr
    (expected_jump, expected_squat) = predict_seconds(["a person jumps", "a person squats"])
    lines = [line for line in res.stdout.splitlines() if line.startswith("length:")]
    assert len(lines) == 2, res.stdout
    (run,) = json.loads((out / "generate.json").read_text())["runs"]
    assert run["settings"]["seconds"] is None
    for line, motion, expected in zip(lines, run["motions"], (expected_jump, expected_squat)):
        assert motion["length_source"] == "predicted"
        assert motion["seconds"] == pytest.approx(round(expected * FPS) / FPS)
        assert f"{motion['seconds']:.2f} s for '{motion['prompt']}' (predicted from the text" in line
        frames = np.load(out / motion["files"][0])["joints"].shape[0]
        assert frames == round(motion["seconds"] * FPS)


def test_an_explicit_seconds_wins(tmp_path: Path) -> None:
    out = tmp_path / "g"
    res = _cli("generate", "a person jumps", "--seconds", "2.5", *CHEAP, "-o", out)
    assert res.returncode == 0, res.stderr
    assert "length:" not in res.stdout
    (motion,) = json.loads((out / "generate.json").read_text())["runs"][0]["motions"]
    assert motion["seconds"] == 2.5 and motion["length_source"] == "given"


def test_generate_refuses_an_empty_prompt_in_one_line(tmp_path: Path) -> None:
    res = _cli("generate", " ", *CHEAP, "-o", tmp_path / "g")
    assert res.returncode != 0
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error:") and "empty" in lines[0], res.stderr
