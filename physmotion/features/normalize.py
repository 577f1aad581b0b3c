"""Feature normalisation: HumanML3D's Mean.npy / Std.npy, computed the published way.

``compute_mean_std`` follows EricGuo5513/HumanML3D ``cal_mean_variance.ipynb`` (``mean_variance``): mean and
(population) std over all frames of all clips, then every group of the vector (``SLICES``) gets one std,
the mean of its members' stds, so that e.g. all 63 ric dims are scaled alike. The ``feat_bias`` weighting
is text-to-motion's (EricGuo5513/text-to-motion ``data/dataset.py``, ``Text2MotionDataset`` when training):
the root groups (rot vel, lin vel, height) and the foot contacts have their std divided by feat_bias,
which weights them up after normalisation. HumanML3D's released Mean/Std use feat_bias = 1 (the default);
text-to-motion's evaluator statistics used 5.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any

import numpy as np

from physmotion.errors import MotionFormatError, ShapeError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, SLICES_BIOMECH
from physmotion.features.humanml3d import FEATURE_DIM, SLICES
from physmotion.motion import write_atomic

MEAN_FILE = "Mean.npy"
STD_FILE = "Std.npy"

MIN_STD = 1e-6
"""Stds below this (constant dimensions) are replaced by 1, so normalising never divides by ~0."""

_BIASED_GROUPS = ("root_rot_vel", "root_lin_vel", "root_y", "foot_contact")
_GROUPS = {FEATURE_DIM: SLICES, FEATURE_DIM_BIOMECH: SLICES_BIOMECH}


class Normalizer:
    """z-normalisation with per-dimension mean and std; numpy arrays and torch tensors alike.

    mean, std: (D,) arrays. Stds below :data:`MIN_STD` are replaced by 1.
    """

    def __init__(self, mean: np.ndarray, std: np.ndarray) -> None:
        mean = np.asarray(mean, dtype=np.float32)
        std = np.asarray(std, dtype=np.float32)
        if mean.ndim != 1 or mean.shape != std.shape:
            raise ShapeError(f"mean and std must be 1-D of equal length, got {mean.shape} and {std.shape}")
        if not (np.all(np.isfinite(mean)) and np.all(np.isfinite(std))):
            raise ShapeError("mean and std must be finite")
        if np.any(std < 0):
            raise ShapeError("std must not be negative")
        self.mean = mean
        self.std = np.where(std < MIN_STD, np.float32(1.0), std)
        self._torch_cache: dict[tuple[Any, Any], tuple[Any, Any]] = {}

    @property
    def dim(self) -> int:
        return int(self.mean.shape[0])

    def normalize(self, x: Any) -> Any:
        """(x - mean) / std; x: (..., D) numpy array or torch tensor, same type out."""
        mean, std = self._stats_like(x)
        return (x - mean) / std

    def denormalize(self, x: Any) -> Any:
        """x * std + mean; the inverse of :meth:`normalize`."""
        mean, std = self._stats_like(x)
        return x * std + mean

    def _stats_like(self, x: Any) -> tuple[Any, Any]:
        dim = x.shape[-1] if hasattr(x, "shape") and len(x.shape) > 0 else None
        if dim != self.dim:
            raise ShapeError(f"features must have last dimension {self.dim}, got {dim}")
        if isinstance(x, np.ndarray):
            return self.mean, self.std
        key = (x.dtype, x.device)
        if key not in self._torch_cache:
            import torch

            self._torch_cache[key] = (
                torch.as_tensor(self.mean, dtype=x.dtype, device=x.device),
                torch.as_tensor(self.std, dtype=x.dtype, device=x.device),
            )
        return self._torch_cache[key]

    @classmethod
    def load(cls, folder: str | Path) -> Normalizer:
        """Read ``Mean.npy`` and ``Std.npy`` from a dataset folder (HumanML3D layout)."""
        folder = Path(folder)
        arrays = []
        for name in (MEAN_FILE, STD_FILE):
            path = folder / name
            if not path.is_file():
                raise MotionFormatError(f"{path}: no such file (dataset statistics)")
            try:
                arrays.append(np.load(path, allow_pickle=False))
            except (OSError, ValueError, EOFError) as exc:
                raise MotionFormatError(f"{path}: not a readable .npy file ({exc})") from None
        return cls(arrays[0], arrays[1])

    def save(self, folder: str | Path) -> None:
        """Write ``Mean.npy`` and ``Std.npy`` (float32) into folder, each atomically."""
        folder = Path(folder)
        write_atomic(folder / MEAN_FILE, lambda f: np.save(f, self.mean))
        write_atomic(folder / STD_FILE, lambda f: np.save(f, self.std))


def compute_mean_std(
    feature_arrays: list[np.ndarray], *, feat_bias: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """Mean and std (D,) float32 of a list of (T_i, D) feature arrays, D = 263 or 329 (``mean_variance``).

    Arrays containing NaN are skipped with a warning, as published. Each group's std becomes the mean of
    its stds; the root groups and foot contacts are then divided by ``feat_bias``; stds that end up below
    :data:`MIN_STD` become 1.
    """
    if feat_bias <= 0 or not np.isfinite(feat_bias):
        raise ShapeError(f"feat_bias must be a positive number, got {feat_bias}")
    kept = []
    for i, arr in enumerate(feature_arrays):
        arr = np.asarray(arr)
        if arr.ndim != 2 or arr.shape[-1] not in _GROUPS:
            want = f"(T, {FEATURE_DIM}) or (T, {FEATURE_DIM_BIOMECH})"
            raise ShapeError(f"feature array {i} must have shape {want}, got {arr.shape}")
        if np.isnan(arr).any():
            warnings.warn(f"feature array {i} contains NaN; skipped", stacklevel=2)
            continue
        kept.append(arr)
    if not kept or sum(len(a) for a in kept) == 0:
        raise ShapeError("no frames to compute statistics from")
    dims = {a.shape[-1] for a in kept}
    if len(dims) > 1:
        raise ShapeError(f"feature arrays differ in dimension: {sorted(dims)}")

    data = np.concatenate(kept, axis=0).astype(np.float64)
    mean = data.mean(axis=0)
    std = data.std(axis=0)
    for name, group in _GROUPS[data.shape[-1]].items():
        std[group] = std[group].mean() / (feat_bias if name in _BIASED_GROUPS else 1.0)
    std = np.where(std < MIN_STD, 1.0, std)
    return mean.astype(np.float32), std.astype(np.float32)
