"""BioMoDiffuse's refinement (Sec. 3.5): a given motion DDIM-inverted part of the way into the diffusion and
denoised back (:func:`physmotion.diffusion.refine.refine`), with physics guidance on a BioMoDiffuse model."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

from physmotion.conventions import FPS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.refine import RefineConfig, check_motion, refine
from physmotion.motion import Motion, joined_licence_tag


@dataclass
class RefineResult:
    motion: Motion  # the refined motion at the model's 20 fps, with the input's and the model's licence tags
    settings: dict = field(default_factory=dict)


class RefinePipeline:
    """A motion in, the refined motion out; ``config.check()`` runs at construction."""

    def __init__(self, model: MotionDiffusion, config: RefineConfig | None = None) -> None:
        self.model, self.config = model, config or RefineConfig()
        self.config.check()

    def check(self, motion: Motion) -> None:
        """Raise (one line) for a motion refine cannot take: NaN, wrong shape, length out of range."""
        check_motion(motion.joints, motion.fps, self.model)

    def __call__(self, motion: Motion) -> RefineResult:
        self.check(motion)
        joints = refine(self.model, motion.joints, motion.fps, self.config)
        # every restriction of the input's and of the model's data travels (NC, SA: joined "NC,SA")
        licence = joined_licence_tag([motion.licence_tag, self.model.licence_tag])
        texts = list(motion.texts) or ([self.config.text] if self.config.text else [])
        out = Motion(joints=joints, fps=FPS, texts=texts, licence_tag=licence, source=motion.source)
        return RefineResult(out, {"pipeline": type(self).__name__, "refine": asdict(self.config)})
