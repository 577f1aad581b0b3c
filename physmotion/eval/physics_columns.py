"""Generation modes side by side (``none``, ``none+floor``, ``post:K``, ``physdiff:<schedule>``, ``morph``: see
:mod:`physmotion.physics_mode`), with physical metrics."""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from physmotion.conventions import FPS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.generate import GenerateConfig, GenerateResult, generate
from physmotion.metrics import physical_metrics
from physmotion.physics_mode import PhysicsMode


def reset_columns(results: Sequence[GenerateResult]) -> dict[str, float]:
    """What the falls did to the outputs of projecting modes: ``reset_rate``, the share of output motions
    whose projection put the humanoid back at least once (error past tau, 0.15 m in generation), and
    ``resets``, the mean number of such jumps per output motion. Empty for modes without P's output."""
    counts = [m.resets for r in results for m in r.motions if m.resets is not None]
    if not counts:
        return {}
    return {"reset_rate": float(np.mean([c > 0 for c in counts])), "resets": float(np.mean(counts))}


def imitation_columns(results: Sequence[GenerateResult]) -> dict[str, float]:
    """Morph's ``imitation_failure_rate`` (Sec. 4, IFR): the share of output motions of the ``morph`` mode
    whose imitation failed, so that the sampled motion was kept. Empty for the other modes."""
    failed = [f for r in results for f in r.imitation_failed]
    return {"imitation_failure_rate": float(np.mean(failed))} if failed else {}


def metric_surface(name: str, bodies: Sequence[np.ndarray | None] | None = None):
    """The body surface of the physical metrics by name: "humanoid" (its geometry, posed with P's body
    where ``bodies`` gives one, e.g. ``GenerateResult.bodies``, else with one estimated from the joints)
    or "joints" (None: the joint-only surface model)."""
    if name == "humanoid":
        from physmotion.physics.surface import HumanoidSurface

        return HumanoidSurface(bodies)
    if name == "joints":
        return None
    raise PhysmotionError(f"unknown surface {name!r}: humanoid or joints")


def compare_modes(
    model: MotionDiffusion,
    prompts: Sequence[str],
    modes: Sequence[str | PhysicsMode],
    base: GenerateConfig | None = None,
    surface: str = "humanoid",
) -> dict[str, dict[str, float]]:
    """Generate one motion per prompt in each mode; mode spelling -> physical metrics (mean over
    motions) plus ``seconds_per_motion``, ``tracked`` (fraction of all projections, PhysDiff's four per
    motion included, in which the humanoid never fell), :func:`reset_columns` and
    :func:`imitation_columns`.

    surface "humanoid": the humanoid's geometry, with the body P simulated for projected outputs and one
    estimated from the joints otherwise; "joints": the joint-only surface model."""
    base = base or GenerateConfig()
    metric_surface(surface)  # a bad name fails before any work
    results: dict[str, dict[str, float]] = {}
    for mode in [PhysicsMode.parse(m) for m in modes]:
        cfg = replace(base, physics=mode)
        start = time.perf_counter()
        out = generate(list(prompts), cfg, model)
        seconds = time.perf_counter() - start
        joints = np.stack([m.joints for m in out.motions])
        row = physical_metrics(joints, FPS, body=metric_surface(surface, out.bodies))
        row["seconds_per_motion"] = seconds / len(prompts)
        log = out.projections
        row["tracked"] = float(np.mean(log.tracked)) if log.tracked else float("nan")
        row.update(reset_columns([out]))
        row.update(imitation_columns([out]))
        results[str(mode)] = row
    return results
