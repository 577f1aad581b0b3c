"""The motions the imitator trains and is evaluated on: built datasets (captured clips with their mirrors),
folders of generated motions (``physmotion generate`` output: Morph's motion-free idea, the policy
learns on what P is asked to project) and teacher folders (``imitator/teacher.py``: segments with the
trajectory the search carried them along, with no outside hand)."""

from __future__ import annotations

import csv
import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import PhysmotionError
from physmotion.skeleton import NUM_JOINTS, mirror_joints


@dataclass(frozen=True)
class TrackedTrajectory:
    """A simulated trajectory of the humanoid built from a clip, for the body to follow in place of the
    kinematic reference (the search's, which the body follows with no outside hand by construction).

    qpos: (N, nq) and qvel: (N, nv) float64 at control steps 0..N-1, MuJoCo's frame; N is at most the
    reference's control steps.
    """

    qpos: np.ndarray
    qvel: np.ndarray


@dataclass(frozen=True)
class ClipSource:
    """One motion to imitate. joints: (T, 22, 3) float32, metres, Y up, at ``fps``; ``tracked``: the
    trajectory the reward, the early termination and the start states follow (None: the reference)."""

    name: str
    joints: np.ndarray
    fps: float
    licence_tag: str
    origin: str  # "captured" or "generated"
    tracked: TrackedTrajectory | None = None


def dataset_clips(folder: str | Path, split: str = "train") -> list[ClipSource]:
    """Every item of ``split`` in a built dataset folder (``new_joints/<id>.npy``, ``<split>.txt``; our
    ``index.csv`` for licence tags, absent in a plain HumanML3D folder), mirrored copies included: a
    mirrored item ``M<id>`` whose file is missing is mirrored from ``<id>`` (a copy of a build carried
    without its mirrors to save space)."""
    root = Path(folder)
    split_file = root / f"{split}.txt"
    if not split_file.is_file():
        raise PhysmotionError(f"not a dataset folder: {split_file} is missing (build one with `data build`)")
    ids = [line.strip() for line in split_file.read_text().splitlines() if line.strip()]
    tags: dict[str, str] = {}
    index = root / "index.csv"
    if index.is_file():
        with index.open(newline="") as f:
            tags = {row["id"]: row["licence_tag"] for row in csv.DictReader(f)}
    out = []
    for i in ids:
        path = root / "new_joints" / f"{i}.npy"
        plain = root / "new_joints" / f"{i[1:]}.npy"
        if not path.is_file() and i.startswith("M") and plain.is_file():
            joints = mirror_joints(np.load(plain)).astype(np.float32)  # a copy made without the mirrors
        elif path.is_file():
            joints = np.load(path).astype(np.float32)
        else:
            raise PhysmotionError(f"dataset item {i} has no joints file {path}")
        _check(joints, str(path))
        out.append(ClipSource(i, joints, float(FPS), tags.get(i, ""), "captured"))
    return out


def motion_clips(folder: str | Path) -> list[ClipSource]:
    """Every ``.npz`` motion in ``folder`` (e.g. ``physmotion generate`` output), sorted by name."""
    from physmotion.motion import Motion

    root = Path(folder)
    if not root.is_dir():
        raise PhysmotionError(f"motion folder not found: {root}")
    out = []
    for path in sorted(root.glob("*.npz")):
        m = Motion.load(path)
        _check(m.joints, str(path))
        out.append(ClipSource(path.stem, m.joints.astype(np.float32), float(m.fps), m.licence_tag, "generated"))
    if not out:
        raise PhysmotionError(f"no .npz motions in {root}")
    return out


