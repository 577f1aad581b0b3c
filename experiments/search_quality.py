"""P with no outside hand: the searching controller against the tracker, on captured clips of every category
and on generated fast motion; writes results/search_quality.md and .json.

Usage: python -m experiments.search_quality [--efforts fast,default,best] [--captured-per 2] [--seeds 2]
       [--seconds 4] [--max-seconds 6] [--out results/search_quality] [--cost '{"world": 30}']

Motions:
- captured: the first ``--captured-per`` clips of each category of ``../shared/data/mocap``
  (experiments.projection_quality.category) and of each HDM05 class, at most ``--max-seconds`` each;
- generated: plain samples (``--physics none``, the default model, ``--seconds`` long) of fast-motion prompts
  (:data:`FAST_PROMPTS`: runs, jogs, sprints, jumps, hops, kicks), ``--seeds`` samples each.
Rows: the tracker with its outside hand (the plain preset), the same tracker with the hand off (root residual
force, lift and torque 0, no feet balance), and the search at each effort (no outside hand at all).
Per motion: carried to the end (no fall, no reset), world MPJPE (drift included) and pelvis-relative MPJPE to
the input, the pelvis's horizontal drift at the end, flight kept (both feet off the floor,
``metrics.actions.flight_height``, output over input) on jumps and hops, Penetrate / Float / Skate of input
(grounded on the body's surface: none+floor) and output, wall and CPU seconds per second of motion.
"""

from __future__ import annotations

import argparse
import warnings
import json
import time
from dataclasses import replace

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from experiments.projection_quality import category, measure_projection
from physmotion.conventions import FPS
from physmotion.io.importer import ClipInfo, import_clip, load_manifest
from physmotion.metrics.actions import flight_height
from physmotion.physics.presets import preset
from physmotion.physics.projection import ProjectionConfig
from physmotion.physics.search import EFFORTS, SearchCost, effort, no_hand, search_humanoid

FAST_PROMPTS = {  # kind -> prompt: generic wording of each kind of fast motion
    "run": "a person runs forward",
    "jog": "a person jogs forward",
    "sprint": "a person sprints forward fast",
    "jump": "a person jumps up high",
    "hop": "a person hops forward on one foot",
    "kick": "a person kicks with the right leg",
}
HELDOUT_PROMPTS = {  # the same kinds in other words, for a check on prompts the settings were not tuned on
    "run": "someone runs quickly in a straight line",
    "jog": "a man jogs slowly ahead",
    "sprint": "a person dashes forward as fast as possible",
    "jump": "a person jumps in place twice",
    "hop": "a person hops on the left leg",
    "kick": "a person does a front kick",
}
FLIGHT_KINDS = ("jump", "hop")


def captured_set(mocap: str, hdm05: str, per: int, only: str = "") -> list[tuple[str, ClipInfo]]:
    """(category, clip): the first ``per`` clips of each mocap category and of each HDM05 class (only those
    categories whose name contains one of the comma-separated words of ``only``, where given)."""
    picked: dict[str, list[ClipInfo]] = {}
    for info in load_manifest(mocap):
        picked.setdefault(category(info.captions), []).append(info)
    for info in load_manifest(hdm05):
        picked.setdefault("hdm05 " + info.path.parent.name, []).append(info)
    words = [w for w in only.split(",") if w]
    keep = [cat for cat in picked if not words or any(w in cat for w in words)]
    return [(cat, info) for cat in keep for info in picked[cat][:per]]


def generated_set(seconds: float, seeds: int, prompts: dict[str, str] = FAST_PROMPTS,
                  seed: int = 0) -> list[tuple[str, np.ndarray]]:  # fmt: skip
    """(kind, joints (T, 22, 3) at 20 fps): ``seeds`` plain samples of each of ``prompts`` (kind -> text)."""
    from physmotion.generate import GenerateConfig, generate

    texts = list(prompts.values())
    result = generate(texts, GenerateConfig(seconds=seconds, num=seeds, physics="none", seed=seed))
    kinds = [kind for kind in prompts for _ in range(seeds)]
    return [(kind, m.joints.astype(np.float64)) for kind, m in zip(kinds, result.motions)]


