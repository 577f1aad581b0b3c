"""Text in, physically plausible motion out: the product's main job, behind ``physmotion generate``.

``physics`` picks how physics enters:
- ``none``: plain diffusion sampling;
- ``physdiff``: PhysDiff's Algorithm 2, the projection P at the steps of ``schedule`` (default
  ``end:4,space:1`` of 50 DDIM steps, the paper's choice);
- ``post``: the post-processing baseline, ``post_projections`` applications of P after sampling.
"""

from __future__ import annotations

import json
import re
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS, MIN_FRAMES
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import (
    DEFAULT_SCHEDULE,
    FeatureProjector,
    ProjectionLog,
    on_data_floor,
    parse_schedule,
    reset_settings,
    sampling_projection,
)
from physmotion.diffusion.samplers import SamplerConfig, sample
from physmotion.errors import PhysmotionError
from physmotion.features.humanml3d import recover_from_ric
from physmotion.motion import Motion, write_atomic
from physmotion.physics.projection import ProjectionConfig

PHYSICS = ("physdiff", "post", "none")
MAX_TEXT_CHARS = 500


@dataclass
class GenerateConfig:
    """Options of one generation run."""

    seconds: float = 6.0
    num: int = 1  # samples per text
    physics: str = "physdiff"
    schedule: str = DEFAULT_SCHEDULE
    post_projections: int = 1
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    seed: int = 0
    projection: ProjectionConfig = field(default_factory=sampling_projection)  # P for physdiff and post


@dataclass
class GenerateResult:
    motions: list[Motion]  # len(texts) * num, text-major
    features: list[np.ndarray]  # (T, 263) un-normalised, one per motion
    projections: ProjectionLog

    @property
    def bodies(self) -> list[np.ndarray | None]:
        """Per motion, the humanoid body (22, 3) whose simulation the output is (``Motion.humanoid``), or
        None where the output is not P's (physics none, or no projection at the last step)."""
        return [m.humanoid for m in self.motions]


def check_request(texts: Sequence[str], config: GenerateConfig, model: MotionDiffusion) -> int:
    """Validate the request before any work; returns the number of frames."""
    if not texts:
        raise PhysmotionError("no text given")
    for t in texts:
        if not isinstance(t, str) or not t.strip():
            raise PhysmotionError("text is empty: describe a motion, e.g. 'a person walks forward'")
        if len(t) > MAX_TEXT_CHARS:
            raise PhysmotionError(f"text is {len(t)} characters long; the limit is {MAX_TEXT_CHARS}")
    if config.physics not in PHYSICS:
        raise PhysmotionError(f"unknown physics mode {config.physics!r}: choose one of {', '.join(PHYSICS)}")
    lo, hi = MIN_FRAMES / FPS, model.denoiser.max_frames / FPS
    if not np.isfinite(config.seconds) or not lo <= config.seconds <= hi:
        raise PhysmotionError(f"--seconds must be between {lo:g} and {hi:g} (the model's range), got {config.seconds:g}")
    if not 1 <= config.num <= 256:
        raise PhysmotionError(f"--num must be between 1 and 256, got {config.num}")
    if config.physics == "post" and not 1 <= config.post_projections <= 50:
        raise PhysmotionError(f"post projections must be between 1 and 50, got {config.post_projections}")
    config.sampler.check()
    if config.physics == "physdiff":
        parse_schedule(config.schedule, config.sampler.steps)
    return round(config.seconds * FPS)


