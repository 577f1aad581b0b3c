"""Text in, physically plausible motion out: the product's main job, behind ``physmotion generate``.

``GenerateConfig.physics`` (a :class:`~physmotion.physics_mode.PhysicsMode`, or its spelling) picks how
physics enters: ``none``, ``none+floor``, ``post[:K]`` or ``physdiff[:SCHEDULE]`` (the default, PhysDiff's
``end:4,space:1`` of 50 DDIM steps).

P in generation is :meth:`ProjectionConfig.sampling`: where the humanoid falls (its error passes 0.15 m)
it is put back on the motion and the simulation goes on (reset-on-fail), so the output is always the
simulation and never the kinematic input; Morph's imitation selection (keep the input when the
imitation fails) is not applied here. Every reset is a jump in the output and is counted
(``GenerateResult.resets``, ``generate.json``).
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
from physmotion.diffusion.physdiff import FeatureProjector, ProjectionLog, on_data_floor, reset_settings
from physmotion.diffusion.samplers import SamplerConfig, sample
from physmotion.errors import PhysmotionError
from physmotion.features.humanml3d import recover_from_ric
from physmotion.motion import Motion, write_atomic
from physmotion.physics.projection import ProjectionConfig
from physmotion.physics_mode import FLOOR, PHYSDIFF, POST, PhysicsMode

MAX_TEXT_CHARS = 500


@dataclass
class GenerateConfig:
    """Options of one generation run; ``physics`` also takes a spelling such as ``"post:4"``."""

    seconds: float = 6.0
    num: int = 1  # samples per text
    physics: PhysicsMode = field(default_factory=PhysicsMode)
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    seed: int = 0
    projection: ProjectionConfig = field(default_factory=ProjectionConfig.sampling)  # P for physdiff and post

    def __post_init__(self) -> None:
        self.physics = PhysicsMode.parse(self.physics)


@dataclass
class GenerateResult:
    motions: list[Motion]  # len(texts) * num, text-major
    features: list[np.ndarray]  # (T, 263) un-normalised, one per motion
    projections: ProjectionLog
    resets: list[int] = field(default_factory=list)  # per motion: resets in the projection it came from

    @property
    def bodies(self) -> list[np.ndarray | None]:
        """Per motion, the humanoid body (22, 3) whose simulation (or surface, for none+floor) the output
        is (``Motion.humanoid``), or None where the output was not put on a body (none; physdiff without
        a projection at the last step)."""
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
    lo, hi = MIN_FRAMES / FPS, model.denoiser.max_frames / FPS
    if not np.isfinite(config.seconds) or not lo <= config.seconds <= hi:
        raise PhysmotionError(f"--seconds must be between {lo:g} and {hi:g} (the model's range), got {config.seconds:g}")
    if not 1 <= config.num <= 256:
        raise PhysmotionError(f"--num must be between 1 and 256, got {config.num}")
    config.sampler.check()
    config.physics.hook_steps(config.sampler.steps)
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
    mode = cfg.physics
    projector = FeatureProjector(model, cfg.projection)
    hook_steps = mode.hook_steps(cfg.sampler.steps)
    total = cfg.sampler.steps + mode.projections
    report = (lambda i, n: on_step(i, total)) if on_step else None
    x = sample(model, prompts, lengths, cfg.sampler, seed=cfg.seed,
               hook=projector if hook_steps else None, hook_steps=hook_steps, on_step=report)  # fmt: skip
    feats = model.normalizer.denormalize(x.float().cpu().numpy())
    feats = [f[:n] for f, n in zip(feats, lengths)]
    joints = [recover_from_ric(f.astype(np.float64)) for f in feats]
    bodies: list[np.ndarray | None] = [None] * len(joints)
    resets = [0] * len(joints)
    if mode.kind == PHYSDIFF and hook_steps[-1:] == [cfg.sampler.steps - 1]:
        # The last step was projected, and DDIM's last step returns x0 itself: the output is P's
        # simulated motion, kept in physical coordinates (soles on the floor) rather than re-floored.
        joints, bodies, resets = projector.last_joints, list(projector.last_bodies), projector.last_resets
    if mode.kind == POST:
        for k in range(mode.projections):
            joints = projector.project_joints([on_data_floor(j) if k else j for j in joints])
            bodies, resets = list(projector.last_bodies), projector.last_resets
            if on_step:
                on_step(cfg.sampler.steps + k + 1, total)
    if mode.kind == FLOOR:
        from physmotion.physics.surface import ground_on_surface

        joints, bodies = (list(z) for z in zip(*(ground_on_surface(j) for j in joints)))
    motions = [
        Motion(joints=j, fps=FPS, texts=[p], licence_tag=model.licence_tag,
               source=f"physmotion generate ({mode})", humanoid=b,
               resets=r if mode.projects and b is not None else None)
        for j, p, b, r in zip(joints, prompts, bodies, resets)
    ]
    return GenerateResult(motions=motions, features=list(feats), projections=projector.log,
                          resets=list(resets))


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
    settings["physics"] = str(config.physics)
    settings["projection"] = reset_settings(config.projection)
    summary = {
        "config": settings,
        "files": [p.name for p in written],
        "licence_tag": result.motions[0].licence_tag if result.motions else "",
        "projections": {"calls": log.calls, "projected": len(log.selected), "without_fall": int(sum(log.tracked)),
                        "resets_total": int(sum(log.resets))},
        "resets_per_motion": dict(zip([p.name for p in written if p.suffix == ".npz"], result.resets)),
    }
    write_atomic(out / "generate.json", lambda f: f.write(json.dumps(summary, indent=2)), "w")
    return written
