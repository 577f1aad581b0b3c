"""PhysDiff's Fig. 4 on our data: the number of projection steps against FID, R-Precision and Phys-Err.

    python -m experiments.schedule_study --data data_build/mocap [--motions 32] [--out results/schedule_study]

writes <out>.md, <out>.json (with the run's meta block) and <out>.png. As in the paper (section 5.3, "Number of Projection Steps"), the projection steps are removed from the
earliest timesteps first and kept consecutive at the end: N projections is the schedule
``end:N,space:1`` of the 50 DDIM steps, and N = 0 is plain sampling. Each point is one row of
:func:`~physmotion.eval.table.evaluate`, so the numbers match ``physmotion evaluate`` exactly.
"""

from __future__ import annotations

import argparse
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

from experiments._results import parse_args, report, run_meta
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import ddim_50
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import EvalTable, EvaluateConfig, evaluate
from physmotion.generate import GenerateConfig
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
    cfg = config or EvaluateConfig(repeats=1, base=GenerateConfig(sampler=ddim_50()))
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="HumanML3D-layout folder")
    parser.add_argument("--out", default="results/schedule_study", help="output stem")
    parser.add_argument("--model", default=None, help="model folder (default: the shipped model)")
    parser.add_argument("--evaluator", default=None, help="evaluator folder (default: the shipped one)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--counts", default=",".join(map(str, DEFAULT_COUNTS)), help="projection counts")
    parser.add_argument("--motions", type=int, default=None, help="a seeded subset of the split")
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--steps", type=int, default=50, help="DDIM steps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--plot-only", action="store_true", help="redraw <out>.png from <out>.json")
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        if args.plot_only:
            return "", [plot_study(EvalTable.from_json(f"{args.out}.json"), f"{args.out}.png")]
        counts = [int(c) for c in args.counts.split(",")]
        cfg = EvaluateConfig(split=args.split, repeats=args.repeats, max_motions=args.motions, seed=args.seed,
                             base=GenerateConfig(sampler=ddim_50()))  # fmt: skip
        cfg.base.sampler.steps = args.steps
        table = schedule_study(MotionDiffusion.load(args.model), Evaluator.load(args.evaluator), args.data,
                               counts, cfg)  # fmt: skip
        # EvaluateConfig's base: generation's P
        table.meta.update(run_meta(__file__, argv, args.tree, "sampling"))
        return table.to_markdown(), write_study(table, args.out)

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
