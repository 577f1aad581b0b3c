"""Generation modes side by side: ``none``, ``post:K`` and ``physdiff:<schedule>``, with physical metrics.

A mode string is what ``physmotion generate`` spells with two options: ``post:4`` is ``--physics post
--post-projections 4``; ``physdiff:end:4,space:1`` is ``--physics physdiff --schedule end:4,space:1``.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from physmotion.conventions import FPS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.generate import GenerateConfig, generate
from physmotion.metrics import physical_metrics


def parse_mode(mode: str, base: GenerateConfig) -> GenerateConfig:
    """The generation config of a mode string (see the module docstring)."""
    name, _, arg = mode.partition(":")
    if name == "none" and not arg:
        return replace(base, physics="none")
    if name == "post":
        try:
            return replace(base, physics="post", post_projections=int(arg or 1))
        except ValueError:
            raise PhysmotionError(f"bad mode {mode!r}: post takes a count, e.g. post:4") from None
    if name == "physdiff":
        return replace(base, physics="physdiff", schedule=arg or base.schedule)
    raise PhysmotionError(f"bad mode {mode!r}: use none, post:K or physdiff:<schedule>")


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
    modes: Sequence[str],
    base: GenerateConfig | None = None,
    surface: str = "humanoid",
) -> dict[str, dict[str, float]]:
    """Generate one motion per prompt in each mode; mode -> physical metrics (mean over motions) plus
    ``seconds_per_motion`` and ``tracked`` (fraction of projections in which the humanoid never fell).

    surface "humanoid": the humanoid's geometry, with the body P simulated for projected outputs and one
    estimated from the joints otherwise; "joints": the joint-only surface model."""
    base = base or GenerateConfig()
    metric_surface(surface)  # a bad name fails before any work
    results: dict[str, dict[str, float]] = {}
    for mode in modes:
        cfg = parse_mode(mode, base)
        start = time.perf_counter()
        out = generate(list(prompts), cfg, model)
        seconds = time.perf_counter() - start
        joints = np.stack([m.joints for m in out.motions])
        row = physical_metrics(joints, FPS, body=metric_surface(surface, out.bodies))
        row["seconds_per_motion"] = seconds / len(prompts)
        log = out.projections
        row["tracked"] = float(np.mean(log.tracked)) if log.tracked else float("nan")
        results[mode] = row
    return results
