"""Where imported motion meets the floor: Penetrate after import per source, and the export -> import
round trip, on every clip of the given collections (docs/decisions/data.md "import floor").

Usage: python -m experiments.import_floor [--source ../shared/data/mocap --source ../shared/data/hdm05]
       [--round-trip-every N] [--out results/import_floor]
Per source: clips, Penetrate / Float / Skate (mm, the metrics' own measure: ``physmotion metrics``'s humanoid
surface on the saved float32 joints) mean and max, clips at or over 2 mm, clips the Penetrate cap raised;
the joint-only surface's Penetrate beside it. Round trip: every N-th clip of each source (N = 1: all)
exported to BVH and imported again, largest joint distance over all frames. Writes ``<out>.md`` and
``<out>.json``; no projection (the meta's preset is null).
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, run_meta, write_results
from physmotion.io import import_clip, import_clip_with_report, load_manifest, save_bvh
from physmotion.metrics import physical_metrics
from physmotion.physics.surface import HumanoidSurface

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", type=Path, action="append", default=None)
    parser.add_argument("--round-trip-every", type=int, default=1)
    parser.add_argument("--out", default="results/import_floor", help="writes OUT.md and OUT.json")
    args = parser.parse_args(argv)
    sources = args.source or [REPO / ".." / "shared" / "data" / "mocap", REPO / ".." / "shared" / "data" / "hdm05"]
    rows: dict[str, list[dict[str, float]]] = defaultdict(list)
    trip: dict[str, list[float]] = defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for folder in sources:
            for info in load_manifest(folder):
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    motion, report = import_clip_with_report(info)
                joints = motion.joints.astype(np.float64)  # what `physmotion metrics` reads back
                m = physical_metrics(joints, fps=motion.fps, body=HumanoidSurface())
                light = physical_metrics(joints, fps=motion.fps)
                rows[info.source].append({
                    "penetrate": m["penetrate"], "float": m["float"], "skate": m["skate"],
                    "penetrate_joints": light["penetrate"], "capped": float(report.grounding.capped),
                    "lift_mm": 1000 * report.grounding.lift,
                })  # fmt: skip
                if (len(rows[info.source]) - 1) % args.round_trip_every == 0:  # each source's 1st, N+1th, ...
                    path = Path(tmp) / "x.bvh"
                    save_bvh(motion, path)
                    back = import_clip(path, rig="smpl22")
                    trip[info.source].append(float(np.linalg.norm(back.joints - motion.joints, axis=-1).max()))
    summary = {}
    table = []
    for source, values in rows.items():
        v = {key: np.array([r[key] for r in values]) for key in values[0]}
        t = np.array(trip[source]) * 1000
        summary[source] = {
            "clips": len(values), "penetrate_mean": v["penetrate"].mean(), "penetrate_max": v["penetrate"].max(),
            "over_2mm": int((v["penetrate"] >= 2).sum()), "capped": int(v["capped"].sum()),
            "float_mean": v["float"].mean(), "skate_mean": v["skate"].mean(),
            "penetrate_joints_mean": v["penetrate_joints"].mean(), "round_trip_max_mm": t.max(),
            "round_trip_clips": len(t),
        }  # fmt: skip
        s = {k: float(x) if isinstance(x, np.floating) else x for k, x in summary[source].items()}
        summary[source] = s
        table.append((source, s["clips"], f"{s['penetrate_mean']:.2f} / {s['penetrate_max']:.2f}", s["over_2mm"],
                      s["capped"], f"{s['float_mean']:.1f}", f"{s['skate_mean']:.1f}",
                      f"{s['penetrate_joints_mean']:.2f}", f"{s['round_trip_max_mm']:.4f}, {s['round_trip_clips']}"))
    header = ("source", "clips", "Penetrate mean / max (mm)", "clips >= 2 mm", "capped", "Float", "Skate",
              "Penetrate, joint surface", "round trip max (mm), clips")  # fmt: skip
    md = "# Where imported motion meets the floor\n\n" + markdown_table(header, table) + "\n"
    print(md)
    meta = run_meta(__file__, argv, None, sources=[str(s) for s in sources], round_trip_every=args.round_trip_every)
    write_results(args.out, md, {"meta": meta, "sources": summary})

if __name__ == "__main__":
    main()
