"""Fixtures of the io tests: the parsed manifest and a clip lookup."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from physmotion.io import ClipInfo, load_manifest


@pytest.fixture(scope="session")
def manifest(mocap_dir: Path) -> list[ClipInfo]:
    return load_manifest(mocap_dir)


@pytest.fixture(scope="session")
def clip(manifest: list[ClipInfo]) -> Callable[[str], ClipInfo]:
    """Look a manifest row up by clip id."""
    by_id = {c.clip: c for c in manifest}
    return by_id.__getitem__


@pytest.fixture(scope="session")
def hdm05_manifest(hdm05_dir: Path) -> list[ClipInfo]:
    return load_manifest(hdm05_dir)


@pytest.fixture(scope="session")
def hdm05_results(hdm05_manifest: list[ClipInfo]) -> dict[str, object]:
    """HDM05 clip id -> (Motion, ImportReport, Latin-1 warnings), or the one-line error; imported once."""
    import warnings

    from physmotion.errors import PhysmotionError
    from physmotion.io import import_clip_with_report
    from physmotion.io.bvh import Latin1Warning

    results: dict[str, object] = {}
    for info in hdm05_manifest:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                motion, report = import_clip_with_report(info)
            except PhysmotionError as exc:
                results[info.clip] = str(exc)
                continue
        results[info.clip] = (motion, report, [w for w in caught if issubclass(w.category, Latin1Warning)])
    return results
