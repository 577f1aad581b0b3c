"""Where imported motion meets the floor: Penetrate after import per source, and the export -> import
round trip, on every clip of the given collections (docs/decisions/data.md "import floor").

Usage: python -m experiments.import_floor [--source ../shared/data/mocap --source ../shared/data/hdm05]
       [--every N] [--round-trip-every N] [--generated] [--out results/import_floor]
Per source (every N-th clip of each source's manifest, N = 1: all): clips, Penetrate / Float / Skate (mm,
the metrics' own measure: ``physmotion metrics``'s humanoid surface on the saved float32 joints) mean and
max, clips at or over 2 mm; "contact Float": Float over the frames where a foot or hand stands
(:mod:`physmotion.io.floor`), the soles' height over the floor the source stood on; the share of frames
where only a hand touches; the joint-only surface's Penetrate beside it; the clips on ground that is not
level (``physmotion.io.floor.UNEVEN_GROUND``) and Penetrate over the others. Round trip: every N-th of those
clips exported to BVH and imported again, largest joint distance over all frames. ``--generated``: also two
motions of the default model (``generate "a person walks forward" "a person jumps" --seconds 4 --seed 0``,
P's output) exported and imported: mean and max joint distance. Writes ``<out>.md`` and ``<out>.json``.
"""

from __future__ import annotations

import argparse
import tempfile
import warnings
from collections import defaultdict
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.io import import_clip, import_clip_with_report, load_manifest, save_bvh
from physmotion.io.floor import hand_frames, stance_frames
from physmotion.metrics import physical_metrics
from physmotion.physics.surface import HumanoidSurface

REPO = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--source", type=Path, action="append", default=None)
    parser.add_argument("--every", type=int, default=1)
    parser.add_argument("--round-trip-every", type=int, default=1)
    parser.add_argument("--generated", action="store_true")
    parser.add_argument("--out", default="results/import_floor", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    sources = args.source or [REPO / ".." / "shared" / "data" / "mocap", REPO / ".." / "shared" / "data" / "hdm05"]
    rows: dict[str, list[dict[str, float]]] = defaultdict(list)
    trip: dict[str, list[float]] = defaultdict(list)
    with tempfile.TemporaryDirectory() as tmp:
        for folder in sources:
            for info in load_manifest(folder)[:: args.every]:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    motion, report = import_clip_with_report(info)
                joints = motion.joints.astype(np.float64)  # what `physmotion metrics` reads back
                surface = HumanoidSurface()
                m = physical_metrics(joints, fps=motion.fps, body=surface)
                low = surface.lowest_height(joints)
                feet = stance_frames(joints, motion.fps)
                contact = feet | hand_frames(joints, surface.hand_heights(joints), low, motion.fps)
                stand = np.maximum(low - 0.005, 0.0) * 1000  # the metrics' Float per frame, mm
                light = physical_metrics(joints, fps=motion.fps)
                rows[info.source].append({
                    "penetrate": m["penetrate"], "float": m["float"], "skate": m["skate"],
                    "penetrate_joints": light["penetrate"], "hand_share": report.grounding.hand_share,
                    "contact_float": float(stand[contact].mean()) if contact.any() else float("nan"),
                    "lift_mm": 1000 * report.grounding.lift, "level": report.grounding.level,
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
            "over_2mm": int((v["penetrate"] >= 2).sum()), "hand_share": v["hand_share"].mean(),
            "contact_float_mean": np.nanmean(v["contact_float"]), "contact_float_max": np.nanmax(v["contact_float"]),
            "contact_float_over_5mm": int((v["contact_float"] > 5).sum()),
            "float_mean": v["float"].mean(), "skate_mean": v["skate"].mean(),
            "penetrate_joints_mean": v["penetrate_joints"].mean(), "round_trip_max_mm": t.max(),
            "round_trip_clips": len(t), "not_level": int((~v["level"]).sum()),
            # every clip of a source may be on uneven ground (a source of one such take): NaN then
            "penetrate_level_mean": v["penetrate"][v["level"]].mean() if v["level"].any() else np.nan,
            "penetrate_level_max": v["penetrate"][v["level"]].max() if v["level"].any() else np.nan,
        }  # fmt: skip
        s = {k: float(x) if isinstance(x, np.floating) else x for k, x in summary[source].items()}
        summary[source] = s
        table.append((source, s["clips"], f"{s['penetrate_mean']:.2f} / {s['penetrate_max']:.2f}", s["over_2mm"],
                      f"{s['float_mean']:.1f}", f"{s['contact_float_mean']:.1f} / {s['contact_float_max']:.1f}",
                      s["contact_float_over_5mm"], f"{100 * s['hand_share']:.1f}", f"{s['skate_mean']:.1f}",
                      f"{s['penetrate_joints_mean']:.2f}", f"{s['round_trip_max_mm']:.4f}, {s['round_trip_clips']}",
                      s["not_level"], f"{s['penetrate_level_mean']:.2f} / {s['penetrate_level_max']:.2f}"))
    header = ("source", "clips", "Penetrate mean / max (mm)", "clips >= 2 mm", "Float",
              "contact Float mean / max", "clips contact Float > 5 mm", "hand-only contact %", "Skate",
              "Penetrate, joint surface", "round trip max (mm), clips", "not level",
              "Penetrate mean / max, level clips")  # fmt: skip
    md = "# Where imported motion meets the floor\n\n" + markdown_table(header, table) + "\n"
    generated = _generated() if args.generated else {}
    if generated:
        md += "\nGenerated (P's output) BVH round trip, mm: " + ", ".join(
            f"{k} mean {v['mean_mm']:.4f} max {v['max_mm']:.4f}" for k, v in generated.items()) + "\n"
    print(md)
    meta = run_meta(__file__, argv, args.tree, None, sources=[str(s) for s in sources], every=args.every,
                    round_trip_every=args.round_trip_every)
    write_results(args.out, md, {"meta": meta, "sources": summary, "generated": generated})


def _generated() -> dict[str, dict[str, float]]:
    """Two motions of the default model, P applied, exported to BVH and imported: joint distance, mm."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate

    prompts = ["a person walks forward", "a person jumps"]
    res = generate(prompts, GenerateConfig(num=1, seed=0, seconds=4), MotionDiffusion.load())
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for prompt, motion in zip(prompts, res.motions):
            path = Path(tmp) / "g.bvh"
            save_bvh(motion, path)
            d = np.linalg.norm(import_clip(path).joints - motion.joints, axis=-1) * 1000
            out[prompt] = {"mean_mm": float(d.mean()), "max_mm": float(d.max())}
    return out

if __name__ == "__main__":
    main()
