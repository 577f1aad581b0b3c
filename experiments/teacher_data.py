"""Teacher data for learning from the search: the search (no outside hand) over captured clips of a built
dataset's train split (mirrors included) and over plain samples of Morph's synthetic prompts (the train
split's captions), resumable; writes results/teacher_data.md and .json (what was produced and at what cost).

Usage: python -m experiments.teacher_data [--data data_build/all] [--out runs/teacher] [--captured 60]
       [--generated 60] [--motions 48] [--effort default] [--workers 0] [--ray [ADDRESS]]

Jobs (physmotion/imitator/teacher.py): segments of at most 4 s, each from its first frame and once from a
perturbed start. ``--captured`` and ``--generated`` take the first N jobs of each kind in the seeded order,
so a larger N extends a set already made; a re-run skips jobs already written. The generated motions are
``--motions`` plain samples (4 s, default model, ``--physics none``) of captions drawn, seeded, from the train
split; the prompts used for evaluation (experiments.search_quality's FAST_PROMPTS and HELDOUT_PROMPTS) are
never among them.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.search_quality import FAST_PROMPTS, HELDOUT_PROMPTS
from physmotion.imitator.clips import ClipSource, dataset_clips
from physmotion.imitator.teacher import TeacherConfig, build_teacher_set, teacher_jobs
from physmotion.physics.search import effort

EVAL_PROMPTS = set(FAST_PROMPTS.values()) | set(HELDOUT_PROMPTS.values())


def synthetic_prompts(data: str, count: int, seed: int) -> list[str]:
    """``count`` distinct train-split captions, drawn with ``seed``, none of them an evaluation prompt."""
    from physmotion.morph.synth import train_captions

    captions = [c for c in train_captions(data) if c not in EVAL_PROMPTS]
    rng = np.random.default_rng(seed)
    return [captions[i] for i in rng.choice(len(captions), size=min(count, len(captions)), replace=False)]


def generated_clips(texts: list[str], seconds: float, seed: int) -> list[ClipSource]:
    """Plain samples (default model, no physics) of ``texts``, one each, as clips."""
    from physmotion.generate import GenerateConfig, generate

    result = generate(texts, GenerateConfig(seconds=seconds, num=1, physics="none", seed=seed))
    return [ClipSource(f"gen{i:03d}", m.joints.astype(np.float32), float(m.fps), m.licence_tag, "generated")
            for i, m in enumerate(result.motions)]  # fmt: skip


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="data_build/all")
    ap.add_argument("--out", default="runs/teacher")
    ap.add_argument("--captured", type=int, default=60)
    ap.add_argument("--generated", type=int, default=60)
    ap.add_argument("--motions", type=int, default=48)
    ap.add_argument("--effort", default="default")
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--ray", nargs="?", const="local", default=None)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", default="results/teacher_data")
    args = parse_args(ap, argv)
    config = TeacherConfig(search=effort(args.effort, args.seed), seed=args.seed)
    captured = teacher_jobs(dataset_clips(args.data, "train"), config)[: args.captured]
    texts = synthetic_prompts(args.data, args.motions, args.seed)
    generated = teacher_jobs(generated_clips(texts, config.segment_seconds, args.seed), config)[: args.generated]
    t0 = time.time()
    index = build_teacher_set(captured + generated, args.out, config, args.workers, args.ray)
    wall = time.time() - t0
    rows = []
    for origin in ("captured", "generated"):
        for kind in ("plain", "perturbed"):
            items = [r for r in index["items"] if r["origin"] == origin and (any(r["push"]) == (kind == "perturbed"))]
            if not items:
                continue
            seconds = sum(r["steps"] for r in items) / 30.0
            cpu = sum(r["cpu_seconds"] for r in items)
            rows.append({"set": origin, "start": kind, "searches": len(items),
                         "motion s": round(seconds, 1), "control steps": sum(r["steps"] for r in items),
                         "to the end": f"{100 * np.mean([r['completed'] for r in items]):.0f} %",
                         "CPU s": round(cpu), "CPU s / s": round(cpu / max(seconds, 1e-9), 1)})  # fmt: skip
    table = markdown_table(list(rows[0]), [list(r.values()) for r in rows]) if rows else "(nothing written)"
    text = (f"# Teacher data: the search over captured and generated motion\n\nWritten by "
            f"`python -m experiments.teacher_data` (its docstring says what the jobs are). Search effort "
            f"{args.effort}; {index['written']} of the {len(captured) + len(generated)} jobs asked for are "
            f"written; this run's wall time {wall / 60:.0f} min (jobs written by earlier runs included in the "
            f"rows). Licence tags: {', '.join(index['licence_tags']) or 'none'}.\n\n{table}\n")  # fmt: skip
    meta = run_meta(__file__, argv, args.tree, None)
    out = {"meta": meta, "rows": rows, "prompts": texts, "written": index["written"],
           "cpu_seconds": index["cpu_seconds"], "control_steps": index["control_steps"]}  # fmt: skip
    write_results(args.results, text, out)
    print(text)
    return out


if __name__ == "__main__":
    main()
