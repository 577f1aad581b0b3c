"""What physics kept of a sample's dynamics, output against the plain sample of the same request.

Phys-Err alone rewards a jump flattened onto the floor (Float counts flight), and a reset the humanoid
needed shows in no physical metric: these two columns sit next to it (issue 62).

- :func:`flight_kept`: over the requests whose plain sample really leaves the floor (both feet at least
  ``min_flight`` up at once, :func:`~physmotion.metrics.actions.flight_height`), the median of the
  output's flight height over the sample's;
- :func:`step_jumps`: the share of outputs whose fastest joint moves further in one frame than the plain
  sample's fastest does, by more than ``margin``: a teleport (a reset) a viewer would see, or, in
  PhysDiff, a faster motion the denoiser made after an earlier P;
- :func:`jumps_past`: the same against given largest steps, such as those of P's own input.

All joints are (T, 22, 3) metres, Y up, one array per motion, outputs and samples in the same order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from physmotion.metrics.actions import flight_height

MIN_FLIGHT: float = 0.05
"""m: a plain sample whose feet are never both this high at once has no flight to keep."""
STEP_MARGIN: float = 0.02
"""m: an output's largest frame-to-frame joint move may exceed the sample's by this much (issue 62)."""


def largest_step(joints: np.ndarray) -> float:
    """The largest distance any joint moves from one frame to the next, metres."""
    j = np.asarray(joints, dtype=np.float64)
    return float(np.linalg.norm(np.diff(j, axis=0), axis=-1).max()) if len(j) > 1 else 0.0


def flight_ratios(outputs: Sequence[np.ndarray], samples: Sequence[np.ndarray],
                  min_flight: float = MIN_FLIGHT) -> list[float]:  # fmt: skip
    """Output flight over sample flight, for each pair whose sample flies at least ``min_flight``."""
    _check(outputs, samples)
    ratios = []
    for out, sample in zip(outputs, samples):
        base = flight_height(np.asarray(sample, dtype=np.float64))
        if base >= min_flight:
            ratios.append(flight_height(np.asarray(out, dtype=np.float64)) / base)
    return ratios


def flight_kept(outputs: Sequence[np.ndarray], samples: Sequence[np.ndarray],
                min_flight: float = MIN_FLIGHT) -> float | None:  # fmt: skip
    """Median of :func:`flight_ratios`; None where no sample flies."""
    ratios = flight_ratios(outputs, samples, min_flight)
    return float(np.median(ratios)) if ratios else None


def step_jumps(outputs: Sequence[np.ndarray], samples: Sequence[np.ndarray], margin: float = STEP_MARGIN) -> float:
    """Share of outputs whose :func:`largest_step` passes their sample's by more than ``margin``."""
    _check(outputs, samples)
    return jumps_past(outputs, [largest_step(s) for s in samples], margin)


def jumps_past(outputs: Sequence[np.ndarray], steps: Sequence[float], margin: float = STEP_MARGIN) -> float:
    """Share of outputs whose :func:`largest_step` passes the matching ``steps`` (m) by more than ``margin``.

    With the largest steps of what the last P was given (``ProjectionLog.last_input_steps``) this counts
    the jumps P made; against the plain samples (:func:`step_jumps`) it also counts what PhysDiff's
    denoising changed after an earlier P (docs/decisions/sampling.md: "jumps past the sample's: P's or
    the denoiser's").
    """
    if len(outputs) != len(steps):
        raise ValueError(f"{len(outputs)} outputs against {len(steps)} reference steps")
    over = [largest_step(out) > step + margin for out, step in zip(outputs, steps)]
    return float(np.mean(over)) if over else 0.0


def _check(outputs: Sequence[np.ndarray], samples: Sequence[np.ndarray]) -> None:
    if len(outputs) != len(samples):
        raise ValueError(f"{len(outputs)} outputs against {len(samples)} samples: pair them one to one")
