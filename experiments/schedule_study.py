"""PhysDiff's Fig. 4 on our data: the number of projection steps against FID, R-Precision and Phys-Err.

As in the paper (section 5.3, "Number of Projection Steps"), the projection steps are removed from the
earliest timesteps first and kept consecutive at the end: N projections is the schedule
``end:N,space:1`` of the 50 DDIM steps, and N = 0 is plain sampling. Each point is one row of
:func:`~physmotion.eval.table.evaluate`, so the numbers match ``physmotion evaluate`` exactly.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from physmotion.diffusion.model import MotionDiffusion
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import EvalTable, EvaluateConfig, evaluate
from physmotion.motion import write_atomic

DEFAULT_COUNTS = (0, 1, 2, 4, 8, 20, 50)
PLOTTED = (("FID", "FID ↓"), ("R@3", "R-Precision (top 3) ↑"), ("phys_err", "Phys-Err (mm) ↓"))


def mode_for(count: int) -> str:
    """The generation mode with ``count`` consecutive projections at the end of sampling."""
    return "none" if count == 0 else f"physdiff:end:{count},space:1"


def schedule_study(
    model: MotionDiffusion,
    evaluator: Evaluator,
    data: str | Path,
    counts: Sequence[int] = DEFAULT_COUNTS,
    config: EvaluateConfig | None = None,
    on_progress: Callable[[int, int], None] | None = None,
) -> EvalTable:
    """One table row per projection count (rows named by the count), plus the real-data row."""
    cfg = config or EvaluateConfig(repeats=1)
    steps = cfg.base.sampler.steps
    if not counts or any(not 0 <= n <= steps for n in counts):
        raise PhysmotionError(f"projection counts must lie in 0..{steps} (the sampling steps), got {list(counts)}")
    table = evaluate(model, evaluator, data, replace(cfg, modes=tuple(mode_for(n) for n in counts)), on_progress)
    rows = {"real": table.rows["real"]} | {str(n): table.rows[mode_for(n)] for n in counts}
    return EvalTable(rows=rows, meta={**table.meta, "study": "projection steps (end:N,space:1)"})


def plot_study(table: EvalTable, path: str | Path) -> Path:
    """Three panels as in PhysDiff's Fig. 4, each metric against the number of projection steps; a PNG."""
    try:
        import matplotlib

        matplotlib.use("Agg")  # files only: no display on a server
        import matplotlib.pyplot as plt
    except ImportError:
        raise PhysmotionError("the plot needs matplotlib: pip install 'physmotion[plot]'") from None
    counts = [int(k) for k in table.rows if k != "real"]
    fig, axes = plt.subplots(1, len(PLOTTED), figsize=(4 * len(PLOTTED), 3.2))
    for ax, (key, label) in zip(axes, PLOTTED, strict=True):
        means = [table.rows[str(n)][key][0] for n in counts]
        half = [table.rows[str(n)][key][1] for n in counts]
        ax.errorbar(counts, means, yerr=half, marker="o", capsize=3)
        if key in table.rows["real"]:
            ax.axhline(table.rows["real"][key][0], color="grey", linestyle="--", label="real data")
            ax.legend(fontsize=8)
        ax.set_xscale("symlog", linthresh=1)  # 0 and 50 on one axis
        ax.set_xlim(-0.3, max(counts) * 1.3)
        ax.set_xticks(counts, [str(n) for n in counts])
        ax.set_xlabel(f"projection steps (of {table.meta['sampler']['steps']})")
        ax.set_title(label)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(path, lambda f: fig.savefig(f, format="png", dpi=120))
    plt.close(fig)
    return path


def write_study(table: EvalTable, stem: str | Path) -> list[Path]:
    """``<stem>.md``, ``<stem>.json`` and ``<stem>.png``."""
    paths = table.write(stem)
    paths.append(plot_study(table, Path(stem).with_suffix(".png")))
    return paths
