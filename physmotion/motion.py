"""The ``Motion`` record passed between every stage, and its .npz file format."""

from __future__ import annotations

import os
import tempfile
import warnings
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS
from physmotion.errors import MotionFormatError, PhysmotionError, PhysmotionWarning, ShapeError
from physmotion.skeleton import NUM_JOINTS, inverse_kinematics


@dataclass
class Motion:
    """One motion on the 22-joint skeleton.

    joints: (T, 22, 3) float32, metres, Y up (world frame).
    rotations: (T, 22, 3, 3) float32 local rotations (see :mod:`physmotion.skeleton`), or None.
    offsets: (22, 3) rest offsets of this body in metres, or None (needed with rotations).
    fps: frames per second. text: caption(s). licence_tag: "NC" for non-commercial data, else "".
    humanoid: (22, 3) rest offsets of the simulated humanoid whose motion this is (the physics
    projection's output: ``ProjectedMotion.body``), or None. The physical metrics pose that body's
    geometry on the joints instead of one estimated from them.
    resets: for P's output, how often the humanoid fell and was put back on the motion (each a jump in
    the joints); None where P was not applied.
    residual: (T, 2) float32, for P's output the root residual it applied in each frame: force in body
    weights, torque in body weight x 1 m (``ProjectedMotion.residual_force`` / ``residual_torque``);
    None where P was not applied.
    residual_cap: the force cap (x body weight) of the P that made it, so that a reader can tell the frames
    at the cap (:func:`physmotion.metrics.report.residual_stats`); None where P was not applied.
    over_limit: (T,) bool, for P's output the frames in which a joint's torque passed its actuator's limit
    (``ProjectedMotion.over_limit``); None where P was not applied.
    residual_peak: (T, 2) float32, the largest root residual of any update within each frame (``residual``
    holds their mean); residual_at_cap: (T,) bool, frames in which an update was held at one of P's caps
    (force, lift or torque); reset_frames: (T,) bool, frames that are not simulated: where the humanoid
    was put back on the motion and the cross-fade before it (``ProjectedMotion.reset_frames``, over every
    P call that made the motion). Each None where P was not applied (or the file predates it).
    searched: for P's output, whether the search (no outside hand) made it, as the controller or as the
    tracker's fallback (``ProjectedMotion.searched``, in any P call); None where P was not applied.
    recovered: for P's output, how many stretches the search carried with no outside hand where the humanoid
    would have been put back on the motion, or re-did where a take-off fell short (``--rescue-flights``)
    (``ProjectedMotion.recovered``, over every P call); None where P
    was not applied (or the file predates it).
    """

    joints: np.ndarray
    fps: float = FPS
    rotations: np.ndarray | None = None
    offsets: np.ndarray | None = None
    texts: list[str] = field(default_factory=list)
    licence_tag: str = ""
    source: str = ""
    humanoid: np.ndarray | None = None
    resets: int | None = None
    residual: np.ndarray | None = None
    residual_cap: float | None = None
    over_limit: np.ndarray | None = None
    residual_peak: np.ndarray | None = None
    residual_at_cap: np.ndarray | None = None
    reset_frames: np.ndarray | None = None
    searched: bool | None = None
    recovered: int | None = None

    def __post_init__(self) -> None:
        if np.asarray(self.joints).dtype.kind not in "fiu":
            raise ShapeError(f"joints must be real numbers, got {np.asarray(self.joints).dtype}")
        with np.errstate(over="ignore"):  # beyond float32's range becomes inf, which check_joints refuses
            self.joints = np.asarray(self.joints, dtype=np.float32)
        check_joints(self.joints)
        if self.fps <= 0 or not np.isfinite(self.fps):
            raise ShapeError(f"fps must be a positive number, got {self.fps}")
        if self.humanoid is not None:
            self.humanoid = np.asarray(self.humanoid, dtype=np.float64)
            if self.humanoid.shape != (NUM_JOINTS, 3) or not np.all(np.isfinite(self.humanoid)):
                shape = self.humanoid.shape
                raise ShapeError(f"humanoid must be finite rest offsets ({NUM_JOINTS}, 3), got {shape}")
        if self.residual is not None:
            self.residual = np.asarray(self.residual, dtype=np.float32)
            if self.residual.shape != (self.num_frames, 2) or not np.all(np.isfinite(self.residual)):
                shape = self.residual.shape
                raise ShapeError(f"residual must be finite (T, 2) = ({self.num_frames}, 2), got {shape}")
        if self.residual_cap is not None and not (np.isfinite(self.residual_cap) and self.residual_cap >= 0):
            raise ShapeError(f"residual_cap must be a finite number >= 0, got {self.residual_cap}")
        if self.over_limit is not None:
            self.over_limit = np.asarray(self.over_limit)
            if self.over_limit.shape != (self.num_frames,) or self.over_limit.dtype != bool:
                shape, dtype = self.over_limit.shape, self.over_limit.dtype
                raise ShapeError(f"over_limit must be bool (T,) = ({self.num_frames},), got {dtype} {shape}")
        if self.residual_peak is not None:
            self.residual_peak = np.asarray(self.residual_peak, dtype=np.float32)
            if self.residual_peak.shape != (self.num_frames, 2) or not np.all(np.isfinite(self.residual_peak)):
                shape = self.residual_peak.shape
                raise ShapeError(f"residual_peak must be finite (T, 2) = ({self.num_frames}, 2), got {shape}")
        for name in ("residual_at_cap", "reset_frames"):
            value = getattr(self, name)
            if value is not None:
                value = np.asarray(value)
                if value.shape != (self.num_frames,) or value.dtype != bool:
                    got = f"{value.dtype} {value.shape}"
                    raise ShapeError(f"{name} must be bool (T,) = ({self.num_frames},), got {got}")
                setattr(self, name, value)

    @property
    def num_frames(self) -> int:
        return int(self.joints.shape[0])

    @property
    def seconds(self) -> float:
        return self.num_frames / self.fps

    def with_rotations(self) -> Motion:
        """This motion with local rotations and offsets solved by IK if it has none."""
        if self.rotations is not None and self.offsets is not None:
            return self
        from physmotion.skeleton import offsets_from_joints

        offsets = offsets_from_joints(self.joints)
        rot, _ = inverse_kinematics(self.joints, offsets)
        return replace(self, rotations=rot.astype(np.float32), offsets=offsets.astype(np.float32))

    def save(self, path: str | Path) -> None:
        """Write an .npz (joints, rotations, offsets, humanoid, resets, residual, residual_cap, over_limit,
        residual_peak, residual_at_cap, reset_frames, searched, recovered, fps, text, licence_tag) atomically."""
        arrays: dict[str, np.ndarray] = {
            "joints": self.joints,
            "fps": np.float32(self.fps),
            "text": np.array("\n".join(self.texts)),
            "licence_tag": np.array(self.licence_tag),
            "source": np.array(self.source),
        }
        if self.rotations is not None:
            arrays["rotations"] = np.asarray(self.rotations, dtype=np.float32)
        if self.offsets is not None:
            arrays["offsets"] = np.asarray(self.offsets, dtype=np.float32)
        if self.humanoid is not None:
            arrays["humanoid"] = np.asarray(self.humanoid, dtype=np.float64)
        if self.resets is not None:
            arrays["resets"] = np.int64(self.resets)
        if self.residual is not None:
            arrays["residual"] = np.asarray(self.residual, dtype=np.float32)
        if self.residual_cap is not None:
            arrays["residual_cap"] = np.float64(self.residual_cap)
        if self.over_limit is not None:
            arrays["over_limit"] = np.asarray(self.over_limit, dtype=bool)
        if self.residual_peak is not None:
            arrays["residual_peak"] = np.asarray(self.residual_peak, dtype=np.float32)
        for name in ("residual_at_cap", "reset_frames"):
            if getattr(self, name) is not None:
                arrays[name] = np.asarray(getattr(self, name), dtype=bool)
        if self.searched is not None:
            arrays["searched"] = np.bool_(self.searched)
        if self.recovered is not None:
            arrays["recovered"] = np.int64(self.recovered)
        write_atomic(path, lambda f: np.savez(f, **arrays))

    @classmethod
    def load(cls, path: str | Path) -> Motion:
        """Read a motion .npz written by :meth:`save` (or any .npz with a ``joints`` array).

        A file without ``fps`` is read at the project's rate, with a :class:`PhysmotionWarning` naming it."""
        path = Path(path)
        if not path.is_file():
            raise MotionFormatError(f"{path}: no such file")
        try:
            _check_zip(path)
            with np.load(path, allow_pickle=False) as data:
                if "joints" not in data:
                    raise MotionFormatError(f"{path}: not a motion file (no 'joints' array)")
                text = str(data["text"]) if "text" in data else ""
                if "fps" not in data:
                    warnings.warn(f"{path} has no 'fps' array; assuming {FPS} fps", PhysmotionWarning,
                                  stacklevel=2)  # fmt: skip
                motion = cls(
                    joints=data["joints"],
                    fps=float(data["fps"]) if "fps" in data else FPS,
                    rotations=data["rotations"] if "rotations" in data else None,
                    offsets=data["offsets"] if "offsets" in data else None,
                    texts=[t for t in text.split("\n") if t],
                    licence_tag=str(data["licence_tag"]) if "licence_tag" in data else "",
                    source=str(data["source"]) if "source" in data else "",
                    humanoid=data["humanoid"] if "humanoid" in data else None,
                    resets=int(data["resets"]) if "resets" in data else None,
                    residual=data["residual"] if "residual" in data else None,
                    residual_cap=float(data["residual_cap"]) if "residual_cap" in data else None,
                    over_limit=data["over_limit"] if "over_limit" in data else None,
                    searched=bool(data["searched"]) if "searched" in data else None,
                    recovered=int(data["recovered"]) if "recovered" in data else None,
                    **{name: data[name] for name in ("residual_peak", "residual_at_cap", "reset_frames")
                       if name in data},
                )
                _check_pose_arrays(motion, path)
                return motion
        except ShapeError as exc:  # Motion's own checks (NaN, zero frames, fps) do not know the file
            raise MotionFormatError(f"{path}: {exc}") from None
        except PhysmotionError:
            raise
        except Exception as exc:  # noqa: BLE001 - corrupt npz bytes raise zipfile, zlib, tokenize,
            # MemoryError (a header claiming a huge shape), TypeError, ValueError ...: all mean "unreadable"
            detail = " ".join(str(exc).split())[:160]
            why = f"{type(exc).__name__}: {detail}"
            raise MotionFormatError(f"{path}: not a readable .npz file ({why})") from None


