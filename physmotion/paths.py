"""Output paths checked before any work: a command that will fail to write must fail in its first second.

Every command that writes calls :func:`check_output` on each path it will write, before it loads a
model or reads a dataset, so a wrong ``-o`` costs a one-line error rather than minutes of work.
"""

from __future__ import annotations

import os
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


class OutputPathError(PhysmotionError):
    """An output path that cannot or must not be written (wrong kind, not writable, would clobber)."""


def check_output(path: str | Path, kind: OutputKind = "file", overwrite: bool = False,
                 hint: str = "pass --overwrite to replace it") -> Path:  # fmt: skip
    """Raise OutputPathError unless ``path`` can be written as a ``kind`` without clobbering anything.

    kind "file": ``path`` must not be a folder, nor (unless ``overwrite``) an existing file.
    kind "folder": ``path`` must not be a file, nor (unless ``overwrite``) a non-empty folder.
    Either way the nearest existing ancestor must be a writable folder (missing folders are created
    later, by the write). ``hint`` ends the would-clobber message. Nothing is created; returns ``path``.
    """
    path = Path(path)
    if kind == "file":
        if path.is_dir():
            raise OutputPathError(f"{path} is a folder; give a file name")
        if path.exists() and not overwrite:
            raise OutputPathError(f"{path} exists; {hint}")
    elif kind == "folder":
        if path.exists() and not path.is_dir():
            raise OutputPathError(f"{path} is a file, not a folder; give a folder")
        if path.is_dir() and not overwrite and any(path.iterdir()):
            raise OutputPathError(f"{path} is a folder that is not empty; {hint}")
    else:
        raise ValueError(f"kind must be 'file' or 'folder', got {kind!r}")
    _check_writable_parent(path)
    return path


def _check_writable_parent(path: Path) -> None:
    """The folder ``path`` goes in (or the nearest one that exists above it) must be a writable folder."""
    target = path if path.is_dir() else path.parent
    ancestor = target.absolute()
    while not ancestor.exists() and not ancestor.is_symlink():
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise OutputPathError(f"cannot write {path}: {ancestor} is a file, not a folder")
    if not os.access(ancestor, os.W_OK | os.X_OK):
        raise OutputPathError(f"cannot write {path}: {ancestor} is not writable")
