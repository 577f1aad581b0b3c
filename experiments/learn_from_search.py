"""Learning a fast controller from the search, compared on held-out motion with no outside hand; writes
results/learn_from_search.md and .json.

Usage: python -m experiments.learn_from_search [--teacher runs/teacher] [--data data_build/all] [--out runs/learn]
       [--dagger-rounds 2] [--ppo-minutes 8 | --ppo FOLDER] [--captured-test 10] [--max-seconds 5]

Training data: the teacher records in ``--teacher`` (``physmotion train teacher`` / experiments/teacher_data.py:
the search over the train split's captured clips, mirrored, and over plain samples of Morph's synthetic prompts,
plain and pushed starts). Methods (physmotion/imitator/student.py):
- BC on the search's choices: behaviour cloning of the records' committed offsets (the naive form);
- (a) BC and DAgger on consistent labels: the MPPI labeller (32 candidates on common random numbers, lookahead
  15, averaged by exp(-cost / (0.1 x the costs' spread)): a deterministic, smooth function of the state) drives
  each training reference (plain or pushed, as the record) and its labelled states are BC's data; then
  ``--dagger-rounds`` rounds in which the student drives them and every 3rd state it visits is labelled; refit
  on all pairs. The labeller as a controller is a row too;
- amortized search: the search at small efforts (candidates x rounds, lookahead), its first round centred on
  the DAgger student's proposal, against the same efforts with no proposal: a curve of cost against success;
- PPO (rsl-rl, ``--ppo-minutes`` of training here, or a folder given with ``--ppo``): tracking the searched
  trajectories with no outside hand, observing the kinematic reference, warm-started from the last student.
Evaluation, every row from the first frame with no outside hand unless the row says "hand on": the first
``--captured-test`` unmirrored clips of the dataset's test split (a take-level split: no take on both sides),
at most ``--max-seconds`` each, and plain samples (4 s) of experiments.search_quality's FAST_PROMPTS and
HELDOUT_PROMPTS (12 prompts never used for teacher data). A fall is the search's: pelvis 0.35 m under the
reference's or tipped 1 rad from it. Columns per set: carried to the end, share of control steps survived,
world / pelvis-relative MPJPE (mm, over the survived steps), CPU seconds per second of motion.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from functools import lru_cache
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.search_quality import FAST_PROMPTS, HELDOUT_PROMPTS
from physmotion.imitator.clips import dataset_clips
from physmotion.imitator.student import Expert, Labeller, StudentConfig, carry, prepared, train_student
from physmotion.imitator.teacher import load_teacher_set
from physmotion.physics.search import SearchConfig, effort

SMALL_EFFORTS = {  # name -> the amortized search's effort (no retries: a fixed cost per window)
    "4x1, lookahead 6": SearchConfig(candidates=4, rounds=1, elites=2, horizon=6, retries=0, rollback=0),
    "8x1, lookahead 6": SearchConfig(candidates=8, rounds=1, elites=3, horizon=6, retries=0, rollback=0),
    "16x2, lookahead 10": SearchConfig(candidates=16, rounds=2, elites=4, horizon=10, retries=1, rollback=1),
}


@lru_cache(maxsize=8)
def _policy(folder: str):
    from physmotion.physics.policy import load_policy

    return load_policy(folder)


def evaluate_row(job: tuple[str, dict, np.ndarray, float]) -> dict:
    """One (row name, row spec, joints (T, 22, 3) metres Y-up, fps) from its first frame: control steps survived
    and in all, world / pelvis-relative MPJPE (m, over the survived steps), CPU seconds, seconds of motion.
    A spec's "kind": "tracker" (with "hand"), "search" ("config", optional "proposal" policy folder),
    "expert" (the MPPI labeller) or "policy" ("folder")."""
    from physmotion.physics.search import SearchController, no_hand
    from physmotion.physics.tracking import ModelBasedTracker

    name, spec, joints, fps = job
    t0 = time.process_time()
    model, ref, pconf = prepared(joints, fps)
    kind = spec["kind"]
    if kind == "search":
        pol = _policy(spec["proposal"]) if spec.get("proposal") else None
        scale = pol.settings.action_scale if pol else 0.0
        proposal = (lambda obs: scale * np.clip(pol.network(obs), -1.0, 1.0)) if pol else None
        search = SearchController(model, replace(spec["config"], threads=1), pconf.humanoid, pconf.tracking, proposal)
        roll, _ = search.run(ref)
        survived = len(ref.qpos) - 1 if roll.failed_at is None else roll.failed_at
        err, rel = _errors(model, roll.qpos[1 : survived + 1], ref.joints_mj[1 : survived + 1])
        out = {"survived": survived, "steps": len(ref.qpos) - 1, "mpjpe": err, "mpjpe_rel": rel}
    else:
        if kind == "tracker":
            tracking = pconf.tracking if spec["hand"] else no_hand(pconf.tracking)
            controller = ModelBasedTracker(model, tracking)
        elif kind == "expert":
            controller = Expert(model, Labeller(), pconf.humanoid, pconf.tracking)
        else:
            controller = _policy(spec["folder"]).controller(model)
        c = carry(model, ref, controller, pconf.humanoid)
        out = {"survived": c.survived, "steps": c.steps, "mpjpe": c.mpjpe, "mpjpe_rel": c.mpjpe_rel}
    return out | {"row": name, "cpu": time.process_time() - t0, "seconds": (len(ref.qpos) - 1) / 30.0}


def _errors(model, qpos: np.ndarray, target: np.ndarray) -> tuple[float, float]:
    import mujoco

    from physmotion.physics.humanoid import layout

    if len(qpos) == 0:
        return float("nan"), float("nan")
    data, ids = mujoco.MjData(model), layout(model).body_ids
    err, rel = [], []
    for q, t in zip(qpos, target):
        data.qpos[:] = q
        mujoco.mj_kinematics(model, data)
        b = data.xpos[ids]
        err.append(np.linalg.norm(b - t, axis=-1).mean())
        rel.append(np.linalg.norm((b - b[0]) - (t - t[0]), axis=-1).mean())
    return float(np.mean(err)), float(np.mean(rel))


def heldout_motions(data: str, captured: int, max_seconds: float, prompts: int,
                    seed: int) -> tuple[list, list[tuple[str, np.ndarray, float]], list[str]]:  # fmt: skip
    """The evaluation set: the first ``captured`` unmirrored clips of ``data``'s test split (at most
    ``max_seconds`` each) and plain samples (4 s, default model, seed) of the first ``prompts`` of
    FAST_PROMPTS + HELDOUT_PROMPTS. Returns (the test clips, [(set, joints (T, 22, 3), fps)], the prompts)."""
    from physmotion.generate import GenerateConfig, generate

    test = [c for c in dataset_clips(data, "test") if not c.name.startswith("M")][:captured]
    motions = [("captured", c.joints[: int(max_seconds * c.fps)], c.fps) for c in test]
    texts = (list(FAST_PROMPTS.values()) + list(HELDOUT_PROMPTS.values()))[:prompts]
    gen = generate(texts, GenerateConfig(seconds=4.0, num=1, physics="none", seed=seed))
    return test, motions + [("generated", m.joints, float(m.fps)) for m in gen.motions], texts


def evaluate_rows(rows: dict[str, dict], motions: list[tuple[str, np.ndarray, float]],
                  workers: int = 0) -> tuple[list[str], list[list[str]], list[dict]]:  # fmt: skip
    """Every row ({name: spec}, :func:`evaluate_row`) on every motion of :func:`heldout_motions`. Returns
    (table header, table rows, per row its figures per set: motions, completed, survived, MPJPE mm,
    CPU s / s)."""
    from physmotion.physics.workers import imap_in_workers

    jobs = [(name, spec, j, fps) for name, spec in rows.items() for _, j, fps in motions]
    sets = [s for _ in rows for s, _, _ in motions]
    results: list = [None] * len(jobs)
    for i, res in imap_in_workers(evaluate_row, jobs, workers):
        results[i] = res | {"set": sets[i]}
    table, json_rows = [], []
    for name in rows:
        cells = [name]
        entry = {"row": name}
        for s in ("captured", "generated"):
            rs = [r for r in results if r["row"] == name and r["set"] == s]
            done = np.mean([r["survived"] == r["steps"] for r in rs])
            share = sum(r["survived"] for r in rs) / sum(r["steps"] for r in rs)
            err = np.nanmean([r["mpjpe"] for r in rs]) * 1000
            rel = np.nanmean([r["mpjpe_rel"] for r in rs]) * 1000
            cpu = sum(r["cpu"] for r in rs) / sum(r["seconds"] for r in rs)
            entry[s] = {"motions": len(rs), "completed": float(done), "survived": float(share), "mpjpe_mm": float(err),
                        "mpjpe_rel_mm": float(rel), "cpu_s_per_s": float(cpu)}  # fmt: skip
            cells += [f"{100 * done:.0f} %", f"{share:.2f}", f"{err:.0f} / {rel:.0f}", f"{cpu:.2f}"]
        table.append(cells)
        json_rows.append(entry)
    header = ["controller (no outside hand unless 'hand on')"]
    for s in ("captured", "generated"):
        header += [f"{s}: to the end", f"{s}: share survived", f"{s}: MPJPE world / pel-rel mm", f"{s}: CPU s / s"]
    return header, table, json_rows


def main(argv: list[str] | None = None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--teacher", default="runs/teacher")
    ap.add_argument("--data", default="data_build/all")
    ap.add_argument("--out", default="runs/learn")
    ap.add_argument("--dagger-rounds", type=int, default=2)
    ap.add_argument("--ppo", default=None, help="a PPO policy folder to evaluate (else one is trained here)")
    ap.add_argument("--ppo-minutes", type=float, default=8.0, help="PPO training warm-started from the last "
                    "student (0: none)")
    ap.add_argument("--captured-test", type=int, default=10)
    ap.add_argument("--max-seconds", type=float, default=5.0)
    ap.add_argument("--prompts", type=int, default=12, help="how many of the 12 evaluation prompts")
    ap.add_argument("--full-search", action=argparse.BooleanOptionalAction, default=True)
    ap.add_argument("--workers", type=int, default=0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--results", default="results/learn_from_search")
    args = parse_args(ap, argv)
    out = Path(args.out)
    records = load_teacher_set(args.teacher)
    cfg = StudentConfig(seed=args.seed)
    teacher_cpu = round(sum(float(r["cpu_seconds"]) for r in records))

    # (a) the naive form: BC on the search's committed offsets; then BC and DAgger on consistent labels
    naive = train_student(records, out / "search_labels", cfg, 0, Labeller(temperature=None), args.workers)
    folders = {"BC on the search's choices": naive["BC"]}
    for name, folder in train_student(records, out / "mppi_labels", cfg, args.dagger_rounds, Labeller(),
                                      args.workers).items():  # fmt: skip
        folders[f"{name} on MPPI labels"] = folder
    current = folders[list(folders)[-1]]
    if args.ppo is None and args.ppo_minutes > 0:  # (c) PPO tracking the searched trajectories, warm from (a)
        from physmotion.imitator.clips import training_sets
        from physmotion.imitator.train import ImitatorTrainConfig, no_hand_config, train_imitator

        clips, evals = training_sets([], [], 16, [args.teacher])
        ppo_cfg = no_hand_config(replace(ImitatorTrainConfig(), init_std=0.1, workers=args.workers, seed=args.seed))
        args.ppo = str(train_imitator(out / "ppo", clips, evals, minutes=args.ppo_minutes, config=ppo_cfg,
                                      sources=[args.teacher], warm_start=current))  # fmt: skip
    fits = {name: json.loads((Path(f) / "card.json").read_text())["fit"] for name, f in folders.items()}
    pairs = fits[list(fits)[-1]]["pairs"]
    _policy.cache_clear()

    test, motions, prompts = heldout_motions(args.data, args.captured_test, args.max_seconds, args.prompts, args.seed)
    rows: dict[str, dict] = {"tracker, hand on": {"kind": "tracker", "hand": True},
                             "tracker, hand off": {"kind": "tracker", "hand": False}}  # fmt: skip
    if args.full_search:
        rows["search default (full)"] = {"kind": "search", "config": effort("default", args.seed)}
    rows["MPPI labeller as a controller (32 x 1, lookahead 15)"] = {"kind": "expert"}
    for name, folder in folders.items():
        rows[f"{name} student"] = {"kind": "policy", "folder": folder}
    if args.ppo:
        rows[f"PPO on the searched trajectories, warm from {list(folders)[-1]}"] = {"kind": "policy",
                                                                                   "folder": args.ppo}
    for name, conf in SMALL_EFFORTS.items():
        conf = replace(conf, seed=args.seed)
        rows[f"search {name}"] = {"kind": "search", "config": conf}
        rows[f"amortized: {current.split('/')[-1]} + search {name}"] = {"kind": "search", "config": conf,
                                                                        "proposal": current}  # fmt: skip
    header, table, json_rows = evaluate_rows(rows, motions, args.workers)
    n_cap = sum(1 for s, _, _ in motions if s == "captured")
    text = (f"# Learning a fast controller from the search (no outside hand)\n\nWritten by "
            f"`python -m experiments.learn_from_search` (its docstring defines methods and columns). Teacher: "
            f"{len(records)} searched records ({teacher_cpu} CPU s), {pairs} labelled pairs at the "
            f"end. Evaluation: {n_cap} held-out captured clips, {len(motions) - n_cap} generated motions of "
            f"prompts never used for teacher data.\n\n{markdown_table(header, table)}\n")  # fmt: skip
    meta = run_meta(__file__, argv, args.tree, None)
    payload = {"meta": meta, "rows": json_rows, "fits": fits, "records": len(records), "pairs": pairs,
               "teacher_cpu_s": teacher_cpu, "prompts": prompts, "test_clips": [c.name for c in test]}  # fmt: skip
    write_results(args.results, text, payload)
    print(text)
    return payload


if __name__ == "__main__":
    main()
