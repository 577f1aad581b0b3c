"""PhysDiff (Yuan et al. 2023): the physics projection P inside the sampler at scheduled steps (Algorithm 2,
``physdiff[:SCHEDULE]``), and the paper's post-processing baseline, P applied K times after sampling
(``post[:K]``). P is :class:`~physmotion.diffusion.physdiff.FeatureProjector` on the generation preset
(``ProjectionConfig.sampling()``): where the humanoid falls it is put back on the motion (a reset, counted)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import FeatureProjector, Projected, ProjectionLog, on_data_floor
from physmotion.diffusion.samplers import SamplerConfig, sample
from physmotion.metrics.actions import flight_height
from physmotion.metrics.dynamics import MIN_FLIGHT
from physmotion.physics.projection import ProjectionConfig, SimRecord
from physmotion.pipelines.base import Physical, Pipeline, Progress
from physmotion.pipelines.modes import DEFAULT_SCHEDULE, PhysicsMode


def _physical(calls: list[Projected]) -> Physical:
    """The last of P's calls, which projects every motion of the output, with every call's resets counted
    in its records (a fall in an earlier call is one the user should know of, though sampling went on
    from it; an earlier call may have projected only some motions: ``fly:last``)."""
    records: list[SimRecord | None] = [None] * len(calls[-1].joints)
    for done in calls:
        for k, r in enumerate(done.records):
            i = k if done.indices is None else done.indices[k]
            records[i] = r.after(records[i])
    return Physical(list(calls[-1].joints), list(calls[-1].bodies), records)


class PhysDiffPipeline(Pipeline):
    """P at the loop indices of ``schedule`` (``end:2,space:1``: the last two steps; ``fly:last``: a motion
    whose denoised x0 flies at the first of them only at the last)."""

    projects = True

    def __init__(self, model: MotionDiffusion, sampler: SamplerConfig | None = None,
                 projection: ProjectionConfig | None = None, schedule: str = DEFAULT_SCHEDULE) -> None:  # fmt: skip
        super().__init__(model, sampler, projection or ProjectionConfig.sampling())
        self.mode = PhysicsMode.parse(f"physdiff:{schedule}")
        self.name = str(self.mode)
        self.steps = self.mode.hook_steps(self.sampler.steps)  # raises for a schedule that does not fit

    def _sample(self, prompts: list[str], lengths: list[int], seed: int, log: ProjectionLog,
                on_step: Progress | None) -> tuple[torch.Tensor, Physical | None]:  # fmt: skip
        projector = FeatureProjector(self.model, self.projection)
        done: list[Projected] = []
        calls = iter(range(len(self.steps)))

        def hook(x0: torch.Tensor, hook_lengths: list[int]) -> torch.Tensor:
            only = None
            if self.mode.flies_last and next(calls) < len(self.steps) - 1:  # fly:last, before the last step
                joints = projector.joints(x0, hook_lengths)
                only = [i for i, j in enumerate(joints) if flight_height(j) < MIN_FLIGHT]
                if not only:
                    return x0
            x, projected = projector.project_features(x0, hook_lengths, only)
            done.append(log.add(projected))
            return x

        x = sample(self.model, prompts, lengths, self.sampler, seed=seed, hook=hook, hook_steps=self.steps,
                   on_step=on_step)  # fmt: skip
        if self.steps[-1:] == [self.sampler.steps - 1]:
            # The last step was projected, and DDIM's last step returns x0 itself: the output is P's
            # simulated motion, kept in physical coordinates (soles on the floor) rather than re-floored.
            return x, _physical(done)
        return x, None


class PostProjectionPipeline(Pipeline):
    """P applied ``projections`` times to the sampled motions, each pass on the last one's output."""

    projects = True

    def __init__(self, model: MotionDiffusion, sampler: SamplerConfig | None = None,
                 projection: ProjectionConfig | None = None, projections: int = 1) -> None:  # fmt: skip
        super().__init__(model, sampler, projection or ProjectionConfig.sampling())
        self.mode = PhysicsMode.parse(f"post:{projections}")
        self.name = str(self.mode)

    @property
    def projections_after(self) -> int:
        return self.mode.projections

    def _after(self, joints: list[np.ndarray], log: ProjectionLog,
               on_projection: Callable[[int], None] | None) -> Physical:  # fmt: skip
        projector = FeatureProjector(self.model, self.projection)
        given, calls = list(joints), []
        for k in range(self.mode.projections):
            # the sampled motion in P's convention first, then each pass's output on its lowest joint
            given = [on_data_floor(j) for j in given] if k else projector.data_floor(given)
            calls.append(log.add(projector.project_joints(given)))
            given = calls[-1].joints
            if on_projection:
                on_projection(k + 1)
        return _physical(calls)
