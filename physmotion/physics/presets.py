"""P's presets by name: every :class:`ProjectionConfig` that a command, a test or an experiment uses.

``preset("sampling")`` is generation's P (:meth:`ProjectionConfig.sampling`, the one source of its
settings), ``preset("plain")`` the plain projection of ``physmotion project`` and Morph's imitation
selection. The ``tracker_v01*`` and ``plain_held_residual`` presets rebuild the tracker as it was before
the changes for dynamic motion, one change at a time (``experiments/projection_dynamic.py`` measures them;
docs/decisions/projection.md has each change). Experiments record the names they used in their
results' ``meta``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from physmotion.errors import PhysmotionError
from physmotion.physics.projection import ProjectionConfig


def plain() -> ProjectionConfig:
    """The plain projection (``ProjectionConfig()``): no reset, Morph's imitation selection at 0.5 m."""
    return ProjectionConfig()


def sampling() -> ProjectionConfig:
    """Generation's P (``ProjectionConfig.sampling()``): a fall past 0.15 m puts the humanoid back on the
    motion and counts a reset."""
    return ProjectionConfig.sampling()


def fine() -> ProjectionConfig:
    """The plain projection at half the simulation step, 1/720 s (``project --fine-step``)."""
    return ProjectionConfig().at_fine_step()


def sampling_fine() -> ProjectionConfig:
    """Generation's P at 1/720 s (``generate --fine-step``)."""
    return ProjectionConfig.sampling().at_fine_step()


def ilc() -> ProjectionConfig:
    """The plain projection with two passes of iterative learning control (``project --ilc 2``)."""
    return ProjectionConfig(ilc_passes=2)


def plain_held_residual() -> ProjectionConfig:
    """The plain projection with the root residual as it was before docs/decisions/projection.md "residual
    within 0.1 W on walks and runs": bounded at 0.3 W, held over 4 simulation steps, the feet's fit
    weighting torque as force."""
    base = ProjectionConfig()
    return replace(base, humanoid=replace(base.humanoid, residual_every=4),
                   tracking=replace(base.tracking, residual_force=0.3, feet_torque_weight=1.0))  # fmt: skip


def tracker_v01() -> ProjectionConfig:
    """The model-based tracker as it was first: :func:`plain_held_residual` without feet balance, toe-off
    flattening or ballistic flight (the residual carries the whole root wrench)."""
    held = plain_held_residual()
    return replace(held, tracking=replace(held.tracking, feet_balance=False),
                   shaping=replace(held.shaping, ballistic_flight=False, flatten_toe_off=False))  # fmt: skip


def tracker_v01_toe_off() -> ProjectionConfig:
    """:func:`tracker_v01` with the toe push-off flattened before a flight."""
    v01 = tracker_v01()
    return replace(v01, shaping=replace(v01.shaping, flatten_toe_off=True))


def tracker_v01_feet_balance() -> ProjectionConfig:
    """:func:`tracker_v01` with the root wrench carried by the feet that touch the floor."""
    v01 = tracker_v01()
    return replace(v01, tracking=replace(v01.tracking, feet_balance=True))


def tracker_v01_toe_off_feet_balance() -> ProjectionConfig:
    """:func:`tracker_v01` with both: toe-off flattening and feet balance (no ballistic flight yet)."""
    held = plain_held_residual()
    return replace(held, shaping=replace(held.shaping, ballistic_flight=False))


PRESETS: dict[str, Callable[[], ProjectionConfig]] = {
    fn.__name__: fn
    for fn in (plain, sampling, fine, sampling_fine, ilc, plain_held_residual, tracker_v01, tracker_v01_toe_off,
               tracker_v01_feet_balance, tracker_v01_toe_off_feet_balance)
}  # fmt: skip


def preset_names() -> tuple[str, ...]:
    """Every preset's name, in the registry's order."""
    return tuple(PRESETS)


def preset(name: str) -> ProjectionConfig:
    """A fresh :class:`ProjectionConfig` of the preset called ``name``."""
    if name not in PRESETS:
        raise PhysmotionError(f"unknown projection preset {name!r}; known: {', '.join(PRESETS)}")
    return PRESETS[name]()


def describe(name: str) -> str:
    """The first line of the preset's description."""
    preset(name)  # a bad name fails with the list of known ones
    return " ".join((PRESETS[name].__doc__ or "").split("\n\n")[0].split())
