"""Morph's inference (Sec. 3.3 "Inference"): plain sampling, App. A's pre-processing ("used for training and
inference"), one P with Morph's imitation selection as post-process (``ProjectionConfig()``: no reset;
where the humanoid fails to imitate a motion, MPJPE past tau = 0.5 m, the sampled motion is kept and
counted as an imitation failure). Meant for a Morph fine-tuned model, and runs with any."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import FeatureProjector, ProjectionLog
from physmotion.diffusion.samplers import SamplerConfig
from physmotion.physics.projection import ProjectionConfig
from physmotion.pipelines.base import Physical, Pipeline
from physmotion.pipelines.modes import MORPH


class MorphPipeline(Pipeline):
    """Sampling, then one P with imitation selection; ``Physical.failed`` marks the kept inputs."""

    name = MORPH
    projects = True

    def __init__(self, model: MotionDiffusion, sampler: SamplerConfig | None = None,
                 projection: ProjectionConfig | None = None) -> None:  # fmt: skip
        super().__init__(model, sampler, projection or ProjectionConfig())

    @property
    def projections_after(self) -> int:
        return 1

    def _after(self, joints: list[np.ndarray], log: ProjectionLog,
               on_projection: Callable[[int], None] | None) -> Physical:  # fmt: skip
        from physmotion.morph.preprocess import PreprocessConfig, floor_first_frame, preprocess

        done = log.add(FeatureProjector(self.model, self.projection).project_joints(
            [preprocess(j, PreprocessConfig()) for j in joints]))  # fmt: skip
        failed = [not s for s in done.selected]
        # A kept input is the pre-processed motion with its first frame's lowest point on the floor; it was
        # not simulated on a body, so it has none.
        out = Physical(joints=[floor_first_frame(j, physical=True) if f else j for j, f in zip(done.joints, failed)],
                       bodies=[None if f else b for b, f in zip(done.bodies, failed)],
                       records=[None if f else r for r, f in zip(done.records, failed)], failed=failed)  # fmt: skip
        if on_projection:
            on_projection(1)
        return out
