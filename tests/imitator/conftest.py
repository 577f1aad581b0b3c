"""Teacher records shared by the imitator tests: real captured motion searched at a tiny effort (one more,
``teacher_dir``, is in tests/conftest.py: experiments use it too)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physmotion.imitator.clips import ClipSource
from physmotion.imitator.teacher import TeacherConfig, build_teacher_set, teacher_jobs
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
