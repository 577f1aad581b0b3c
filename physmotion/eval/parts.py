"""Finished runs of an evaluation, saved as they finish, so that a killed ``physmotion evaluate`` resumes
where it stopped instead of starting over (the default table takes hours on 2 cores).

One file per (mode, repeat): ``<folder>/<mode>_r<repeat>.npz`` with the run's figures, its motions'
evaluator embeddings, and (for ``none``, whose plain samples the other modes are measured against) its
joints. Each is keyed by a digest of everything that decides the run: the model's weights and
normaliser, the evaluator's embeddings of the split's motions and drawn captions (so its weights, the
items and the captions), the mode's generation settings with the repeat's seed, and the table's own
settings. A file with another key is computed again and replaced, never reused.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict
from pathlib import Path

import numpy as np

from physmotion.motion import write_atomic


def digest(*parts: object) -> str:
    """A hex digest of arrays, tensors and JSON-able values, in order."""
    h = hashlib.sha256()
    for part in parts:
        if hasattr(part, "detach"):  # a torch tensor
            part = part.detach().cpu().numpy()
        if isinstance(part, np.ndarray):
            h.update(str((part.dtype.str, part.shape)).encode())
            h.update(np.ascontiguousarray(part).tobytes())
        else:
            h.update(json.dumps(part, sort_keys=True, default=str).encode())
        h.update(b"\0")
    return h.hexdigest()


def model_digest(model) -> str:
    """The generating model's weights (every state tensor, by name) and its feature normaliser."""
    state = model.net.state_dict()
    return digest(*[x for name in sorted(state) for x in (name, state[name])],
                  model.normalizer.mean, model.normalizer.std)  # fmt: skip


class RunParts:
    """The finished runs under ``folder`` (created on the first save)."""

    def __init__(self, folder: str | Path, common: str) -> None:
        self.folder, self.common = Path(folder), common

    def key(self, mode: str, repeat: int, generate_config) -> str:
        return digest(self.common, mode, repeat, asdict(generate_config))

    def path(self, mode: str, repeat: int) -> Path:
        return self.folder / f"{re.sub(r'[^A-Za-z0-9+.=-]', '_', mode)}_r{repeat}.npz"

    def load(self, mode: str, repeat: int, key: str):
        """``(run, emb, joints or None)`` saved under ``key``, else None."""
        path = self.path(mode, repeat)
        if not path.is_file():
            return None
        try:
            with np.load(path) as f:
                if str(f["key"]) != key:
                    return None
                joints = [f[f"joints_{i}"] for i in range(int(f["joints"]))] if "joints" in f else None
                return json.loads(str(f["run"])), f["emb"], joints
        except (OSError, ValueError, KeyError):  # a part cut short by a kill before its rename: recompute
            return None

    def save(self, mode: str, repeat: int, key: str, run: dict, emb: np.ndarray,
             joints: list[np.ndarray] | None = None) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)
        arrays = {"key": np.array(key), "run": np.array(json.dumps(run)), "emb": emb}
        if joints is not None:
            arrays |= {"joints": np.array(len(joints))} | {f"joints_{i}": j for i, j in enumerate(joints)}
        write_atomic(self.path(mode, repeat), lambda f: np.savez(f, **arrays))



def count_parts(folder: str | Path) -> int:
    """How many finished runs ``folder`` holds, whatever their settings."""
    folder = Path(folder)
    return len(list(folder.glob("*_r*.npz"))) if folder.is_dir() else 0


def remove_parts(folder: str | Path) -> None:
    """Delete the saved runs and their folder (once the table is written); anything else there stays."""
    folder = Path(folder)
    if folder.is_dir():
        for path in [*folder.glob("*_r*.npz"), *folder.glob(".*.tmp")]:  # a killed write's temporary too
            path.unlink()
        try:
            folder.rmdir()
        except OSError:  # not empty: leave it
            pass
