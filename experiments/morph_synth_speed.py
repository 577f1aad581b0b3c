"""Morph's synthetic data throughput: synthetic motions refined per second, and where the time goes.

Usage: python -m experiments.morph_synth_speed [--model DIR] [--data data_build/mocap] [--captions 16]
    [--per-caption 1] [--workers 0] [--steps 50] [--ilc 0] [--run RUN] [--out STEM]
Runs :func:`physmotion.morph.synth.synthesize` on the first ``--captions`` distinct train captions
(lengths drawn from the train split, 50 DDIM steps, P with Morph's selection settings, ``--ilc`` passes of
iterative learning control as `morph run --ilc`) into a temporary
folder, and writes one table from its :class:`SynthReport` (``<out>.md``, ``<out>.json``): items per second, the share of wall time in
sampling (the denoiser) and in P (pre-processing, projection, features and writing, waited for).
The model is loaded before timing; the first batch pays the text encoder's and the worker pool's start.
With ``--run RUN`` (a finished `physmotion morph run` folder) it adds each round's split of wall time
between synthesis and fine-tuning, from ``RUN/rounds.json``.

On one GPU the denoiser's share (sampling and fine-tuning) would shrink by one to two orders of magnitude
while P, MuJoCo on the CPU, would not: P would become the bottleneck of synthesis.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import SamplerConfig
from physmotion.morph.synth import SynthConfig, synthesize, train_captions


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", type=Path, default=None)
    parser.add_argument("--data", type=Path, default=Path("data_build/mocap"))
    parser.add_argument("--captions", type=int, default=16)
    parser.add_argument("--per-caption", type=int, default=1)
    parser.add_argument("--workers", type=int, default=0)
    parser.add_argument("--steps", type=int, default=50)
    parser.add_argument("--batch-size", type=int, default=16)
    parser.add_argument("--ilc", type=int, default=0,
                        help="P's iterative learning control passes, as `morph run --ilc`")
    parser.add_argument("--run", type=Path, default=None, help="a finished `morph run` folder")
    parser.add_argument("--out", default="results/morph_synth_speed", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)

    model = MotionDiffusion.load(args.model)
    captions = train_captions(args.data)[: args.captions]
    cfg = SynthConfig(per_caption=args.per_caption, workers=args.workers, batch_size=args.batch_size,
                      sampler=SamplerConfig(steps=args.steps), ilc_passes=args.ilc)  # fmt: skip
    with tempfile.TemporaryDirectory() as tmp:
        report = synthesize(args.model, args.data, Path(tmp) / "synth", cfg, captions=captions, model=model)

    title = (f"Morph synthetic data: {report.done} motions ({len(captions)} captions x {args.per_caption}), "
             f"{args.steps} DDIM steps, batch {args.batch_size}, ILC {args.ilc}")
    wall = report.seconds or float("nan")
    rows = [("sampling (denoiser)", f"{report.sampling_seconds:.1f}", f"{report.sampling_seconds / wall:.0%}",
             f"{report.done / report.sampling_seconds:.2f}"),
            ("P (pre-process, project, features, write)", f"{report.physics_seconds:.1f}",
             f"{report.physics_seconds / wall:.0%}", f"{report.done / report.physics_seconds:.2f}"),
            ("synthetic data, total", f"{report.seconds:.1f}", "100%", f"{report.items_per_second:.2f}")]
    for row in _rounds(args.run) if args.run else []:  # a whole round: synthesis, then fine-tuning
        total = row["synth_seconds"] + row["finetune_seconds"]
        for stage, key in (("synthesis", "synth_seconds"), ("fine-tuning", "finetune_seconds")):
            label = f"round {row['round']}: {stage} ({row['synthetic_items']} motions, {row['finetune_steps']} steps)"
            rows.append((label, f"{row[key]:.0f}", f"{row[key] / total:.0%} of round",
                         f"{row['synthetic_items'] / row[key]:.2f}"))
    md = f"# {title}\n\n" + markdown_table(("stage", "seconds", "share of wall", "motions / s"), rows) + "\n"
    print(md)
    figures = {"motions": report.done, "seconds": report.seconds, "sampling_seconds": report.sampling_seconds,
               "physics_seconds": report.physics_seconds, "items_per_second": report.items_per_second}
    meta = run_meta(__file__, argv, args.tree, "plain", model=str(args.model),  # Morph's selection
                    captions=len(captions), per_caption=args.per_caption, steps=args.steps,
                    ilc_passes=args.ilc)
    write_results(args.out, md, {"meta": meta, "figures": figures, "rows": rows})


def _rounds(run: Path) -> list[dict]:
    """The rows of ``run/rounds.json`` (written by physmotion.morph.loop)."""
    return json.loads((run / "rounds.json").read_text())["rounds"]

if __name__ == "__main__":
    main()
