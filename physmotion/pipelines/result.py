"""What a generation pipeline returns: the motions, and what physics did to each of them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from physmotion.diffusion.physdiff import ProjectionLog
from physmotion.motion import Motion


@dataclass
class GenerateResult:
    """One run of a pipeline; lists are per motion, in the order of the prompts given (text-major)."""

    motions: list[Motion]
    features: list[np.ndarray]  # (T, D) un-normalised, as sampled (before any physics after sampling)
    projections: ProjectionLog  # every call of P in the run (physdiff: inside sampling; post, morph: after)
    resets: list[int] = field(default_factory=list)  # per motion: resets in the projection it came from
    # morph, per motion: the imitation failed and the sampled motion was kept (empty in the other modes)
    imitation_failed: list[bool] = field(default_factory=list)
    # per motion: its length in frames and where it came from, "given" or "predicted" (from the text)
    lengths: list[int] = field(default_factory=list)
    length_source: list[str] = field(default_factory=list)
    settings: dict = field(
        default_factory=dict
    )  # the pipeline, its sampler and P's settings (Pipeline.settings)

    @property
    def bodies(self) -> list[np.ndarray | None]:
        """Per motion, the humanoid body (22, 3) whose simulation (or surface, for none+floor) the output
        is (``Motion.humanoid``), or None where the output was not put on a body (none; physdiff without
        a projection at the last step)."""
        return [m.humanoid for m in self.motions]

    @property
    def residuals(self) -> list[np.ndarray | None]:
        """Per motion, the root residual (T, 2) of the simulation it is (``Motion.residual``), or None."""
        return [m.residual for m in self.motions]
