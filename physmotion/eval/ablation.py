"""BioMoDiffuse's ablation (its Tables 3 and 4) and speed-control study (Table 6) on our data.

Rows, as the paper's, each a model trained with the same width, steps, seed and data order
(``scripts/biomodiffuse_table.py`` trains them) and sampled alike (SDE DPM-Solver++, 10 steps, CFG 2.5):

- ``UNet baseline (263-d)``: the 1D UNet on HumanML3D's 263-d features, x0 MSE;
- ``+ L_accel (329-d)``: the same UNet on the 329-d features, L_diffusion + L_accel;
- ``+ PhysNet``: the UNet with the physical network (``arch="biomo"``), trained without P_c dropout and
  sampled with the network on every pass (the paper's row without guidance);
- ``+ PhysNet (P_c 10 %)``: the model of the last row, trained with P_c = 10 % (physics guidance needs
  the dropout), sampled with the network on every pass: what the dropout alone changes;
- ``+ physics guidance``: that model sampled with physics guidance (``phys_scale``).

Every row is measured by
:func:`physmotion.eval.table.evaluate` (mode ``none``: no projection) on the 263-d build's split, so all
rows meet the same real motions, captions and lengths.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import BIOMO_SAMPLER, SamplerConfig
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import REAL, EvaluateConfig, evaluate
from physmotion.generate import GenerateConfig

Row = dict[str, tuple[float, float]]  # metric -> (mean, 95 % half-width)

GENERATION = ("FID", "R@1", "R@2", "R@3", "MM-Dist", "Diversity", "MModality")
PHYSICAL = ("vc", "ac", "speed", "smoothness", "float_ratio", "skate_ratio", "penetrate_ratio", "clip_ratio",
            "phys_err")  # fmt: skip
SPEED_COLUMNS = ("FID", "R@3", "speed", "smoothness", "skate_ratio", "float_ratio")
SPEEDS = (0.5, 0.75, 1.0, 1.25, 1.5)
# The physical metrics "full BioMoDiffuse beats the baseline" is counted on; each metric's own ``better``
# (physmotion.metrics.physical.METRICS) says which way: lower, or closer to the real motions' value.
WIN_COLUMNS = ("vc", "ac", "smoothness", "skate_ratio", "float_ratio", "penetrate_ratio")


@dataclass(frozen=True)
class AblationRow:
    """One row: its label, the training run it samples (a folder name), and its physics guidance."""

    name: str
    run: str
    phys_scale: float | None = None

    def sampler(self) -> SamplerConfig:
        return replace(BIOMO_SAMPLER, phys_scale=self.phys_scale)


ROWS = (
    AblationRow("UNet baseline (263-d)", "unet263"),
    AblationRow("+ L_accel (329-d)", "unet329"),
    AblationRow("+ PhysNet", "biomo_nodrop"),
    AblationRow("+ PhysNet (P_c 10 %)", "biomo"),
    AblationRow("+ physics guidance", "biomo", BIOMO_SAMPLER.phys_scale),
)

RUNS: dict[str, dict] = {  # how each run is trained: its architecture, features and P_c
    "unet263": {"arch": "unet", "features": 263, "phys_drop": 0.0},
    "unet329": {"arch": "unet", "features": 329, "phys_drop": 0.0},
    "biomo_nodrop": {"arch": "biomo", "features": 329, "phys_drop": 0.0},
    "biomo": {"arch": "biomo", "features": 329, "phys_drop": 0.1},
}


def evaluate_row(
    model: MotionDiffusion,
    evaluator: Evaluator,
    data: str | Path,
    sampler: SamplerConfig,
    repeats: int = 3,
    seed: int = 0,
    on_progress: Callable[[int, int], None] | None = None,
    real_row: bool = True,
) -> tuple[Row, Row | None]:
    """(generated row, real row or None) of one model sampled with ``sampler``, no projection, ``repeats``
    runs. The real row does not depend on the model: ask for it once (``real_row``)."""
    cfg = EvaluateConfig(modes=("none",), repeats=repeats, seed=seed, base=GenerateConfig(sampler=sampler),
                         real_row=real_row)  # fmt: skip
    table = evaluate(model, evaluator, data, cfg, on_progress=on_progress)
    return table.rows["none"], table.rows.get(REAL)


def separated(a: Row, b: Row, columns: tuple[str, ...]) -> dict[str, str]:
    """For each column both rows have, ">" or "<" when b's mean lies above or below a's and the two 95 %
    intervals do not overlap, else "~" (within the noise of ``repeats`` runs)."""
    out = {}
    for col in (c for c in columns if c in a and c in b):  # MModality needs 2+ repeats
        (ma, ha), (mb, hb) = a[col], b[col]
        out[col] = ">" if mb - hb > ma + ha else "<" if mb + hb < ma - ha else "~"
    return out


def wins(baseline: Row, row: Row, real: Row, columns: tuple[str, ...] = WIN_COLUMNS) -> list[str]:
    """The columns where ``row`` is better than ``baseline`` beyond both 95 % intervals: lower, or (for
    metrics whose ``better`` is "closer to real") nearer the real row's mean by more than the two
    half-widths."""
    from physmotion.metrics.physical import METRICS

    out = []
    for c in columns:
        (ma, ha), (mb, hb) = baseline[c], row[c]
        if METRICS[c].better == "lower":
            won = mb + hb < ma - ha
        else:
            target = real[c][0]
            won = abs(mb - target) + hb < abs(ma - target) - ha
        if won:
            out.append(c)
    return out


def fmt(value: tuple[float, float]) -> str:
    mean, half = value
    digits = 3 if abs(mean) < 10 else 1
    return f"{mean:.{digits}f} ± {half:.{digits}f}"


def markdown_table(rows: dict[str, Row], columns: tuple[str, ...], first: str = "row") -> str:
    """One Markdown table: a row per entry of ``rows``, "mean ± half-width" per column."""
    lines = ["| " + " | ".join((first, *columns)) + " |", "|" + "---|" * (len(columns) + 1)]
    for name, row in rows.items():
        lines.append("| " + " | ".join((name, *(fmt(row[c]) if c in row else "" for c in columns))) + " |")
    return "\n".join(lines)
