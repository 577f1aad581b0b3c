"""A dataset built once per test session from the real mocap, shared by the data tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from physmotion.data.build import BuildConfig, BuildReport, build_dataset


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path) -> BuildReport:
    """The whole mocap collection built with the default options."""
    out = tmp_path_factory.mktemp("build") / "mocap"
    return build_dataset(mocap_dir, out, BuildConfig(), progress=False)


@pytest.fixture(scope="session")
def built_dir(built: BuildReport) -> Path:
    return built.out
