"""Learning from the search at scale: does the student (BC, then DAgger, on the MPPI labeller's consistent
labels) get better with many more labelled states? Writes results/learn_at_scale.md and .json.

Three stages, so that the costly one can run on a bigger machine (issue 63, item 5):

    python -m experiments.learn_at_scale refs  [--data data_build/all] [--captured 700] [--motions 250]
                                               [--out runs/scale/refs.npz]
    python -m experiments.learn_at_scale label [--refs runs/scale/refs.npz] [--pairs runs/scale/pairs]
                                               [--start 0] [--limit 0] [--workers 0] [--minutes 0]
    python -m experiments.learn_at_scale fit   [--refs ...] [--pairs FOLDER ...] [--label-machines TEXT ...]
                                               [--out runs/scale/students] [--dagger-refs 120]

- ``refs``: the training references, as experiments/teacher_data.py makes its jobs (physmotion/imitator/
  teacher.py: segments of at most 4 s, each from a plain and a pushed start): the first ``--captured`` jobs of
  the built dataset's train split (mirrors included) and every job of ``--motions`` plain samples (4 s,
  default model) of Morph's synthetic prompts (train captions, never an evaluation prompt), the two kinds
  interleaved so that any prefix holds both.
- ``label``: the MPPI labeller as the :class:`~physmotion.imitator.student.Expert` drives each reference of
  ``--start`` .. ``--start + --limit`` in that order (:func:`~physmotion.imitator.student.expert_episode`) in
  worker processes, until every one is done or ``--minutes`` have passed; its labelled (observation, offset)
  pairs are written in chunks of about 5,000 (``pairs_NNN.npz``, atomically), with ``index.json`` (per
  reference written: steps survived, pairs; the wall time and workers). A re-run into the same folder
  skips the references written (resumable); machines can share the work by ranges. Needs numpy, scipy and
  MuJoCo only.
- ``fit``: BC students on growing prefixes of the labelled references (1/8, 1/4, 1/2, all: a curve of success
  against labelled pairs), each fitted twice, keeping the last step's weights (StudentConfig's default) or
  the step with the least validation error; then one DAgger round from the all-data student kept on
  validation, on the first ``--dagger-refs`` references (the student drives them, its visited states are
  labelled, refit on all).
  Every student, the bare tracker, the labeller as a controller and small searches with the last student
  proposing (``--amortized``) are evaluated with no outside hand on experiments/learn_from_search.py's
  held-out set and columns.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from functools import partial
from pathlib import Path

import numpy as np

CHUNK = 5000  # pairs per file: 5,000 x 599 float32 stay under a 16 MiB transfer limit


def _refs(args: argparse.Namespace) -> None:
    from experiments.teacher_data import generated_clips, synthetic_prompts
    from physmotion.imitator.clips import dataset_clips
    from physmotion.imitator.teacher import TeacherConfig, teacher_jobs
    from physmotion.motion import write_atomic

    config = TeacherConfig(seed=args.seed)
    captured = teacher_jobs(dataset_clips(args.data, "train"), config)[: args.captured]
    texts = synthetic_prompts(args.data, args.motions, args.seed)
    generated = teacher_jobs(generated_clips(texts, config.segment_seconds, args.seed), config)
    jobs = [j for pair in zip(captured, generated) for j in pair]
    jobs += captured[len(generated) :] + generated[len(captured) :]
    segments: dict[tuple[str, int], int] = {}  # a plain and a pushed start share their segment's joints
    first: dict[tuple[str, int], object] = {}
    for j in jobs:
        segments.setdefault((j.source, j.start), len(segments))
        first.setdefault((j.source, j.start), j)
    lengths = np.array([len(first[k].joints) for k in segments])
    arrays = {
        "joints": np.concatenate([first[k].joints for k in segments]).astype(np.float32),  # (sum T, 22, 3)
        "offsets": np.r_[0, np.cumsum(lengths)], "segment": np.array([segments[(j.source, j.start)] for j in jobs]),
        "fps": np.array([j.fps for j in jobs]), "push": np.stack([j.push for j in jobs]),
        "name": np.array([j.id for j in jobs]), "origin": np.array([j.origin for j in jobs]),
        "licence_tag": np.array([j.licence_tag for j in jobs]), "prompts": np.array(texts),
    }  # fmt: skip
    write_atomic(args.out, lambda f: np.savez_compressed(f, **arrays))
    print(f"{len(jobs)} references ({len(captured)} captured, {len(generated)} generated), "
          f"{sum(len(j.joints) / j.fps for j in jobs):.0f} s of motion -> {args.out}")  # fmt: skip


def load_refs(path: str | Path) -> list[dict]:
    """The references ``refs`` wrote, in labelling order, as records (:func:`expert_episode`'s keys, with
    "name", "origin" and "licence_tag")."""
    with np.load(path) as z:
        a = {k: z[k] for k in z.files}
    out = []
    for i, seg in enumerate(a["segment"]):
        joints = a["joints"][a["offsets"][seg] : a["offsets"][seg + 1]]
        out.append({"joints": joints, "fps": float(a["fps"][i]), "push": a["push"][i], "name": str(a["name"][i]),
                    "origin": str(a["origin"][i]), "licence_tag": str(a["licence_tag"][i])})  # fmt: skip
    return out


def _label(args: argparse.Namespace) -> None:
    from physmotion.imitator.student import Labeller, StudentConfig, expert_episode
    from physmotion.motion import write_atomic
    from physmotion.physics.workers import imap_in_workers, worker_count

    everything = load_refs(args.refs)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    index_file = out / "index.json"
    index: dict = json.loads(index_file.read_text()) if index_file.is_file() else {"wall_s": 0.0, "done": {}}
    chunks = len(list(out.glob("pairs_*.npz")))  # a re-run goes on after what is written
    span = range(args.start, min(len(everything), args.start + args.limit) if args.limit else len(everything))
    todo = [i for i in span if everything[i]["name"] not in index["done"]]
    fn = partial(expert_episode, labeller=Labeller(), action_scale=StudentConfig().action_scale)
    workers = worker_count(args.workers, len(todo))
    index["workers"] = workers
    t0, wall0 = time.time(), float(index["wall_s"])
    deadline = t0 + 60 * args.minutes if args.minutes else float("inf")
    buf: list[tuple[int, np.ndarray, np.ndarray, dict]] = []

    def flush() -> None:  # a reference counts as done once its pairs are written
        nonlocal buf, chunks
        if buf:
            x = np.concatenate([b[1] for b in buf])
            y = np.concatenate([b[2] for b in buf])
            ref = np.concatenate([np.full(len(b[1]), b[0]) for b in buf])
            write_atomic(out / f"pairs_{chunks:03d}.npz", lambda f: np.savez_compressed(f, x=x, y=y, ref=ref))
            index["done"] |= {everything[b[0]]["name"]: b[3] for b in buf}
            chunks, buf = chunks + 1, []
        index["wall_s"] = round(wall0 + time.time() - t0, 1)
        write_atomic(index_file, lambda f: f.write(json.dumps(index)), "w")

    print(f"{len(todo)} of {len(span)} references to label ({len(span) - len(todo)} done before)", flush=True)
    for n, (j, (x, y, survived, steps)) in enumerate(imap_in_workers(fn, [everything[i] for i in todo], workers), 1):
        buf.append((todo[j], x, y, {"ref": todo[j], "survived": survived, "steps": steps, "pairs": len(x)}))
        if sum(len(b[1]) for b in buf) >= CHUNK:
            flush()
        if n % 10 == 0 or n == len(todo):
            print(f"{n}/{len(todo)} references, {time.time() - t0:.0f} s", flush=True)
        if time.time() > deadline:
            print(f"deadline: {n} of {len(todo)} references labelled", flush=True)
            break
    flush()


def load_pairs(folders: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every pair ``label`` wrote in ``folders``: observations (M, 599), labels (M, 63), reference index (M,)."""
    files = [f for folder in folders for f in sorted(Path(folder).glob("pairs_*.npz"))]
    parts = [np.load(f) for f in files]
    return (np.concatenate([p["x"] for p in parts]), np.concatenate([p["y"] for p in parts]),
            np.concatenate([p["ref"] for p in parts]))  # fmt: skip