def teacher_clips(folder: str | Path) -> list[ClipSource]:
    """Every record in a teacher folder (``imitator/teacher.py``, ``<id>.npz``), sorted by name, as a clip of
    its segment (``joints``, ``fps``) whose tracked trajectory is the search's ``qpos``/``qvel``, cut before
    ``failed_at`` where the search fell (only the part it carried). A record with under 2 carried control
    steps is left out: there is no step to learn from."""
    root = Path(folder)
    if not root.is_dir():
        raise PhysmotionError(f"teacher folder not found: {root}")
    out = []
    for path in sorted(root.glob("*.npz")):
        try:
            with np.load(path) as z:
                joints, fps = z["joints"].astype(np.float32), float(z["fps"])
                end = len(z["qpos"]) if bool(z["completed"]) else int(z["failed_at"])
                qpos, qvel = z["qpos"][:end].astype(np.float64), z["qvel"][:end].astype(np.float64)
                tag, origin = str(z["licence_tag"]), str(z["origin"])
        except (OSError, ValueError, KeyError) as e:
            raise PhysmotionError(f"{path}: not a teacher record ({e})") from None
        _check(joints, str(path))
        if len(qpos) != len(qvel) or not (np.all(np.isfinite(qpos)) and np.all(np.isfinite(qvel))):
            raise PhysmotionError(f"{path}: its qpos and qvel differ in length or are not finite")
        if end >= 2:
            out.append(ClipSource(path.stem, joints, fps, tag, origin, TrackedTrajectory(qpos, qvel)))
    if not out:
        raise PhysmotionError(f"no teacher records with 2 or more carried steps in {root} "
                              "(`physmotion train teacher` makes them)")  # fmt: skip
    return out


def _held_out(segment: str) -> bool:
    """One segment in 8 or so, by a stable hash of its name."""
    return int(hashlib.sha1(segment.encode()).hexdigest(), 16) % 8 == 0


def _segment(name: str) -> str:
    """A teacher record's segment: its id without the start's tag (``<source>_f<start>``)."""
    return name.rsplit("_", 1)[0]


def _check(joints: np.ndarray, where: str) -> None:
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3) or len(joints) < 2:
        raise PhysmotionError(f"{where}: joints must be (T, 22, 3) with T >= 2, got {joints.shape}")
    if not np.all(np.isfinite(joints)):
        raise PhysmotionError(f"{where}: joints contain NaN or infinite values")


def licence_tags(clips: list[ClipSource]) -> list[str]:
    """The licence tags the clips carry (sorted, empty tags left out)."""
    return sorted({c.licence_tag for c in clips if c.licence_tag})


def training_sets(data: list[str | Path], motions: list[str | Path], eval_clips: int = 16,
                  teachers: list[str | Path] = ()) -> tuple[list[ClipSource], list[ClipSource]]:  # fmt: skip
    """The clips to train on and the fixed evaluation set, from dataset folders (their train splits; the
    evaluation takes unmirrored test items), folders of generated motions (every 8th is held out for
    evaluation) and teacher folders (one segment in 8 by a hash of its name, each of its starts, is held out;
    evaluated as P runs, on the kinematic reference from its first frame). The evaluation set, at most ``eval_clips``, is shared
    evenly between the sources."""
    if not data and not motions and not teachers:
        raise PhysmotionError("give at least one --data, --motions or --teacher folder")
    clips, evals = [], []
    per_source = max(1, eval_clips // (len(data) + len(motions) + len(teachers)))
    for folder in data:
        clips += dataset_clips(folder, "train")
        evals += [c for c in dataset_clips(folder, "test") if not c.name.startswith("M")][:per_source]
    for folder in motions:
        gen = motion_clips(folder)
        evals += gen[::8][:per_source]
        clips += [c for i, c in enumerate(gen) if i % 8]
    for folder in teachers:
        records = teacher_clips(folder)
        segments = {_segment(c.name) for c in records}
        # Held out by a hash of the segment's name, not its rank: a folder still being written keeps its
        # held-out segments as it grows, so a resumed run never trains on what it evaluated on.
        held = {s for s in segments if _held_out(s)} if len(segments) > 1 else set()
        evals += [c for c in records if _segment(c.name) in held and c.name.endswith("_plain")][:per_source]
        clips += [c for c in records if _segment(c.name) not in held]
    return clips, evals[:eval_clips]
