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