def generate(
    texts: Sequence[str],
    config: GenerateConfig | None = None,
    model: MotionDiffusion | None = None,
    on_step: Callable[[int, int], None] | None = None,
    lengths: Sequence[int] | None = None,
) -> GenerateResult:
    """Generate ``config.num`` motions per text. Deterministic under ``config.seed``.

    lengths: frames per text (evaluation matches the test motions' lengths); default ``config.seconds``.
    """
    cfg = config or GenerateConfig()
    model = model or MotionDiffusion.load()
    frames = check_request(texts, cfg, model)
    if lengths is None:
        lengths = [frames] * len(texts)
    elif len(lengths) != len(texts) or not all(MIN_FRAMES // 2 <= n <= model.denoiser.max_frames for n in lengths):
        raise PhysmotionError(f"give one length per text, each {MIN_FRAMES // 2}..{model.denoiser.max_frames} frames")
    prompts = [t.strip() for t in texts for _ in range(cfg.num)]
    lengths = [int(n) for n in lengths for _ in range(cfg.num)]
    projector = FeatureProjector(model, cfg.projection)
    hook_steps = parse_schedule(cfg.schedule, cfg.sampler.steps) if cfg.physics == "physdiff" else []
    total = cfg.sampler.steps + (cfg.post_projections if cfg.physics == "post" else 0)
    report = (lambda i, n: on_step(i, total)) if on_step else None
    x = sample(model, prompts, lengths, cfg.sampler, seed=cfg.seed,
               hook=projector if hook_steps else None, hook_steps=hook_steps, on_step=report)  # fmt: skip
    feats = model.normalizer.denormalize(x.float().cpu().numpy())
    feats = [f[:n] for f, n in zip(feats, lengths)]
    joints = [recover_from_ric(f.astype(np.float64)) for f in feats]
    bodies: list[np.ndarray | None] = [None] * len(joints)
    if cfg.physics == "physdiff" and hook_steps[-1:] == [cfg.sampler.steps - 1]:
        # The last step was projected, and DDIM's last step returns x0 itself: the output is P's
        # simulated motion, kept in physical coordinates (soles on the floor) rather than re-floored.
        joints, bodies = projector.last_joints, list(projector.last_bodies)
    if cfg.physics == "post":
        for k in range(cfg.post_projections):
            joints = projector.project_joints([on_data_floor(j) if k else j for j in joints])
            bodies = list(projector.last_bodies)
            if on_step:
                on_step(cfg.sampler.steps + k + 1, total)
    motions = [
        Motion(joints=j, fps=FPS, texts=[p], licence_tag=model.licence_tag,
               source=f"physmotion generate ({cfg.physics})", humanoid=b)
        for j, p, b in zip(joints, prompts, bodies)
    ]
    return GenerateResult(motions=motions, features=list(feats), projections=projector.log)


def slug(text: str, limit: int = 40) -> str:
    """A file-name stem from a caption: lower case, words joined by '_'."""
    return re.sub(r"[^a-z0-9]+", "_", text.lower()).strip("_")[:limit].rstrip("_") or "motion"


def write_outputs(result: GenerateResult, out: str | Path, config: GenerateConfig, preview: bool = True) -> list[Path]:
    """Write .npz, .bvh and (optionally) a .gif preview per motion, plus ``generate.json``; returns the paths.

    Every file is written atomically, so an interrupted run leaves only whole files.
    """
    from physmotion.io.export import save_bvh
    from physmotion.render import save_gif

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    counts: dict[str, int] = {}
    for motion in result.motions:
        stem = slug(motion.texts[0])
        k = counts[stem] = counts.get(stem, -1) + 1
        base = out / f"{stem}_{k:02d}"
        motion.save(base.with_suffix(".npz"))
        save_bvh(motion, base.with_suffix(".bvh"))
        written += [base.with_suffix(".npz"), base.with_suffix(".bvh")]
        if preview:
            save_gif(base.with_suffix(".gif"), motion.joints, motion.fps, title=motion.texts[0])
            written.append(base.with_suffix(".gif"))
    log = result.projections
    settings = asdict(config)
    settings["projection"] = reset_settings(config.projection)
    summary = {
        "config": settings,
        "files": [p.name for p in written],
        "licence_tag": result.motions[0].licence_tag if result.motions else "",
        "projections": {"calls": log.calls, "projected": len(log.selected), "without_fall": int(sum(log.tracked))},
    }
    write_atomic(out / "generate.json", lambda f: f.write(json.dumps(summary, indent=2)), "w")
    return written
