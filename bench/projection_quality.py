"""Physics projection on every captured clip of the bundled mocap, by category of motion: one table.

Usage: python bench/projection_quality.py [--mocap ../shared/data/mocap] [--limit N] [--walks-runs] [--ilc N]
       [--fine-step]
One row per category (jump, kick, dance, run, turn, walk, other; from the captions), then "walks+runs"
(the 203 walking/running clips of earlier figures) and "all": success (no MPJPE past 0.5 m), MPJPE, the
physical metrics of input -> simulation (both on the clip's humanoid geometry, the input grounded on it:
the metrics' floor convention), airborne share of frames (no foot patch within 2 cm of the floor) of input
-> simulation, and the root residual used (force x W, torque x W m; mean and 95th percentile over frames).
scripts/projection_dynamic.py writes the same rows for each configuration into results/.
"""

from __future__ import annotations

import argparse
import time

from rich.console import Console
from rich.table import Table

from physmotion.eval.projection_quality import LOCOMOTION, by_category, measure_clips
from physmotion.io.importer import load_manifest
from physmotion.physics.projection import ProjectionConfig


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--limit", type=int, default=0, help="only the first N clips")
    parser.add_argument("--walks-runs", action="store_true", help="only the walking/running clips")
    parser.add_argument("--ilc", type=int, default=0, help="iterative learning control passes (project --ilc)")
    parser.add_argument("--fine-step", action="store_true", help="simulate at 1/720 s (project --fine-step)")
    args = parser.parse_args()
    clips = load_manifest(args.mocap)
    if args.walks_runs:
        clips = [c for c in clips if LOCOMOTION.search(c.captions[0].lower())]
    clips = clips[: args.limit] if args.limit else clips
    start = time.perf_counter()
    config = ProjectionConfig(ilc_passes=args.ilc)
    config = config.at_fine_step() if args.fine_step else config
    measured = measure_clips(clips, config)  # one worker process per core
    seconds = time.perf_counter() - start
    rows = by_category(clips, measured)
    failed = [c.clip for c, m in zip(clips, measured) if not m.result.success]

    options = (f", ILC {args.ilc} passes" if args.ilc else "") + (", 1/720 s steps" if args.fine_step else "")
    table = Table(title=f"projection of {len(clips)} captured clips by category{options} ({seconds:.0f} s)",
                  caption=f"failed: {', '.join(failed) or '-'}")  # fmt: skip
    for col in ("category", "clips", "success", "MPJPE mm", "Penetrate", "Float", "Skate", "Phys-Err",
                "airborne", "residual F (W)", "residual τ (W m)"):  # fmt: skip
        table.add_column(col, justify="left" if col == "category" else "right")
    for name, r in rows.items():
        table.add_row(
            name, str(r["clips"]), f"{100 * r['success']:.1f} %", f"{r['mpjpe_mm']:.1f}",
            *(f"{r[k + '_in']:.2f} → {r[k + '_out']:.2f}" for k in ("penetrate", "float", "skate", "phys_err")),
            f"{100 * r['airborne_in']:.0f} → {100 * r['airborne_out']:.0f} %",
            f"{r['residual_force_mean']:.3f} / {r['residual_force_p95']:.2f}",
            f"{r['residual_torque_mean']:.3f} / {r['residual_torque_p95']:.2f}",
        )  # fmt: skip
    Console(width=200).print(table)


if __name__ == "__main__":
    main()
