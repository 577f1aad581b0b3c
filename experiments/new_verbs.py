"""Do the models do the verbs HDM05 brought in? Squat, kick, lie down, hop: plain sampling (``--physics
none``) of each verb's prompts over seeds, measured by :data:`physmotion.metrics.actions.ACTION_CHECKS`.

Usage: python -m experiments.new_verbs [--model default --model runs/x/model ...] [--seeds 5] [--out results/new_verbs]

Each verb has its HDM05 training caption, two paraphrases that no caption has (unseen wording, used in
the tests), and three more (:data:`FRESH`) written before the caption rewrites of training were measured and
never used to choose anything. One row per model and verb: the share of motions that pass the check over
all six prompts, and per group of prompts.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from experiments._results import ROOT, markdown_table, parse_args, report, run_meta, write_results

PROMPTS: dict[str, list[str]] = {
    "squat": ["a person squats down and stands back up", "someone does a deep squat", "a man squats once"],
    "kick": ["a person kicks forward with the left leg", "someone kicks with the right foot", "a person kicks a ball"],
    "lie down": ["a person lies down on the floor", "someone lies down on the ground", "a man lies down"],
    "hop": ["a person hops once on both legs", "someone jumps up with both feet", "a person hops in place"],
}  # fmt: skip
FRESH: dict[str, list[str]] = {
    "squat": ["a woman squats", "the person crouches down low and then stands up",
              "someone bends their knees into a squat and rises again"],
    "kick": ["a man kicks", "the person does a front kick with one leg", "someone kicks their foot out in front of them"],
    "lie down": ["a woman lies down", "the person gets down onto the ground and lies flat",
                 "someone lies down on their back"],
    "hop": ["a man hops", "the person hops up and lands on both feet", "someone does a small two-footed hop"],
}  # fmt: skip


def measure(model_dir: str, seeds: int, seconds: float,
            prompts_by_verb: dict[str, list[str]] = PROMPTS) -> dict[str, dict]:  # fmt: skip
    """verb -> {"passed": share, "median": figure, "values": per motion, "per_prompt": passes over the
    seeds} for one model folder ("default": the shipped one)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics.actions import ACTION_CHECKS

    model = MotionDiffusion.load(None if model_dir == "default" else model_dir)
    out: dict[str, dict] = {}
    for verb, prompts in prompts_by_verb.items():
        check = ACTION_CHECKS[verb]
        values, passed = [], []
        for seed in range(seeds):
            res = generate(prompts, GenerateConfig(seconds=seconds, physics="none", seed=seed), model=model)
            for m in res.motions:
                values.append(check.measure(m.joints))
                passed.append(check.passes(m.joints))
        # passes per prompt over the seeds (the motions come seed by seed, the prompts within a seed)
        per_prompt = {p: int(sum(passed[i::len(prompts)])) for i, p in enumerate(prompts)}
        out[verb] = {"what": check.what, "threshold": check.threshold, "passed": float(np.mean(passed)),
                     "median": float(np.median(values)), "values": values, "per_prompt": per_prompt}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", action="append", help="model folder, or 'default' (repeatable)")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--seconds", type=float, default=4.0)
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "new_verbs")
    args = parse_args(ap, argv)
    models = args.model or ["default"]

    def run() -> tuple[str, list[Path]]:
        every = {verb: PROMPTS[verb] + FRESH[verb] for verb in PROMPTS}
        figures = {m: measure(m, args.seeds, args.seconds, every) for m in models}

        def group(f: dict, prompts: list[str]) -> str:
            return f"{sum(f['per_prompt'][p] for p in prompts)}/{args.seeds * len(prompts)}"

        rows = [[m, verb, f["what"], f"{f['threshold']:g}", f"{f['passed']:.2f}", f"{f['median']:.3f}",
                 group(f, PROMPTS[verb][:1]), group(f, PROMPTS[verb][1:]), group(f, FRESH[verb]),
                 ", ".join(f"{k}/{args.seeds}" for k in f["per_prompt"].values())]
                for m, verbs in figures.items() for verb, f in verbs.items()]  # fmt: skip
        table = markdown_table(["model", "verb", "figure", "threshold", "share passing", "median", "caption",
                                "paraphrases", "fresh paraphrases", "passing per prompt"], rows)  # fmt: skip
        n = args.seeds * len(next(iter(every.values())))
        md = (
            f"Plain sampling (`none`), {args.seconds:g} s, {n} motions per verb ({args.seeds} seeds x 6 prompts: "
            f"the HDM05 caption, the two paraphrases the tests use, and three fresh ones).\n\n{table}\n"
        )
        meta = run_meta(__file__, argv, args.tree, None, seeds=args.seeds, seconds=args.seconds,
                        prompts=every)
        return table, write_results(args.out, md, {"meta": meta, "models": figures})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
