"""Generation wall time by physics mode, one table from one run (compare the ratios).

Usage: python -m experiments.generate_speed [--model DIR] [--morph DIR] [--biomo DIR] [--seconds 6] [--repeats 2]
       [--out results/generate_speed]
Modes: none, morph (Morph's inference: pre-processing, one P, imitation selection), post:4 (as many
projections as PhysDiff's default), physdiff:end:4,space:1, and PhysDiff with every projection at 1/720 s
(``generate --fine-step``); batches of 1
and 16 motions (one caption each, from the physics prompt set); 50 DDIM steps, CFG 2.5. The model and the
text encoder are loaded and warmed up once before timing; each time is the best of ``--repeats`` rounds.
PhysDiff reports 2.5x none at batch 1.

With ``--morph DIR`` (a Morph-tuned model) three rows time it in modes none, post:1 (one P, the sampling
preset's reset instead of Morph's selection) and morph, beside the base model's: Morph's claim is plain
sampling at the base model's cost, and one P instead of PhysDiff's four.

With ``--biomo DIR`` (a BioMoDiffuse model, e.g. ``runs/biomo_ablation/biomo`` from
``experiments/biomodiffuse.py``) a row times it without projection at its own sampler (SDE DPM-Solver++,
10 steps, physics guidance: three network passes per step) against the transformer's ``none`` row.

The last row is the physics floor: plain sampling plus the time PhysDiff spends inside MuJoCo's ``mj_step``.
At batch 1 it is clocked during the best timed run (one motion is projected in this process); at batch 16
the batch is generated once more with the projection in this process, and its stepping time is divided by
the cores (the worker processes' best case). No speed-up of the projection's Python can bring PhysDiff
below this ratio at this simulation rate.

P: the ``sampling`` preset (physdiff, post), ``sampling_fine`` in the 1/720 s row, and ``plain`` for morph
(physmotion/physics/presets.py). Writes ``<out>.md`` and ``<out>.json``.
"""

from __future__ import annotations

import argparse
import gc
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager, nullcontext
from dataclasses import replace

import mujoco

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.prompts import PHYSICS_PROMPTS
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.samplers import ddim_50, default_sampler
from physmotion.generate import GenerateConfig, generate
from physmotion.physics.presets import preset

MODES = ("none", "morph", "post:4", "physdiff:end:4,space:1")  # morph: Morph's inference, one P
PHYSDIFF = MODES[-1]
BIOMO = "BioMoDiffuse none (dpmpp-sde 10 steps)"
MORPH_MODES = ("none", "post:1", "morph")  # a Morph-tuned model: plain sampling and one P, two ways


@contextmanager
def _mj_step_clock(total: list[float]) -> Iterator[None]:
    """Add the seconds spent in ``mujoco.mj_step`` (called in this process) to ``total[0]``."""
    step = mujoco.mj_step

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return step(*args, **kwargs)
        finally:
            total[0] += time.perf_counter() - start

    mujoco.mj_step = timed
    try:
        yield
    finally:
        mujoco.mj_step = step


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default=None)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--repeats", type=int, default=2, help="rounds over all modes; the best time counts")
    parser.add_argument("--biomo", default=None, help="a BioMoDiffuse model folder to time beside the others")
    parser.add_argument("--morph", default=None,
                        help="a Morph-tuned model folder (physmotion/weights/morph): times its none, post:1 "
                             "and morph")
    parser.add_argument("--out", default="results/generate_speed", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    model = MotionDiffusion.load(args.model)
    base = GenerateConfig(seconds=args.seconds, sampler=ddim_50(), projection=preset("sampling"),
                          morph_projection=preset("plain"))  # fmt: skip
    generate(PHYSICS_PROMPTS[:1], replace(base, physics="none"), model)  # warm-up: encoder load, first calls
    runs = {mode: (model, replace(base, physics=mode)) for mode in MODES}
    runs[f"{PHYSDIFF} at 1/720 s"] = (model, replace(base, physics=PHYSDIFF, projection=preset("sampling_fine")))
    if args.biomo:
        biomo = MotionDiffusion.load(args.biomo)
        runs[BIOMO] = (biomo, replace(base, physics="none", sampler=default_sampler(biomo)))
        generate(PHYSICS_PROMPTS[:1], runs[BIOMO][1], biomo)
    if args.morph:
        tuned = MotionDiffusion.load(args.morph)
        for mode in MORPH_MODES:
            runs[f"Morph-tuned {mode}"] = (tuned, replace(base, physics=mode))
        generate(PHYSICS_PROMPTS[:1], replace(base, physics="none"), tuned)
    times: dict[tuple[str, int], float] = {}
    stepping = 0.0  # mj_step seconds inside the best PhysDiff run at batch 1
    # Rounds interleave the modes, so a slow spell of the shared machine hits all of them alike.
    for _ in range(max(1, args.repeats)):
        for batch in (1, 16):
            for mode, (net, config) in runs.items():
                clocked = (mode, batch) == (PHYSDIFF, 1)  # the projection runs in this process only there
                inside = [0.0]
                gc.collect()  # the last mode's garbage is not collected on this mode's clock (as timeit does)
                with _mj_step_clock(inside) if clocked else nullcontext():
                    start = time.perf_counter()
                    generate(PHYSICS_PROMPTS[:batch], config, net)
                    seconds = time.perf_counter() - start
                if seconds < times.get((mode, batch), float("inf")):
                    times[mode, batch] = seconds
                    stepping = inside[0] if clocked else stepping
    # Batch 16's stepping, clocked with the projection in this process (untimed run).
    config = replace(base, physics=PHYSDIFF)
    inside = [0.0]
    with _mj_step_clock(inside):
        generate(PHYSICS_PROMPTS[:16], replace(config, projection=replace(config.projection, workers=1)), model)
    floor = {1: times["none", 1] + stepping, 16: times["none", 16] + inside[0] / (os.cpu_count() or 1)}
    title = (f"generation wall time, {args.seconds:g} s motions, 50 DDIM steps (BioMoDiffuse: its own), "
             f"best of {max(1, args.repeats)}")
    times.update({("floor: none + PhysDiff's mj_step", batch): floor[batch] for batch in (1, 16)})
    rows = [(mode, f"{times[mode, 1]:.2f}", f"{times[mode, 16]:.2f}", f"{times[mode, 16] / 16:.2f}",
             f"{times[mode, 1] / times['none', 1]:.2f}x", f"{times[mode, 16] / times['none', 16]:.2f}x")
            for mode in dict.fromkeys(m for m, _ in times)]  # fmt: skip
    header = ("mode", "batch 1 (s)", "batch 16 (s)", "s/motion at 16", "vs none, batch 1", "vs none, batch 16")
    md = f"# {title}\n\n" + markdown_table(header, rows) + "\n"
    print(md)
    presets = {"physdiff, post": "sampling", f"{PHYSDIFF} at 1/720 s": "sampling_fine", "morph": "plain"}
    meta = run_meta(__file__, argv, args.tree, presets, seconds=args.seconds, repeats=args.repeats)
    seconds = {mode: {str(batch): t for (m, batch), t in times.items() if m == mode} for mode, _ in times}
    write_results(args.out, md, {"meta": meta, "seconds": seconds})

if __name__ == "__main__":
    main()
