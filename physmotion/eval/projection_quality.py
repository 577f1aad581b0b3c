"""The physics projection on captured clips: which clips the issue's targets speak of, and how one clip
is measured. Shared by ``bench/projection_quality.py`` (all clips) and the tests (a subset).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from physmotion.io.importer import ClipInfo, import_clip, load_manifest
from physmotion.metrics import physical_metrics
from physmotion.physics.projection import ProjectedMotion, ProjectionConfig, project
from physmotion.physics.surface import HumanoidSurface, ground_on_surface
from physmotion.physics.workers import map_in_workers

LOCOMOTION = re.compile(r"\b(walk|walks|walking|run|runs|running|jog|jogs|jogging)\b")
"""A clip whose first caption matches is a walking/running clip."""


def locomotion_clips(mocap_dir: str | Path) -> list[ClipInfo]:
    """The walking and running clips of a mocap directory, in manifest order."""
    return [c for c in load_manifest(mocap_dir) if LOCOMOTION.search(c.captions[0].lower())]


@dataclass
class ClipProjection:
    """One projected clip: P's result and the physical metrics of its input and of the simulation, both
    on the humanoid's geometry of the clip's own body, under the metrics' floor convention (the input
    grounded on that surface, :func:`ground_on_surface`; the simulation as it is)."""

    result: ProjectedMotion
    before: dict[str, float]
    after: dict[str, float]


def measure_projection(
    joints: np.ndarray, fps: float, config: ProjectionConfig | None = None
) -> ClipProjection:
    """Project ``joints`` (T, 22, 3), data convention, at ``fps`` and measure input and output."""
    result = project(joints, fps, config)
    grounded, body = ground_on_surface(joints)
    surface = HumanoidSurface(body)
    before = physical_metrics(grounded, fps=fps, body=surface)
    after = physical_metrics(result.simulated, fps=fps, body=surface)
    return ClipProjection(result, before, after)


def measure_clips(
    clips: list[ClipInfo], config: ProjectionConfig | None = None, workers: int = 0
) -> list[ClipProjection]:
    """:func:`measure_projection` of each clip (imported from the manifest), in input order, the clips
    spread over ``workers`` processes (0: one per core)."""
    return map_in_workers(partial(_measure_clip, config=config), clips, workers)


def _measure_clip(info: ClipInfo, config: ProjectionConfig | None) -> ClipProjection:
    motion = import_clip(info)
    return measure_projection(motion.joints, motion.fps, config)