def _check_zip(path: Path) -> None:
    """Refuse a file that is not a zip archive (an .npz is one) before np.load sees it: np.load takes any
    other bytes for a pickle and answers with advice to load it with ``allow_pickle``, which is unsafe."""
    with open(path, "rb") as f:
        head = f.read(2)
    if head != b"PK":  # every zip record starts so (PKWARE APPNOTE 4.3.7: local header 0x04034b50)
        hint = (f"; a .bvh is read with `physmotion import {path} -o <name>.npz`" if path.suffix.lower() == ".bvh"
                else "")
        raise MotionFormatError(f"{path}: not a motion .npz (a zip of arrays with 'joints', as physmotion "
                                f"writes){hint}")


def _check_pose_arrays(motion: Motion, path: Path) -> None:
    """Rotations and offsets read from a file must fit the joints and be finite (or be absent)."""
    n = motion.num_frames
    for name, value, shape in (
        ("rotations", motion.rotations, (n, NUM_JOINTS, 3, 3)),
        ("offsets", motion.offsets, (NUM_JOINTS, 3)),
    ):
        if value is None:
            continue
        arr = np.asarray(value, dtype=np.float32)
        if arr.shape != shape or not np.all(np.isfinite(arr)):
            raise MotionFormatError(f"{path}: '{name}' must be finite with shape {shape}, got {arr.shape}")
        setattr(motion, name, arr)


def joined_licence_tag(tags: Iterable[str]) -> str:
    """The licence tag of something made from sources with these tags: every restriction they carry
    ("NC", "SA"; a tag may already be a joined "NC,SA"), sorted and joined with ","; "open" if none."""
    found = {part for tag in tags for part in str(tag).split(",") if part and part not in ("open", "unknown")}
    return ",".join(sorted(found)) or "open"


def check_joints(joints: np.ndarray, name: str = "joints") -> None:
    """Raise ShapeError unless joints is a finite (T, 22, 3) array with T >= 1."""
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise ShapeError(f"{name} must have shape (T, {NUM_JOINTS}, 3), got {tuple(joints.shape)}")
    if joints.shape[0] == 0:
        raise ShapeError(f"{name} has zero frames")
    if not np.all(np.isfinite(joints)):
        raise ShapeError(f"{name} contains NaN or infinite values")


def write_atomic(path: str | Path, write: Callable[[object], None], mode: str = "wb") -> None:
    """Write a file through a temporary file in the same folder, renamed into place at the end.

    A failure part-way leaves nothing behind at ``path``.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, mode) as f:
            write(f)
        os.chmod(tmp, 0o644)  # mkstemp makes 0600; outputs are ordinary files
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
