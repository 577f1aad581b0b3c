"""Morph's synthetic data run on the shipped model and the real built dataset: layout, features,
determinism, resume, and a folder from another model refused."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.features.humanml3d import extract_features
from physmotion.morph.preprocess import correct_tilt, tilt_angle
from physmotion.morph.selection import HELP_FIELDS, INDEX_FIELDS, select
from physmotion.morph.synth import SUBDIRS, SynthConfig, caption_subset, split_lengths, synthesize, train_captions

CAPTIONS = ["a person walks forward", "a person jumps", "a person sits on a chair", "a person waves"]


@pytest.fixture(scope="module")
def model():
    from physmotion.diffusion.model import MotionDiffusion

    return MotionDiffusion.load(None)


def config() -> SynthConfig:
    return SynthConfig(sampler=SamplerConfig(steps=5), batch_size=2, max_frames=40, workers=2)


def run(model, built_dir: Path, out: Path, **kw):
    return synthesize(None, built_dir, out, config(), captions=kw.pop("captions", CAPTIONS), model=model, **kw)


@pytest.fixture(scope="module")
def full(model, built_dir: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("synth") / "full"
    report = run(model, built_dir, out)
    assert (report.planned, report.done, report.total_done) == (4, 4, 4)
    assert report.sampling_seconds > 0 and report.physics_seconds > 0
    return out


def index_rows(folder: Path) -> list[dict]:
    with open(folder / "index.csv", newline="") as f:
        return list(csv.DictReader(f))


def test_layout(full: Path) -> None:
    info = json.loads((full / "synth.json").read_text())
    for key in ("model", "model_sha256", "feature_dim", "skeleton", "fps", "data", "split", "per_caption",
                "seed", "tau", "licence_tags", "preprocess", "projection", "items_planned"):  # fmt: skip
        assert key in info
    assert (info["feature_dim"], info["skeleton"], info["fps"], info["tau"]) == (263, "smpl22", 20, 0.5)
    assert info["projection"]["reset_on_fail"] is False and info["items_planned"] == 4
    rows = index_rows(full)
    assert list(rows[0]) == [*INDEX_FIELDS, *HELP_FIELDS]
    assert [r["id"] for r in rows] == ["s000000", "s000001", "s000002", "s000003"]
    assert [r["caption"] for r in rows] == CAPTIONS
    assert [r["grounded"] for r in rows] == ["1", "1", "0", "1"]
    for r in rows:
        sid, frames = r["id"], int(r["frames"])
        sim, inp = (np.load(full / d / f"{sid}.npy") for d in ("new_joints", "input_joints"))
        # the planned length (40: the data's shortest, the config's cap) is the features' rows, which
        # fine-tuning's 40-frame minimum keeps; the joints have one frame more
        assert frames == 40 and sim.shape == inp.shape == (frames + 1, 22, 3)
        assert sim.dtype == inp.dtype == np.float32
        for joints, vecs in ((sim, "new_joint_vecs"), (inp, "input_joint_vecs")):
            feats = np.load(full / vecs / f"{sid}.npy")
            assert feats.shape == (frames, 263) and feats.dtype == np.float32
            np.testing.assert_allclose(feats, extract_features(joints)[0], atol=1e-5)
        assert (full / "texts" / f"{sid}.txt").read_text() == f"{r['caption']}##0.0#0.0\n"
        assert 0 <= float(r["mpjpe_mean"]) <= float(r["mpjpe_max"])
        # P's help: the plain preset's residual, under its 0.2 W cap, and shares of frames
        assert 0 < float(r["residual_force"]) <= 0.2 + 1e-6
        assert 0 <= float(r["residual_at_cap"]) <= 1 and 0 <= float(r["over_limit"]) <= 1
    sel = select(full)
    assert sel.counts["items"] == 4 and sel.counts["non_grounded"] == 1
    assert set(sel.help) == (set(HELP_FIELDS) if sel.counts["refined"] else set())


def test_same_seed_same_files(model, built_dir: Path, full: Path, tmp_path: Path) -> None:
    # batch size 4 and one worker against the fixture's 2 and 2: an item's noise does not depend on its batch
    out = tmp_path / "again"
    synthesize(None, built_dir, out, SynthConfig(sampler=SamplerConfig(steps=5), batch_size=4, max_frames=40,
                                                 workers=1), captions=CAPTIONS, model=model)  # fmt: skip
    assert_same(full, out, atol=1e-4)


def assert_same(a: Path, b: Path, atol: float = 0.0) -> None:
    ra, rb = index_rows(a), index_rows(b)
    assert [r["id"] for r in ra] == [r["id"] for r in rb]
    for r in ra:
        for sub in SUBDIRS[:4]:
            np.testing.assert_allclose(np.load(a / sub / f"{r['id']}.npy"), np.load(b / sub / f"{r['id']}.npy"),
                                       atol=atol)  # fmt: skip


def test_interrupted_run_resumes_without_duplicates(model, built_dir: Path, full: Path, tmp_path: Path) -> None:
    out = tmp_path / "resumed"
    first = run(model, built_dir, out, limit=2)
    assert (first.done, first.total_done) == (2, 2)
    second = run(model, built_dir, out)
    assert (second.done, second.skipped, second.total_done) == (2, 2, 4)
    ids = [r["id"] for r in index_rows(out)]
    assert ids == sorted(set(ids)) and len(ids) == 4
    assert_same(full, out)
    again = run(model, built_dir, out)  # finished: nothing to do
    assert again.done == 0 and len(index_rows(out)) == 4


def test_folder_of_another_model_is_refused(model, built_dir: Path, full: Path, tmp_path: Path) -> None:
    out = tmp_path / "other"
    shutil.copytree(full, out)
    info = json.loads((out / "synth.json").read_text())
    info["model_sha256"] = "0" * 64
    (out / "synth.json").write_text(json.dumps(info))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    with pytest.raises(PhysmotionError, match="made by another model") as err:
        run(model, built_dir, out)
    assert "\n" not in str(err.value)
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_other_settings_are_refused(model, built_dir: Path, full: Path, tmp_path: Path) -> None:
    out = tmp_path / "settings"
    shutil.copytree(full, out)
    with pytest.raises(PhysmotionError, match="other settings"):
        synthesize(None, built_dir, out, SynthConfig(sampler=SamplerConfig(steps=5), batch_size=2, max_frames=40,
                                                     seed=1), captions=CAPTIONS, model=model)  # fmt: skip
    # P with iterative learning control refines otherwise: a folder made with plain P is not continued.
    with pytest.raises(PhysmotionError, match=r"settings \(projection\.ilc_passes: 0 there, 2 now\)"):
        synthesize(None, built_dir, out, SynthConfig(sampler=SamplerConfig(steps=5), batch_size=2, max_frames=40,
                                                     ilc_passes=2), captions=CAPTIONS, model=model)  # fmt: skip
    assert SynthConfig(ilc_passes=2).projection().ilc_passes == 2


def test_a_folder_older_than_a_setting_resumes(model, built_dir: Path, full: Path, tmp_path: Path) -> None:
    """A P setting added later, at its default (which keeps what P did before), does not orphan a folder
    whose synth.json predates it; the same setting at another value does."""
    out = tmp_path / "older"
    shutil.copytree(full, out)
    info = json.loads((out / "synth.json").read_text())
    del info["projection"]["shaping"]["hover_support"]
    (out / "synth.json").write_text(json.dumps(info))
    again = run(model, built_dir, out)
    assert again.done == 0 and len(index_rows(out)) == len(index_rows(full))
    info["projection"]["shaping"]["hover_support"] = 0.05
    (out / "synth.json").write_text(json.dumps(info))
    with pytest.raises(PhysmotionError, match=r"projection\.shaping\.hover_support: 0\.05 there, 0\.0 now"):
        run(model, built_dir, out)
    # the arm fit came in off and became the default later: a folder from before it was made without it
    info["projection"]["shaping"]["hover_support"] = 0.0
    del info["projection"]["reach_arms"]
    (out / "synth.json").write_text(json.dumps(info))
    with pytest.raises(PhysmotionError, match=r"projection\.reach_arms: False there, True now"):
        run(model, built_dir, out)
    info["projection"]["reach_arms"] = True
    # a folder from before planned lengths counted feature rows holds items one row short: not continued
    del info["projection"]["shaping"]["hover_support"], info["lengths"]
    (out / "synth.json").write_text(json.dumps(info))
    with pytest.raises(PhysmotionError, match=r"lengths: None there, features now"):
        run(model, built_dir, out)


def test_a_caption_subset_is_seeded_and_part_of_the_folder(model, built_dir: Path, tmp_path: Path) -> None:
    every = train_captions(built_dir)
    picked = caption_subset(every, 3, seed=0)
    assert picked == caption_subset(every, 3, seed=0) != caption_subset(every, 3, seed=1)
    assert picked != every[:3] and len(set(picked)) == 3 and set(picked) <= set(every)
    assert [every.index(c) for c in picked] == sorted(every.index(c) for c in picked)  # the split's order
    assert caption_subset(every[:2], 3, seed=0) == every[:2]
    out = tmp_path / "subset"
    cfg = SynthConfig(sampler=SamplerConfig(steps=5), batch_size=3, max_frames=40, workers=1, captions=3)
    report = synthesize(None, built_dir, out, cfg, model=model)
    assert (report.planned, report.done) == (3, 3)
    assert [r["caption"] for r in index_rows(out)] == picked
    assert json.loads((out / "synth.json").read_text())["captions"] == 3
    with pytest.raises(PhysmotionError, match=r"captions: 3 there, 4 now"):
        synthesize(None, built_dir, out, SynthConfig(sampler=SamplerConfig(steps=5), max_frames=40, captions=4),
                   model=model)  # fmt: skip
    with pytest.raises(PhysmotionError, match="--captions must be at least 1"):
        SynthConfig(captions=0)


def test_lengths_are_drawn_from_the_motions_the_model_trained_on(model, built_dir: Path) -> None:
    # The shipped model's run kept every motion (--max-length 196); a run with --max-length 120 (the model
    # before) keeps those under 124 frames, and the split holds longer ones.
    limit = model.trained_max_length
    assert limit == model.info["train"]["max_length"] == 196
    every = split_lengths(built_dir)
    assert np.array_equal(split_lengths(built_dir, max_length=limit), every)
    kept = split_lengths(built_dir, max_length=120)
    assert kept.max() < 124 <= every.max() and len(kept) == int((every < 124).sum()) > 0


def test_tilt_correction() -> None:
    from physmotion.skeleton import rest_joints

    stand = np.repeat(rest_joints()[None], 5, axis=0)
    stand[:, :, 0] += np.linspace(0, 1, 5)[:, None]  # a path along x
    assert tilt_angle(stand) < 10
    theta = np.radians(20)
    rot = np.array([[1, 0, 0], [0, np.cos(theta), -np.sin(theta)], [0, np.sin(theta), np.cos(theta)]])
    leaning = stand @ rot.T
    assert tilt_angle(leaning) == pytest.approx(tilt_angle(stand) + 20, abs=3)
    fixed, angle = correct_tilt(leaning)
    assert angle > 10 and tilt_angle(fixed) < 1e-6
    np.testing.assert_allclose(fixed[:, 0], leaning[:, 0])  # the root's path is kept
    same, _ = correct_tilt(stand)
    np.testing.assert_array_equal(same, stand)  # under 10 degrees: untouched


def test_synth_with_the_search_keeps_teacher_records(model, built_dir: Path, tmp_path: Path) -> None:
    """Morph's data refined by the search controller: no outside help, and each item's teacher records."""
    from physmotion.physics.search import effort

    cfg = SynthConfig(sampler=SamplerConfig(steps=5), batch_size=1, max_frames=30, workers=1, controller="search")
    assert cfg.projection().humanoid.cone == "elliptic" and cfg.projection().search == effort("default")
    synthesize(None, built_dir, tmp_path / "s", cfg, captions=["a person jumps"], model=model)
    row = index_rows(tmp_path / "s")[0]
    assert float(row["residual_force"]) == 0.0 and float(row["over_limit"]) == 0.0
    records = np.load(tmp_path / "s" / "teacher" / f"{row['id']}.npz")
    assert records["observations"].shape[1] == 599 and records["offsets"].shape[1] == 63
    assert str(records["text"]) == "a person jumps" and str(records["licence_tag"]) == row["licence_tag"]


@pytest.mark.slow
def test_ray_refines_what_local_processes_do(built_dir: Path, tmp_path: Path) -> None:
    """``morph synth --ray local``: one Ray task per motion, in one Ray session for the run, the same files."""
    pytest.importorskip("ray", reason="Ray is the optional extra physmotion[ray]; make install has it")
    import subprocess
    import sys

    def synth(out: Path, *how: str) -> None:
        # in its own process, as a user runs it (a Ray driver's start and shutdown stay out of the test process)
        command = [sys.executable, "-m", "physmotion.cli", "morph", "synth", "--data", str(built_dir), "-o", str(out),
                   "--captions", "3", *how]  # fmt: skip
        res = subprocess.run(command, capture_output=True, text=True, timeout=600)
        assert res.returncode == 0, res.stderr
        assert "3 new item(s), 3/3 done" in res.stdout

    synth(tmp_path / "ray", "--ray", "local")
    synth(tmp_path / "local", "--workers", "2")
    assert index_rows(tmp_path / "ray") == index_rows(tmp_path / "local")
    for row in index_rows(tmp_path / "ray"):
        for sub in ("new_joints", "input_joints"):
            a = np.load(tmp_path / "ray" / sub / f"{row['id']}.npy")
            np.testing.assert_array_equal(a, np.load(tmp_path / "local" / sub / f"{row['id']}.npy"))
