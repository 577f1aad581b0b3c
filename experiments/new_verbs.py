"""Do the models do the verbs HDM05 brought in? Squat, kick, lie down, hop: plain sampling (``--physics
none``) of each verb's prompts over seeds, measured by :data:`physmotion.metrics.actions.ACTION_CHECKS`.

Usage: python -m experiments.new_verbs [--model default --model runs/x/model ...] [--seeds 5] [--out results/new_verbs]

Each verb has its HDM05 training caption and two paraphrases that no caption has (unseen wording). One
row per model and verb: the share of motions that pass the check, and the median figure.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from experiments._results import ROOT, markdown_table, report, run_meta, write_results

PROMPTS: dict[str, list[str]] = {
    "squat": ["a person squats down and stands back up", "someone does a deep squat", "a man squats once"],
    "kick": ["a person kicks forward with the left leg", "someone kicks with the right foot", "a person kicks a ball"],
    "lie down": ["a person lies down on the floor", "someone lies down on the ground", "a man lies down"],
    "hop": ["a person hops once on both legs", "someone jumps up with both feet", "a person hops in place"],
}  # fmt: skip


def measure(model_dir: str, seeds: int, seconds: float) -> dict[str, dict]:
    """verb -> {"passed": share, "median": figure, "values": per motion} for one model folder ("default":
    the shipped one)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.generate import GenerateConfig, generate
    from physmotion.metrics.actions import ACTION_CHECKS

    model = MotionDiffusion.load(None if model_dir == "default" else model_dir)
    out: dict[str, dict] = {}
    for verb, prompts in PROMPTS.items():
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
    args = ap.parse_args(argv)
    models = args.model or ["default"]

    def run() -> tuple[str, list[Path]]:
        figures = {m: measure(m, args.seeds, args.seconds) for m in models}
        rows = [[m, verb, f["what"], f"{f['threshold']:g}", f"{f['passed']:.2f}", f"{f['median']:.3f}",
                 ", ".join(f"{k}/{args.seeds}" for k in f["per_prompt"].values())]
                for m, verbs in figures.items() for verb, f in verbs.items()]  # fmt: skip
        table = markdown_table(["model", "verb", "figure", "threshold", "share passing", "median",
                                "passing per prompt (caption, paraphrases)"], rows)  # fmt: skip
        n = args.seeds * len(next(iter(PROMPTS.values())))
        md = (
            f"Plain sampling (`none`), {args.seconds:g} s, {n} motions per verb ({args.seeds} seeds x 3 prompts: "
            f"the HDM05 caption and two paraphrases).\n\n{table}\n"
        )
        meta = run_meta(__file__, argv, None, seeds=args.seeds, seconds=args.seconds, prompts=PROMPTS)
        return table, write_results(args.out, md, {"meta": meta, "models": figures})

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