def rows(efforts: list[str], cost: SearchCost | None, cone_row: bool = True) -> dict[str, ProjectionConfig]:
    """Row label -> P's config. The tracker with and without its hand, under MuJoCo's default pyramidal
    friction cone and under the elliptic one at impratio 10 (what the search runs on; the tracker's own
    hand); the search on its own humanoid (:func:`search_humanoid`) at every effort in ``efforts``, and at
    the default effort under the pyramidal cone."""
    plain = preset("plain")
    elliptic = replace(plain.humanoid, cone="elliptic", impratio=10.0)
    pyramidal = replace(plain.humanoid, cone="pyramidal", impratio=1.0)
    out = {}
    for label, humanoid in (("pyramidal", pyramidal), ("elliptic", elliptic)):
        out[f"tracker, hand on, {label}"] = replace(plain, humanoid=humanoid)
        out[f"tracker, hand off, {label}"] = replace(plain, humanoid=humanoid, tracking=no_hand(plain.tracking))
    searched = search_humanoid(plain.humanoid)
    searches = [(name, searched, "elliptic") for name in efforts]
    if cone_row:  # before the slowest
        pyramidal_search = replace(searched, cone="pyramidal", impratio=1.0)
        searches.insert(min(2, len(searches)), ("default", pyramidal_search, "pyramidal"))
    for name, humanoid, label in searches:
        search = effort(name)
        search = replace(search, cost=cost) if cost is not None else search
        out[f"search {name}, {label}"] = replace(plain.with_controller("search", search=search), humanoid=humanoid)
    return out


def measure(kind: str, joints: np.ndarray, fps: float, config: ProjectionConfig) -> dict[str, float]:
    """One motion under one config: the per-motion figures of the module docstring."""
    wall, cpu = time.perf_counter(), time.process_time()
    m = measure_projection(joints, fps, replace(config, workers=1))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    r = m.result
    sim = r.simulated.astype(np.float64)
    rel = np.linalg.norm((sim - sim[:, :1]) - (joints - joints[:, :1]), axis=-1).mean()
    seconds = (len(joints) - 1) / fps
    row = {
        "kind": kind, "seconds": seconds,
        "completed": float(bool(r.success) and int(r.resets) == 0),
        "mpjpe_mm": 1000 * float(r.mpjpe.mean()), "rel_mpjpe_mm": 1000 * float(rel),
        "drift_mm": 1000 * float(np.linalg.norm(sim[-1, 0, [0, 2]] - joints[-1, 0, [0, 2]])),
        "help": float(r.residual_force.max() + r.residual_torque.max()), "over_limit": float(r.over_limit.mean()),
        "wall_per_s": wall / seconds, "cpu_per_s": cpu / seconds,
    }  # fmt: skip
    for key in ("penetrate", "float", "skate"):
        row[f"{key}_in"], row[f"{key}_out"] = float(m.before[key]), float(m.after[key])
    if kind in FLIGHT_KINDS:
        row["flight_in_cm"], row["flight_out_cm"] = 100 * flight_height(joints), 100 * flight_height(sim)
    return row


def summary(per_motion: list[dict[str, float]]) -> dict[str, float]:
    """Means over motions, completed as a share, flight kept as the median ratio."""
    out = {"motions": len(per_motion)}
    for key in ("completed", "mpjpe_mm", "rel_mpjpe_mm", "drift_mm", "help", "over_limit", "penetrate_in",
                "penetrate_out", "float_in", "float_out", "skate_in", "skate_out"):
        out[key] = float(np.mean([m[key] for m in per_motion]))
    out["skate_not_above_in"] = float(np.mean([m["skate_out"] <= m["skate_in"] for m in per_motion]))
    out["wall_per_s"] = float(np.median([m["wall_per_s"] for m in per_motion]))
    out["cpu_per_s"] = float(np.median([m["cpu_per_s"] for m in per_motion]))
    flights = [m["flight_out_cm"] / m["flight_in_cm"] for m in per_motion if m.get("flight_in_cm", 0) > 2.0]
    out["flight_kept"] = float(np.median(flights)) if flights else float("nan")
    return out


HEADER = ["set", "controller", "motions", "to the end, no reset", "MPJPE world / pelvis-rel mm", "drift mm",
          "flight kept (median)", "Penetrate in/out mm", "Float in/out mm", "Skate in/out mm",
          "Skate <= input", "outside help (max, W)", "wall s / s (median)", "CPU s / s"]  # fmt: skip


