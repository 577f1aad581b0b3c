"""Teacher records shared by the imitator tests: real captured motion searched at a tiny effort."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import ClipSource, dataset_clips
from physmotion.imitator.teacher import TeacherConfig, TeacherJob, build_teacher_set, search_job, teacher_jobs
from physmotion.io.importer import import_clip, load_manifest
from physmotion.physics.search import SearchConfig
from tests.conftest import _shared_dir

RUN = "bandai2_dataset-2_run_normal_001"  # a captured run, 3.3 s; the tracker with its hand off falls in it
TINY = SearchConfig(candidates=8, rounds=1, elites=2, horizon=6, retries=0, rollback=0, seed=1)


@pytest.fixture(scope="session")
def run_clip(mocap_dir: Path) -> ClipSource:
    """The run through the importer (20 fps), as a training clip with its licence tag."""
    info = {c.clip: c for c in load_manifest(mocap_dir)}[RUN]
    clip = import_clip(info, floor="frame0")
    return ClipSource(RUN, clip.joints.astype(np.float32), 20.0, info.licence_tag, "captured")


@pytest.fixture(scope="session")
def teacher_set(run_clip: ClipSource, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, dict, TeacherConfig]:
    """The run's first 1.5 s searched at a tiny effort, from a plain and a pushed start: (folder, index,
    config)."""
    config = TeacherConfig(search=TINY, segment_seconds=1.5, min_seconds=1.0, perturbed=1, seed=2)
    jobs = teacher_jobs([run_clip], config)
    jobs = [j for j in jobs if j.start == 0]
    out = tmp_path_factory.mktemp("teacher")
    index = build_teacher_set(jobs, out, config, workers=1, progress=False)
    return out, index, config


# The search at a tiny effort: enough to carry 1 s of a walk with no outside hand in a few seconds.
TINY_TEACHER = TeacherConfig(search=SearchConfig(candidates=4, rounds=1, elites=2, horizon=3))


@pytest.fixture(scope="session")
def teacher_dir(small_built_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A teacher folder holding one record: the first second of a captured walk, searched from a plain
    start."""

    def make(folder: Path) -> None:
        train = dataset_clips(small_built_dir, "train")
        src = next(c for c in train if "_walk_" in c.name and c.name[0] != "M")
        joints = src.joints[: int(src.fps)].astype(np.float64)
        job = TeacherJob(src.name, src.origin, src.licence_tag, 0, joints, src.fps, np.zeros(6))
        folder.mkdir(parents=True, exist_ok=True)
        np.savez_compressed(folder / f"{job.id}.npz", **search_job(job, TINY_TEACHER))

    return _shared_dir(tmp_path_factory, "teacher_walk", make)
