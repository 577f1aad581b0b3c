"""Shared fixtures: the real mocap folder and every manifest clip imported once per session."""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from physmotion.data.build import BuildConfig, BuildReport, build_dataset

MOCAP_DIR = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "mocap"


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "slow: runs over the whole mocap manifest (seconds); still run in CI")


@pytest.fixture(scope="session")
def mocap_dir() -> Path:
    """``../shared/data/mocap`` next to the repository; a failure, not a skip, when it is missing."""
    if not (MOCAP_DIR / "manifest.csv").is_file():
        pytest.fail(f"the mocap data is missing: expected {MOCAP_DIR.resolve()}/manifest.csv")
    return MOCAP_DIR.resolve()


@pytest.fixture(scope="session")
def import_results(mocap_dir: Path) -> dict[str, object]:
    """clip id -> (Motion, ImportReport), or the one-line error message; imports the manifest once.

    The wall time of the whole import is stored under the key ``"__seconds__"``.
    """
    from physmotion.errors import PhysmotionError
    from physmotion.io import import_clip_with_report, load_manifest

    results: dict[str, object] = {}
    start = time.perf_counter()
    for info in load_manifest(mocap_dir):
        try:
            results[info.clip] = import_clip_with_report(info)
        except PhysmotionError as exc:
            results[info.clip] = str(exc)
    results["__seconds__"] = time.perf_counter() - start
    return results


@pytest.fixture(scope="session")
def imported_clips(import_results: dict[str, object]) -> dict[str, object]:
    """clip id -> Motion, or the one-line error message for clips that failed to import."""
    return {
        k: v[0] if isinstance(v, tuple) else v for k, v in import_results.items() if not k.startswith("__")
    }


@pytest.fixture(scope="session")
def built(tmp_path_factory: pytest.TempPathFactory, mocap_dir: Path) -> BuildReport:
    """The whole mocap collection built with the default options (about 12 s)."""
    out = tmp_path_factory.mktemp("build") / "mocap"
    return build_dataset(mocap_dir, out, BuildConfig(), progress=False)


@pytest.fixture(scope="session")
def built_dir(built: BuildReport) -> Path:
    return built.out
