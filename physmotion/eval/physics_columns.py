"""The physics columns of the evaluation tables: what P's falls did (resets), the outside help P's body got
(the root residual), Morph's imitation failures, and the body surface the physical metrics are measured
on."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.generate import GenerateResult
from physmotion.metrics.report import help_stats


def reset_columns(results: Sequence[GenerateResult]) -> dict[str, float]:
    """What the falls did to the outputs of projecting modes: ``reset_rate``, the share of output motions
    whose projection put the humanoid back at least once (error past tau, 0.15 m in generation), and
    ``resets``, the mean number of such jumps per output motion; and ``fell``, the share of all of P's
    projections (PhysDiff's inside sampling too) in which the humanoid fell; ``recovered_rate``, the share of
    output motions in which the search carried the body where it would have been put back
    (``ProjectionConfig.recover``). Empty for modes without P's output."""
    counts = [m.resets for r in results for m in r.motions if m.resets is not None]
    if not counts:
        return {}
    tracked = [t for r in results for t in r.projections.tracked]
    fell = {"fell": 1.0 - float(np.mean(tracked))} if tracked else {}
    recovered = [m.recovered or 0 for r in results for m in r.motions if m.resets is not None]
    return {"reset_rate": float(np.mean([c > 0 for c in counts])), "resets": float(np.mean(counts)),
            "recovered_rate": float(np.mean([c > 0 for c in recovered]))} | fell


def residual_columns(results: Sequence[GenerateResult]) -> dict[str, float]:
    """The help P gave its outputs, over every frame of them (:func:`~physmotion.metrics.report.help_stats`):
    ``residual_force`` and ``residual_force_p95`` (x body weight), ``residual_torque`` and
    ``residual_torque_p95`` (x body weight x 1 m), ``residual_at_cap`` (the share of frames at the force's
    cap) and ``over_limit`` (the share with a joint's torque over its actuator's limit). A motion Morph's
    selection kept as sampled has none. Empty for modes without P's output."""
    return help_stats([m for r in results for m in r.motions])


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
