"""Plain diffusion sampling (``none``), and the same grounded on the floor (``none+floor``): the papers'
baseline and the clean-up any user does first, at its best."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from physmotion.diffusion.physdiff import ProjectionLog
from physmotion.pipelines.base import Physical, Pipeline
from physmotion.pipelines.modes import FLOOR, NONE


class PlainPipeline(Pipeline):
    """Motions as sampled."""

    name = NONE


class FloorPipeline(Pipeline):
    """Motions as sampled, each moved up or down by the constant that leaves it the least Phys-Err on the
    body's surface (:func:`physmotion.physics.surface.ground_on_surface`)."""

    name = FLOOR

    def _after(self, joints: list[np.ndarray], log: ProjectionLog,
               on_projection: Callable[[int], None] | None) -> Physical:  # fmt: skip
        from physmotion.physics.surface import ground_on_surface

        grounded, bodies = (list(z) for z in zip(*(ground_on_surface(j) for j in joints)))
        return Physical(grounded, bodies, [None] * len(joints))
