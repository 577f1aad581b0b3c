"""The shape every generation method shares: sample features from text, recover joints, then the method's
physics, then motions. A method is a subclass that says how it samples (:meth:`Pipeline._sample`: PhysDiff
projects inside the loop) and what it does after (:meth:`Pipeline._after`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from physmotion.conventions import FPS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import ProjectionLog, projection_settings
from physmotion.diffusion.samplers import SamplerConfig, sample
from physmotion.features.humanml3d import recover_from_ric
from physmotion.motion import Motion
from physmotion.physics.projection import ProjectionConfig, SimRecord
from physmotion.pipelines.result import GenerateResult

# on_step(done, total): progress over the sampling steps and P's applications after sampling
Progress = Callable[[int, int], None]


@dataclass
class Physical:
    """The motions after a method's physics, per motion: joints (T, 22, 3); the humanoid body (22, 3) they
    are the simulation (or surface) of, or None; what P recorded of that simulation over every call that
    made it (resets, help, reset frames), or None where the output is no simulation."""

    joints: list[np.ndarray]
    bodies: list[np.ndarray | None]
    records: list[SimRecord | None]
    failed: list[bool] = field(default_factory=list)  # Morph's imitation selection kept the input

    @classmethod
    def kinematic(cls, joints: list[np.ndarray]) -> Physical:
        """Motions that were not simulated on a body."""
        return cls(list(joints), [None] * len(joints), [None] * len(joints))

    @property
    def resets(self) -> list[int]:
        """Per motion, the times P put the humanoid back on it over every call (0 without P)."""
        return [r.resets if r is not None else 0 for r in self.records]


class Pipeline:
    """Text -> motions with one method. ``name`` is the physics mode's spelling (``physics_mode``)."""

    name = "none"
    projects = False  # the method applies P: its motions carry the simulation's resets and residual

    def __init__(self, model: MotionDiffusion, sampler: SamplerConfig | None = None,
                 projection: ProjectionConfig | None = None) -> None:  # fmt: skip
        self.model = model
        self.sampler = sampler or SamplerConfig()
        self.projection = projection

    @property
    def projections_after(self) -> int:
        """P's applications after sampling (reported as steps of the progress)."""
        return 0

    def settings(self) -> dict:
        """What made the motions: the method, the sampler and P's settings (None without P)."""
        return {"pipeline": type(self).__name__, "physics": self.name, "sampler": asdict(self.sampler),
                "projection": projection_settings(self.projection) if self.projection else None}  # fmt: skip

    def __call__(self, prompts: Sequence[str], lengths: Sequence[int], seed: int = 0,
                 on_step: Progress | None = None) -> GenerateResult:  # fmt: skip
        """One motion per prompt, ``lengths`` frames each; deterministic under ``seed``."""
        prompts, lengths = [p.strip() for p in prompts], [int(n) for n in lengths]
        total = self.sampler.steps + self.projections_after
        report = (lambda i, n: on_step(i, total)) if on_step else None
        log = ProjectionLog()
        x, last = self._sample(prompts, lengths, seed, log, report)
        feats = self.model.normalizer.denormalize(x.float().cpu().numpy())
        feats = [f[:n] for f, n in zip(feats, lengths)]
        joints = [recover_from_ric(f.astype(np.float64)) for f in feats]
        after = (lambda k: on_step(self.sampler.steps + k, total)) if on_step else None
        done = self._after(joints, log, after) if last is None else last
        cap = self.projection.residual_bound() if self.projects else None
        motions = [
            Motion(joints=j, fps=FPS, texts=[p], licence_tag=self.model.licence_tag,
                   source=f"physmotion generate ({self.name})", humanoid=b,
                   **(r.motion_fields(cap) if self.projects and b is not None and r is not None else {}))
            for j, p, b, r in zip(done.joints, prompts, done.bodies, done.records)
        ]  # fmt: skip
        return GenerateResult(motions=motions, features=list(feats), projections=log,
                              resets=log.resets_per_motion(len(prompts)), imitation_failed=done.failed, lengths=lengths, settings=self.settings())  # fmt: skip

    def _sample(self, prompts: list[str], lengths: list[int], seed: int, log: ProjectionLog,
                on_step: Progress | None) -> tuple[torch.Tensor, Physical | None]:  # fmt: skip
        """Normalised features (B, max(lengths), D), and the motions themselves where sampling already
        made them physical (None: :meth:`_after` does)."""
        return sample(self.model, prompts, lengths, self.sampler, seed=seed, on_step=on_step), None

    def _after(self, joints: list[np.ndarray], log: ProjectionLog,
               on_projection: Callable[[int], None] | None) -> Physical:  # fmt: skip
        """The method's physics on the sampled joints (T_i, 22, 3); on_projection(k) after P's k-th pass."""
        return Physical.kinematic(joints)
