"""What made a result: the code (version, and the commit where it runs from a git checkout), the machine and
the date, so that a table written by ``physmotion evaluate`` (or an experiment) can be traced and its
figures compared only with figures of the same code and CPU."""

from __future__ import annotations

import os
import platform
import subprocess
from dataclasses import dataclass
from datetime import datetime, timezone
from pathlib import Path

_PACKAGE_ROOT = Path(__file__).resolve().parents[1]  # the checkout, where the package runs from one


@dataclass(frozen=True)
class Checkout:
    """The git checkout code ran from: HEAD's short hash ("+dirty" appended where tracked files differed
    from it) and whether they did; ``commit`` None where the code is not in a git checkout (an installed
    wheel), and ``dirty`` True then, since nothing says it is clean."""

    commit: str | None
    dirty: bool


def checkout(root: str | Path | None = None) -> Checkout:
    """The state of the git checkout whose root is ``root`` (default: the folder this package runs from).
    Tracked files only (``git diff --quiet HEAD``, index and work tree): an untracked file does not count.
    A folder that is not a checkout's root (a wheel installed into a venv inside some repository) has no
    commit: that repository's would not be the package's."""

    def git(*args: str) -> subprocess.CompletedProcess | None:
        try:
            return subprocess.run(["git", *args], cwd=root or _PACKAGE_ROOT, capture_output=True, text=True,
                                  check=False, timeout=30)  # fmt: skip
        except (OSError, subprocess.TimeoutExpired):  # no git installed, or a hung filesystem
            return None

    where = Path(root or _PACKAGE_ROOT).resolve()
    top = git("rev-parse", "--show-toplevel")
    if top is None or top.returncode or Path(top.stdout.strip()).resolve() != where:
        return Checkout(None, True)  # not a checkout's root: e.g. a wheel in a venv inside some repository
    head = git("rev-parse", "--short", "HEAD")
    if head is None or head.returncode:  # a repository with no commit yet
        return Checkout(None, True)
    diff = git("diff", "--quiet", "HEAD")
    dirty = diff is None or diff.returncode != 0  # 1: differences; anything else: cannot tell
    return Checkout(head.stdout.strip() + ("+dirty" if dirty else ""), dirty)


def cpu_model() -> str:
    """The CPU's model name (``/proc/cpuinfo``), else what :func:`platform.processor` says."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown CPU"


def provenance() -> dict:
    """The ``made`` record of a result: physmotion's version, the commit (None outside a git checkout) and
    whether the tree was dirty, the CPU and its core count, the date (UTC, ISO 8601), and the versions of
    Python, torch and MuJoCo that computed it."""
    from physmotion import __version__

    code = checkout()
    return {"physmotion": __version__, "commit": code.commit, "dirty": code.dirty, "cpu": cpu_model(),
            "cores": os.cpu_count(), "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
            "python": platform.python_version(), "torch": _version("torch"),
            "mujoco": _version("mujoco")}  # fmt: skip


def _version(package: str) -> str | None:
    """An installed package's version, None where it is not installed."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version(package)
    except PackageNotFoundError:
        return None
