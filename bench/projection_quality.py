"""Physics projection on every walking and running clip of the bundled mocap: one table.

Usage: python bench/projection_quality.py [--mocap ../shared/data/mocap] [--limit N]
Prints success rate, MPJPE, residual used and the physical metrics of input and output, both measured
on the humanoid's collision geometry (the input grounded on it: the metrics' floor convention).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from rich.console import Console
from rich.table import Table

from physmotion.eval.projection_quality import locomotion_clips, measure_clips
from physmotion.physics.projection import ProjectionConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--limit", type=int, default=0)
    args = parser.parse_args()
    clips = locomotion_clips(args.mocap)
    clips = clips[: args.limit] if args.limit else clips
    start = time.perf_counter()
    measured = measure_clips(clips, ProjectionConfig())  # one worker process per core
    rows = [(info, m.result, m.before, m.after) for info, m in zip(clips, measured)]
    seconds = time.perf_counter() - start

    ok = [r for r in rows if r[1].success]
    def mean(key: str, which: int, subset=rows) -> float:
        return float(np.mean([r[which][key] for r in subset])) if subset else float("nan")

    table = Table(title=f"projection of {len(rows)} walking/running clips ({seconds:.0f} s)")
    for col in ("measure", "value"):
        table.add_column(col)
    table.add_row("success (no MPJPE > 0.5 m)", f"{len(ok)}/{len(rows)} = {100 * len(ok) / len(rows):.1f} %")
    table.add_row("MPJPE mean, successful clips (mm)",
                  f"{1000 * np.mean([r[1].mpjpe.mean() for r in ok]):.1f}")
    table.add_row("MPJPE median over clips, all clips (mm)",
                  f"{1000 * np.median([r[1].mpjpe.mean() for r in rows]):.1f}")
    table.add_row("residual force used, mean / p95 (x W)",
                  f"{np.mean([r[1].residual_force.mean() for r in rows]):.3f} / "
                  f"{np.percentile(np.concatenate([r[1].residual_force for r in rows]), 95):.3f}")
    for key in ("penetrate", "float", "skate", "phys_err"):
        table.add_row(f"{key} input -> simulated, successful clips (mm)",
                      f"{mean(key, 2, ok):.2f} -> {mean(key, 3, ok):.2f}")
    by_source: dict[str, list[bool]] = {}
    for info, out, _, _ in rows:
        by_source.setdefault(info.source, []).append(bool(out.success))
    table.add_row("success by source", ", ".join(f"{s} {sum(v)}/{len(v)}" for s, v in by_source.items()))
    table.add_row("failed clips", ", ".join(r[0].clip for r in rows if not r[1].success) or "-")
    Console(width=160).print(table)


if __name__ == "__main__":
    main()
