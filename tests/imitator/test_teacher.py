"""Teacher data: the search over segments of real captured motion, plain and pushed starts, resumable."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import ClipSource
from physmotion.imitator.student import carry
from physmotion.imitator.teacher import TeacherConfig, build_teacher_set, load_teacher_set, teacher_jobs
from physmotion.physics.policy import NUM_ACTIONS, OBS_DIM
from physmotion.physics.projection import prepare_motion
from physmotion.physics.search import no_hand
from physmotion.physics.tracking import ModelBasedTracker, prepare_reference


def test_jobs_cover_the_clip_in_a_seeded_order(run_clip: ClipSource) -> None:
    config = TeacherConfig(segment_seconds=1.0, min_seconds=0.5, perturbed=2, seed=5)
    jobs = teacher_jobs([run_clip], config)
    starts = sorted({j.start for j in jobs})
    seg = 20
    kept = [s for s in range(0, len(run_clip.joints), seg) if len(run_clip.joints) - s >= 0.5 * 20]
    assert starts == kept  # every segment, a short tail dropped
    assert len(jobs) == 3 * len(kept)  # one plain and two pushed starts each
    assert all(len(j.joints) <= seg for j in jobs)
    pushes = np.stack([j.push for j in jobs if j.push.any()])
    assert np.all(pushes[:, 2] == 0.0)  # the push is horizontal (MuJoCo z is up)
    assert len({j.id for j in jobs}) == len(jobs)
    again = teacher_jobs([run_clip], config)
    assert [j.id for j in again] == [j.id for j in jobs]  # the same seed, the same order
    other = teacher_jobs([run_clip], TeacherConfig(segment_seconds=1.0, min_seconds=0.5, perturbed=2, seed=6))
    assert [j.id for j in other] != [j.id for j in jobs]


def test_records_hold_what_a_student_needs(teacher_set, run_clip: ClipSource) -> None:
    folder, index, _ = teacher_set
    records = load_teacher_set(folder)
    assert index["written"] == len(records) == 2
    for r in records:
        n = len(r["offsets"])
        assert n == int(np.floor((len(r["joints"]) - 1) / 20.0 * 30.0 + 1e-9)) + 1  # per control step, 30 Hz
        assert r["observations"].shape == (n, OBS_DIM) and r["offsets"].shape == (n, NUM_ACTIONS)
        assert r["qpos"].shape == r["ref_qpos"].shape == (n, 70) and r["ref_joints"].shape == (n, 22, 3)
        assert str(r["licence_tag"]) == run_clip.licence_tag != ""  # the source's tag travels
        assert float(r["cpu_seconds"]) > 0 and int(r["rollouts"]) > 0
    pushed = next(r for r in records if r["push"].any())
    plain = next(r for r in records if not r["push"].any())
    # A pushed start is the plain start's state with the push added to the root's velocity.
    np.testing.assert_allclose(pushed["qvel"][0, :6] - plain["qvel"][0, :6], pushed["push"], atol=1e-12)
    assert index["licence_tags"] == [run_clip.licence_tag]
    assert json.loads((folder / "index.json").read_text())["written"] == 2


def test_the_committed_offsets_replay_the_searched_trajectory(teacher_set) -> None:
    # What a student imitates is exact: the tracker's nominal control plus the recorded offsets, closed loop
    # in the ordinary simulation, reproduces the searched states (the search ran them in mujoco.rollout).
    folder, _, config = teacher_set
    for r in load_teacher_set(folder):
        pconf = config.projection()
        prep = prepare_motion(r["joints"].astype(np.float64), float(r["fps"]), pconf)
        ref = prepare_reference(prep.model, prep.target, pconf.humanoid.control_dt, pconf.tracking)
        np.testing.assert_array_equal(ref.qpos, r["ref_qpos"])
        replay = _Replay(ModelBasedTracker(prep.model, no_hand(pconf.tracking)), r["offsets"].astype(np.float64))
        c = carry(prep.model, ref, replay, pconf.humanoid, push=r["push"])
        end = c.survived if int(r["failed_at"]) < 0 else min(c.survived, int(r["failed_at"]))
        assert end > 10
        qpos = c.states[: end + 1, 1 : 1 + prep.model.nq]  # full-physics state: time, then qpos
        # Within 0.1 mm / 0.1 mrad: the offsets are stored as float32, and contacts amplify the rounding
        # (1e-6 after 24 steps); an offset one step off moves the joints by centimetres.
        np.testing.assert_allclose(qpos, r["qpos"][: end + 1], atol=1e-4)


def test_a_rerun_skips_what_is_written(teacher_set) -> None:
    folder, index, config = teacher_set
    stamps = {p.name: os.stat(p).st_mtime_ns for p in Path(folder).glob("*.npz")}
    jobs = [j for j in teacher_jobs(_clips_of(folder), config) if j.start == 0]
    again = build_teacher_set(jobs, folder, config, workers=1, progress=False)
    assert {p.name: os.stat(p).st_mtime_ns for p in Path(folder).glob("*.npz")} == stamps
    assert again["items"] == index["items"]


def _clips_of(folder: Path) -> list[ClipSource]:
    """The run as the fixture gave it (its segment 0 is stored whole in each record)."""
    r = load_teacher_set(folder)[0]
    return [ClipSource(str(r["source"]), r["joints"], float(r["fps"]), str(r["licence_tag"]), str(r["origin"]))]


class _Replay:
    """The tracker with the recorded offset of each control step added to its PD targets."""

    def __init__(self, tracker: ModelBasedTracker, offsets: np.ndarray) -> None:
        self.tracker, self.offsets = tracker, offsets

    def act(self, data, ref, k):
        ctrl, qfrc = self.tracker.act(data, ref, k)
        return ctrl + self.offsets[k], qfrc

    def residual(self, data, ref, step, substeps):
        return self.tracker.residual(data, ref, step, substeps)

    def caps(self):
        return self.tracker.caps()


@pytest.mark.slow
def test_ray_runs_one_task_per_job_and_matches_local_processes(small_built_dir: Path, tmp_path: Path) -> None:
    pytest.importorskip("ray", reason="Ray is the optional extra physmotion[ray]; make install has it")
    import subprocess
    import sys

    # In its own process, as a user runs it (a Ray driver's start and shutdown stay out of the test process).
    command = [sys.executable, "-m", "physmotion.cli", "train", "teacher", "--data", str(small_built_dir), "-o",
               str(tmp_path / "ray"), "--jobs", "2", "--effort", "fast", "--perturbed", "0", "--ray", "local"]
    res = subprocess.run(command, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr
    assert "2 of 2 searches" in res.stdout
    local_command = [*command[:-2], "--workers", "1"]
    local_command[local_command.index(str(tmp_path / "ray"))] = str(tmp_path / "local")
    local = subprocess.run(local_command, capture_output=True, text=True, timeout=600)
    assert local.returncode == 0, local.stderr
    names = sorted(p.name for p in (tmp_path / "ray").glob("*.npz"))
    assert len(names) == 2 and names == sorted(p.name for p in (tmp_path / "local").glob("*.npz"))
    for name in names:  # the same search, whichever worker ran it
        a, b = np.load(tmp_path / "ray" / name), np.load(tmp_path / "local" / name)
        np.testing.assert_array_equal(a["offsets"], b["offsets"])
        np.testing.assert_array_equal(a["qpos"], b["qpos"])
