"""PPO on the searched trajectories at more than one sample budget, against its warm start and the tracker,
on the held-out motions of experiments/learn_from_search.py, with no outside hand; writes
results/ppo_at_scale.md and .json.

Usage: python -m experiments.ppo_at_scale --teacher FOLDER --student FOLDER --ppo NAME=FOLDER [--ppo ...]
       [--data data_build/all] [--captured-test 10] [--max-seconds 5] [--prompts 12] [--workers 0]

Each ``--ppo`` folder is a policy that ``physmotion train imitator --teacher T --warm-start STUDENT``
exported (its ``card.json`` gives the samples, wall minutes and hardware it trained with) on the teacher
records of ``--teacher`` (``physmotion train teacher`` or experiments/teacher_data.py); ``--student`` is that
warm start (``physmotion train student`` on the same records). Rows: the tracker with and without the
outside hand, the student, each PPO policy. Columns as learn_from_search's (carried to the end, share of
control steps survived, world / pelvis-relative MPJPE, CPU s per s of motion), plus each policy's training
samples.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.learn_from_search import evaluate_rows, heldout_motions
from physmotion.errors import PhysmotionError
from physmotion.imitator.teacher import load_teacher_set


def _card(folder: str) -> dict:
    path = Path(folder) / "card.json"
    return json.loads(path.read_text()) if path.is_file() else {}


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--teacher", required=True, help="the teacher folder they learnt from")
    ap.add_argument("--student", required=True, help="the PPO runs' warm start (a policy folder)")
    ap.add_argument("--ppo", action="append", default=[], help="NAME=FOLDER of a PPO policy; repeat")
    ap.add_argument("--data", default="data_build/all")
    ap.add_argument("--captured-test", type=int, default=10)
    ap.add_argument("--max-seconds", type=float, default=5.0)
    ap.add_argument("--prompts", type=int, default=12)
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", default="results/ppo_at_scale")
    args = parse_args(ap, argv)
    if not args.ppo or any("=" not in item for item in args.ppo):
        ap.error("give each PPO policy as --ppo NAME=FOLDER")
    runs = dict(item.split("=", 1) for item in args.ppo)
    for folder in (args.student, *runs.values()):
        if not (Path(folder) / "settings.json").is_file():
            ap.error(f"{folder}: not a policy folder (no settings.json)")
    try:  # before the work: a wrong folder fails in one line
        records = load_teacher_set(args.teacher)
    except PhysmotionError as e:
        ap.error(str(e))
    teacher = {"records": len(records), "control_steps": sum(len(r["offsets"]) for r in records),
               "cpu_seconds": round(sum(float(r["cpu_seconds"]) for r in records), 1),
               "licence_tags": sorted({str(r["licence_tag"]) for r in records})}  # fmt: skip
    rows: dict[str, dict] = {"tracker, hand on": {"kind": "tracker", "hand": True},
                             "tracker, hand off": {"kind": "tracker", "hand": False},
                             "warm start (student)": {"kind": "policy", "folder": args.student}}  # fmt: skip
    for name, folder in runs.items():
        rows[f"PPO, {name}"] = {"kind": "policy", "folder": folder}
    test, motions, prompts = heldout_motions(args.data, args.captured_test, args.max_seconds, args.prompts,
                                             args.seed)  # fmt: skip
    header, table, json_rows = evaluate_rows(rows, motions, args.workers)
    cards = {name: _card(folder) for name, folder in runs.items()}
    fit = _card(args.student).get("fit", {})
    header.append("PPO samples (wall min, hardware)")
    for cells, name in zip(table, rows):
        card = cards.get(name.removeprefix("PPO, "))
        cells.append(f"{card['samples']:,} ({card['wall_minutes']}, {card['hardware']})" if card else "")
    n_cap = sum(1 for s, _, _ in motions if s == "captured")
    text = (f"# PPO on the searched trajectories at more than one sample budget (no outside hand)\n\n"
            f"Written by `python -m experiments.ppo_at_scale` (its docstring defines rows and columns). "
            f"Teacher: {teacher['records']} searched records ({teacher['control_steps']} control steps, "
            f"{teacher['cpu_seconds']:.0f} CPU s). Warm start: the student `{args.student}` "
            f"({fit.get('pairs')} labelled pairs). Evaluation: {n_cap} held-out captured clips, "
            f"{len(motions) - n_cap} generated motions of prompts never used for teacher data.\n\n"
            f"{markdown_table(header, table)}\n")  # fmt: skip
    meta = run_meta(__file__, argv, args.tree, None)
    payload = {"meta": meta, "rows": json_rows, "cards": cards, "student_fit": fit, "teacher": teacher,
               "prompts": prompts, "test_clips": [c.name for c in test]}  # fmt: skip
    write_results(args.results, text, payload)
    print(text)
    return payload


if __name__ == "__main__":
    main()
