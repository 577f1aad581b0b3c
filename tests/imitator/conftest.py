"""A teacher record (``imitator/teacher.py``) made from a real captured walk, shared by the imitator tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import dataset_clips
from physmotion.imitator.teacher import TeacherConfig, TeacherJob, search_job
from physmotion.physics.search import SearchConfig
from tests.conftest import _shared_dir

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