def _where(indexes: list[dict], machines: list[str]) -> str:
    return "; ".join(f"{len(ix['done'])} references in {ix['wall_s'] / 60:.1f} min on {ix['workers']} processes "
                     f"({m})" for ix, m in zip(indexes, machines))  # fmt: skip


def _fit(args: argparse.Namespace) -> None:
    from experiments._results import markdown_table, run_meta, write_results
    from experiments.learn_from_search import SMALL_EFFORTS, evaluate_rows, heldout_motions
    from physmotion.imitator.student import (
        Labeller,
        StudentConfig,
        card,
        dagger_episode,
        dagger_round,
        fit_student,
        save_student,
        student_settings,
    )
    refs = load_refs(args.refs)
    x, y, ref = load_pairs(args.pairs)
    indexes = [json.loads((Path(p) / "index.json").read_text()) for p in args.pairs]
    order = sorted({int(d["ref"]) for ix in indexes for d in ix["done"].values()})  # labelled, in labelling order
    cfg, out = StudentConfig(steps=args.fit_steps, seed=args.seed), Path(args.out)
    chosen = replace(cfg, select_on_validation=True)
    folders, fits = {}, {}
    for share in (8, 4, 2, 1):
        used = order[: max(1, len(order) // share)]
        keep = np.isin(ref, used)
        for label, conf in (("last step", cfg), ("least validation error", chosen)):
            weights, stats = fit_student(x[keep], y[keep], ref[keep], conf)
            name = f"BC, {len(used)} references ({stats['pairs']} pairs), {label}"
            sub = f"bc_{len(used)}" + ("_selected" if conf.select_on_validation else "")
            folders[name] = str(save_student(out / sub, weights, student_settings(conf),
                                             card(conf, "BC", [refs[i] for i in used], stats)))  # fmt: skip
            fits[name] = stats
            start = name  # DAgger starts from the last: all the data, kept on validation
            print(f"{name}: validation MSE {stats['val_mse']:.3f} (0 predicted: {stats['val_mse_zero']:.3f}), "
                  f"step {stats['steps_kept']}", flush=True)  # fmt: skip
    if args.dagger_refs:  # one round from ``start``, refit the same way
        used = order[: args.dagger_refs]
        step = partial(dagger_episode, labeller=Labeller(), action_scale=cfg.action_scale)
        x2, y2, r2, survived = dagger_round(step, [refs[i] for i in used], used, folders[start], (x, y, ref),
                                            args.workers)  # fmt: skip
        weights, stats = fit_student(x2, y2, r2, chosen)
        stats["survived_before"] = round(float(survived), 3)
        name = f"DAgger 1 on {len(used)} references ({stats['pairs']} pairs), least validation error"
        folders[name] = str(save_student(out / "dagger1", weights, student_settings(chosen),
                                         card(chosen, "DAgger 1", [refs[i] for i in order], stats)))  # fmt: skip
        fits[name] = stats
        print(f"{name}: the BC student survived {survived:.2f} of those steps; validation MSE "
              f"{stats['val_mse']:.3f}", flush=True)  # fmt: skip

    test, motions, prompts = heldout_motions(args.data, args.captured_test, args.max_seconds, args.prompts, args.seed)
    rows: dict[str, dict] = {"tracker, hand off": {"kind": "tracker", "hand": False}}
    if args.labeller_row:
        rows["MPPI labeller as a controller (32 x 1, lookahead 15)"] = {"kind": "expert"}
    rows |= {f"{name} student": {"kind": "policy", "folder": folder} for name, folder in folders.items()}
    last = list(folders)[-1]
    for effort_name in args.amortized:  # the last student as the proposal of a small search
        conf = replace(SMALL_EFFORTS[effort_name], seed=args.seed)
        rows[f"amortized: {last.split(' (')[0]} + search {effort_name}"] = {"kind": "search", "config": conf,
                                                                          "proposal": folders[last]}  # fmt: skip
    header, table, json_rows = evaluate_rows(rows, motions, args.workers)
    labelled = [refs[i] for i in order]
    seconds = sum(len(r["joints"]) / r["fps"] for r in labelled)
    n_cap = sum(1 for s, _, _ in motions if s == "captured")
    text = (f"# Learning from the search at scale (no outside hand)\n\nWritten by `python -m "
            f"experiments.learn_at_scale` (its docstring defines the stages). Labelled: {len(order)} references "
            f"({sum(r['origin'] == 'captured' for r in labelled)} captured, "
            f"{sum(r['origin'] == 'generated' for r in labelled)} generated; {seconds:.0f} s of motion), "
            f"{len(x)} pairs by the MPPI labeller ({_where(indexes, args.label_machines)}). Evaluation: {n_cap} "
            f"held-out captured clips, {len(motions) - n_cap} generated motions of prompts never used for "
            f"training, as in results/learn_from_search.md.\n\n{markdown_table(header, table)}\n")  # fmt: skip
    labelling = [{"folder": p, "machine": m, "wall_s": ix["wall_s"], "workers": ix["workers"],
                  "references": len(ix["done"])} for p, m, ix in zip(args.pairs, args.label_machines, indexes)]
    meta = run_meta(__file__, args.argv, args.tree, None, labelling=labelling)
    payload = {"meta": meta, "rows": json_rows, "fits": fits, "references": len(order), "pairs": int(len(x)),
               "licence_tags": sorted({r["licence_tag"] for r in labelled if r["licence_tag"]}),
               "prompts": prompts, "test_clips": [c.name for c in test]}  # fmt: skip
    write_results(args.results, text, payload)
    print(text)


def main(argv: list[str] | None = None) -> None:
    from experiments._results import parse_args
    from physmotion.imitator.student import StudentConfig

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("stage", choices=["refs", "label", "fit"])
    ap.add_argument("--data", default="data_build/all")
    ap.add_argument("--refs", default="runs/scale/refs.npz")
    ap.add_argument("--pairs", nargs="+", default=["runs/scale/pairs"], help="label: the folder to write; "
                    "fit: every folder to read")
    ap.add_argument("--out", default=None, help="refs: the .npz; label: the pairs folder; fit: the students folder")
    ap.add_argument("--captured", type=int, default=700, help="refs: captured jobs")
    ap.add_argument("--motions", type=int, default=250, help="refs: generated motions (2 jobs each)")
    ap.add_argument("--start", type=int, default=0, help="label: the first reference (machines can share the "
                    "work: one takes 0..N-1, another N..)")
    ap.add_argument("--limit", type=int, default=0, help="label: at most this many references (0: all)")
    ap.add_argument("--minutes", type=float, default=0.0, help="label: stop after this long (0: never)")
    ap.add_argument("--label-machines", nargs="+", default=[], help="fit: where each --pairs folder was "
                    "labelled, for the table")
    ap.add_argument("--dagger-refs", type=int, default=120, help="fit: references of the DAgger round (0: none)")
    ap.add_argument("--fit-steps", type=int, default=StudentConfig().steps, help="fit: gradient steps per fit")
    ap.add_argument("--amortized", nargs="*", default=["8x1, lookahead 6", "16x2, lookahead 10"],
                    help="fit: small search efforts (experiments.learn_from_search.SMALL_EFFORTS) with the last "
                         "student proposing, as rows")
    ap.add_argument("--labeller-row", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--captured-test", type=int, default=10)
    ap.add_argument("--max-seconds", type=float, default=5.0)
    ap.add_argument("--prompts", type=int, default=12)
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", default="results/learn_at_scale")
    args = parse_args(ap, argv)
    args.argv = argv
    args.out = args.out or {"refs": args.refs, "label": args.pairs[0], "fit": "runs/scale/students"}[args.stage]
    args.label_machines = (args.label_machines + ["this machine"] * len(args.pairs))[: len(args.pairs)]
    {"refs": _refs, "label": _label, "fit": _fit}[args.stage](args)


if __name__ == "__main__":
    main()