def _cells(group: str, label: str, s: dict[str, float]) -> list[str]:
    flight = "-" if np.isnan(s["flight_kept"]) else f"{s['flight_kept']:.2f}"
    return [group, label, str(s["motions"]), f"{100 * s['completed']:.0f} %",
            f"{s['mpjpe_mm']:.0f} / {s['rel_mpjpe_mm']:.0f}", f"{s['drift_mm']:.0f}", flight,
            f"{s['penetrate_in']:.1f} / {s['penetrate_out']:.1f}", f"{s['float_in']:.1f} / {s['float_out']:.1f}",
            f"{s['skate_in']:.1f} / {s['skate_out']:.1f}", f"{100 * s['skate_not_above_in']:.0f} %",
            f"{s['help']:.2f}", f"{s['wall_per_s']:.1f}", f"{s['cpu_per_s']:.1f}"]  # fmt: skip


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--hdm05", default="../shared/data/hdm05")
    parser.add_argument("--efforts", default="fast,default,best")
    parser.add_argument("--captured-per", type=int, default=2)
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--seconds", type=float, default=4.0)
    parser.add_argument("--max-seconds", type=float, default=6.0)
    parser.add_argument("--categories", default="", help="only captured categories containing these words")
    parser.add_argument("--cost", default="", help="JSON of SearchCost fields to override")
    parser.add_argument("--prompt-set", choices=("fast", "heldout"), default="fast",
                        help="FAST_PROMPTS, or HELDOUT_PROMPTS (the same kinds in other words)")
    parser.add_argument("--seed", type=int, default=0, help="generation's seed")
    parser.add_argument("--no-cone-row", action="store_true", help="leave out the search under the pyramidal cone")
    parser.add_argument("--out", default="results/search_quality", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    warnings.filterwarnings("ignore", message=".*read as Latin-1")  # HDM05's header bytes, as documented
    efforts = [e for e in args.efforts.split(",") if e]
    for e in efforts:
        effort(e)  # a bad name fails here, before any work
    cost = SearchCost(**json.loads(args.cost)) if args.cost else None
    motions: list[tuple[str, str, np.ndarray]] = []  # (set, kind, joints at FPS)
    for cat, info in captured_set(args.mocap, args.hdm05, args.captured_per, args.categories):
        joints = import_clip(info, floor="frame0").joints.astype(np.float64)
        motions.append(("captured", cat, joints[: int(args.max_seconds * FPS) + 1]))
    if args.seeds:
        prompts = HELDOUT_PROMPTS if args.prompt_set == "heldout" else FAST_PROMPTS
        motions += [("generated", kind, j) for kind, j in generated_set(args.seconds, args.seeds, prompts, args.seed)]
    print(f"{len(motions)} motions", flush=True)
    configs = rows(efforts, cost, cone_row=not args.no_cone_row)
    meta = run_meta(__file__, argv, args.tree, "plain", efforts=efforts, cost=args.cost or "default")
    per: dict[str, dict[str, list[dict]]] = {}
    seconds: dict[str, float] = {}
    for label, config in configs.items():  # the table is written after every row: a long run keeps what it has
        start = time.perf_counter()
        for group, kind, joints in motions:
            per.setdefault(group, {}).setdefault(label, []).append(measure(kind, joints, FPS, config))
        seconds[label] = time.perf_counter() - start
        print(f"{label}: {seconds[label]:.0f} s", flush=True)
        md = _markdown(per, args, efforts, len(configs) - len(seconds))
        write_results(args.out, md, {"meta": meta | {"seconds": seconds}, "per_motion": per})
    print(md)


def _markdown(per: dict[str, dict[str, list[dict]]], args, efforts: list[str], left: int) -> str:
    table = [_cells(g, label, summary(ms)) for g, by_label in per.items() for label, ms in by_label.items()]
    pending = f" ({left} rows still to run)" if left else ""
    return "\n".join([
        "# P with no outside hand: the search against the tracker", "",
        "Written by `python -m experiments.search_quality` (its docstring defines every column). Captured: the "
        f"first {args.captured_per} clips of each category and HDM05 class (at most {args.max_seconds:g} s); "
        f"generated: plain samples of {len(FAST_PROMPTS)} fast-motion prompts ({args.prompt_set} set, seed "
        f"{args.seed}) x {args.seeds} samples, {args.seconds:g} s. Search efforts: " + "; ".join(
            f"{e}: {EFFORTS[e].candidates} candidates x {EFFORTS[e].rounds} rounds, lookahead {EFFORTS[e].horizon}"
            for e in efforts) + f"{pending}.", "",
        markdown_table(HEADER, table), ""])  # fmt: skip


if __name__ == "__main__":
    main()
