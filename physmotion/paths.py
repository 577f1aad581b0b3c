"""Output paths checked before any work: a command that will fail to write must fail in its first second.

Every command that writes calls :func:`check_output` on each path it will write, before it loads a
model or reads a dataset, so a wrong ``-o`` costs a one-line error rather than minutes of work.
"""

from __future__ import annotations

import errno
import os
import tempfile
from pathlib import Path
from typing import Literal

from physmotion.errors import PhysmotionError

OutputKind = Literal["file", "folder"]

# The shipped weights, one folder per model (base, morph, evaluator, imitator, length).
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
# The generator `generate` uses when no --model is given (``--model default`` names it too): the Morph-tuned
# one, fine-tuned from ``BASE_MODEL`` on physically refined motions (docs/decisions/morph.md: "the Morph-tuned
# model becomes the default").
DEFAULT_MODEL = "morph"
BASE_MODEL = "base"  # the generator trained on the captured data alone, that Morph fine-tunes


# The suffixes of the files physmotion writes: a new output *folder* named like one of them is a mistake
# (`generate -o walk.npz` would make a folder called walk.npz).
FILE_SUFFIXES: tuple[str, ...] = (".npz", ".bvh", ".glb", ".json", ".csv", ".gif", ".mp4", ".png", ".html")
# The motion formats a motion output may take, by suffix (physmotion.io.export.save_motion's).
MOTION_SUFFIXES: tuple[str, ...] = (".bvh", ".glb", ".npz")


class OutputPathError(PhysmotionError):
    """An output path that cannot or must not be written (wrong kind, not writable, would clobber)."""


def check_output(path: str | Path, kind: OutputKind = "file", overwrite: bool = False,
                 hint: str = "pass --overwrite to replace it", suffixes: tuple[str, ...] | None = None) -> Path:
    """Raise OutputPathError unless ``path`` can be written as a ``kind`` without clobbering anything.

    kind "file": ``path`` must not be a folder, nor (unless ``overwrite``) an existing file, and must end
    in one of ``suffixes`` (lower case, with the dot) where they are given.
    kind "folder": ``path`` must not be a file, nor (unless ``overwrite``) a non-empty folder, nor a new
    folder named like a file (a suffix of :data:`FILE_SUFFIXES`).
    Either way a file must be creatable in the nearest existing ancestor (missing folders are created
    later, by the write). ``hint`` ends the would-clobber message. Nothing is left behind; returns ``path``.
    """
    path = Path(path)
    if kind == "file":
        if path.is_dir():
            raise OutputPathError(f"{path} is a folder; give a file name")
        suffix = path.suffix.lower()
        if suffixes is not None and suffix not in suffixes:
            # save_motion's words, said before the work rather than after it
            raise OutputPathError(f"{path}: unknown output format {suffix or '(none)'!r}: use "
                                  f"{' or '.join(suffixes)}")  # fmt: skip
        if path.exists() and not overwrite:
            raise OutputPathError(f"{path} exists; {hint}")
    elif kind == "folder":
        if path.exists() and not path.is_dir():
            raise OutputPathError(f"{path} is a file, not a folder; give a folder")
        if not path.exists() and path.suffix.lower() in FILE_SUFFIXES:
            raise OutputPathError(f"{path}: -o names a folder here, not a {path.suffix} file; give a folder name")
        if path.is_dir() and not overwrite and any(path.iterdir()):
            raise OutputPathError(f"{path} is a folder that is not empty; {hint}")
    else:
        raise ValueError(f"kind must be 'file' or 'folder', got {kind!r}")
    _check_writable_parent(path)
    return path


def _check_writable_parent(path: Path) -> None:
    """The folder ``path`` goes in (or the nearest one that exists above it) must take a new entry.

    It is tried, not asked: ``os.access`` says yes to root everywhere, and to anyone in /proc and /sys
    (whose folders refuse new files), so a create-and-remove of a hidden temporary entry is the only
    answer that holds. A missing folder is tried as a folder (what the write will ``mkdir``)."""
    target = path if path.is_dir() else path.parent
    ancestor = target.absolute()
    while not ancestor.exists() and not ancestor.is_symlink():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(f"cannot write {path}: {ancestor} is a file, not a folder")
    try:
        if ancestor == target.absolute():
            fd, probe = tempfile.mkstemp(dir=ancestor, prefix=".physmotion-probe-")
            os.close(fd)
            os.unlink(probe)
        else:
            os.rmdir(tempfile.mkdtemp(dir=ancestor, prefix=".physmotion-probe-"))
    except OSError as exc:
        # /proc answers a new name with ENOENT, which would read as if the folder were missing
        why = f" ({exc.strerror})" if exc.strerror and exc.errno != errno.ENOENT else ""
        raise OutputPathError(f"cannot write {path}: {ancestor} is not writable{why}") from None
