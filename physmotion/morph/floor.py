"""Fine-tuning data with the humanoid's soles on the floor (:data:`~physmotion.conventions.FLOOR_SURFACE`).

HumanML3D's features put each clip's lowest *joint* on y = 0, which leaves the humanoid's soles about
2.5 cm under the floor, and re-flooring P's simulated motions that way throws away where physics put
their feet. The features store absolute heights, so they can hold the physical floor instead: a model
fine-tuned on motions in this convention samples motions that stand on the floor
(docs/decisions/morph.md: "Morph fine-tuning on the physical floor").

- refined synthetic motions: the simulation's own heights (``extract_features(..., floor=False)`` of
  ``new_joints``, whose soles P kept on the floor);
- generated inputs kept by the selection, and real train windows: moved up by the constant that grounds
  them on the humanoid's surface (:func:`~physmotion.physics.surface.ground_on_surface`, the metrics'
  and ``none+floor``'s convention).
"""

from __future__ import annotations

import hashlib
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from physmotion.data.dataset import MotionItem
from physmotion.features.humanml3d import FEATURE_DIM, extract_features, raise_features, recover_from_ric
from physmotion.physics.workers import map_in_workers

_CHUNK = 32  # motions per worker batch between progress updates
_LIFTS: dict[str, float] = {}  # sha1 of a motion's features -> its surface lift (m)


def features_lift(features: np.ndarray) -> float:
    """Metres by which the motion of ``features`` (T, 263 or 329; not normalised) must rise for the
    humanoid's soles to stand on the floor (:func:`~physmotion.physics.surface.surface_lift`, on the body
    fitted to the motion)."""
    from physmotion.physics.humanoid import body_from_joints
    from physmotion.physics.surface import surface_lift

    joints = recover_from_ric(np.asarray(features[:, :FEATURE_DIM], dtype=np.float64))
    return surface_lift(joints, body_from_joints(joints))


def simulated_features(joints_path: Path) -> np.ndarray:
    """Features (T-1, 263) float32 of a simulated motion ``new_joints/<id>.npy`` at the heights P left it."""
    return extract_features(np.load(joints_path).astype(np.float64), floor=False)[0]


def on_surface(items: Sequence[MotionItem], progress: bool = False, label: str = "grounding") -> list[MotionItem]:
    """``items`` (features in the data convention) moved onto the humanoid's surface, in worker processes.

    Lifts are remembered per features for the life of the process (about 0.15 s a motion), so the real
    train split is grounded once for all rounds of a ``morph run``."""
    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    keys = [hashlib.sha1(np.ascontiguousarray(it.features).tobytes()).hexdigest() for it in items]
    todo = [k for k in dict.fromkeys(keys) if k not in _LIFTS]
    features = {k: it.features for k, it in zip(keys, items)}
    columns = (TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn())
    with Progress(*columns, console=Console(stderr=True), disable=not progress or not todo) as bar:
        task = bar.add_task(label, total=len(todo))
        for start in range(0, len(todo), _CHUNK):
            chunk = todo[start : start + _CHUNK]
            _LIFTS.update(zip(chunk, map_in_workers(features_lift, [features[k] for k in chunk])))
            bar.advance(task, len(chunk))
    return [replace(it, features=raise_features(it.features, _LIFTS[k])) for it, k in zip(items, keys)]


def selected_on_surface(items: Sequence[MotionItem], refined_joints: dict[str, Path],
                        progress: bool = False) -> list[MotionItem]:  # fmt: skip
    """Selected synthetic items in the surface convention: a refined one (its id in ``refined_joints``,
    which gives its ``new_joints`` file) at the simulation's heights, a kept input grounded."""
    out = list(items)
    inputs = [k for k, it in enumerate(items) if it.id not in refined_joints]
    for k, it in enumerate(items):
        if it.id in refined_joints:
            out[k] = replace(it, features=simulated_features(refined_joints[it.id]))
    for k, it in zip(inputs, on_surface([items[k] for k in inputs], progress, "grounding kept inputs")):
        out[k] = it
    return out
