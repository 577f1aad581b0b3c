"""The old and the retrained default model in one table (issue 50, item 4): the same evaluator, data,
split, sampler and seeds for both.

    python -m experiments.retrained_default --data data_build/all --old OLD_MODEL --new NEW_MODEL
        --evaluator EVALUATOR [--physics MODES] [--tables runs/retrained_default]
        [--out results/retrained_default] [--title TITLE] [--names old,new]

Each model gets one ``physmotion evaluate`` run (:func:`evaluate_command` spells it; test split, 3
repeats, the default sampler, seed 0) for the physics modes (default :data:`MODES`), written to
``<tables>/<label>.{md,json}``. A table already there is read, after checking that its meta names the
same computation (its modes may be more), instead of re-run; a mode a table lacks is left out of its
rows, so another model's table (the Morph-tuned one's, with ``morph``) can be set beside it. With the
default modes, the new model's table is ``physmotion evaluate``'s default computation once the new model
and evaluator are the shipped ones, so it doubles as ``results/evaluate_default``. The new model's FID
and R@3 are held against the old one's 95 % intervals: within or better (FID at most the upper edge,
R@3 at least the lower edge), the issue's acceptance.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from experiments._results import (
    ROOT,
    heading,
    markdown_table,
    parse_args,
    report,
    run_meta,
    within_interval,
    write_results,
)
from physmotion.errors import PhysmotionError
from physmotion.pipelines.modes import parse_modes

MODES = ("none", "none+floor", "post:1", "post:4", "physdiff:end:2,space:1")  # evaluate's default modes
REPEATS = 3
LABELS = ("old", "new")
GENERATION = ("FID", "R@1", "R@3", "MM-Dist", "Diversity", "MModality")
PHYSICAL = ("penetrate", "float", "skate", "phys_err", "reset_rate")


def evaluate_command(
    model: str, evaluator: str, data: str, stem: Path, modes: tuple[str, ...] = MODES
) -> str:
    """The ``physmotion evaluate`` command that writes one model's table at ``stem``."""
    return (f"physmotion evaluate --data {data} --model {model} --evaluator {evaluator} "
            f"--physics {','.join(modes)} --repeats {REPEATS} -o {stem}")  # fmt: skip


def _check_meta(meta: dict, data: str, path: Path) -> None:
    """Refuse a table that is not this experiment's computation (any modes)."""
    want = {"split": "test", "repeats": REPEATS, "seed": 0, "data": str(data)}
    got = {k: meta.get(k) for k in want}
    if got != want:
        raise PhysmotionError(f"{path}: not this experiment's run ({got} vs {want})")


def tables(models: dict[str, str], evaluator: str, data: str, out: Path,
           modes: tuple[str, ...] = MODES) -> dict[str, dict]:  # fmt: skip
    """label -> the evaluate table (as ``EvalTable.to_json`` writes it), read from ``out`` or computed for
    ``modes``."""
    result = {}
    for label, model_dir in models.items():
        path = out / f"{label}.json"
        if not path.exists():
            from physmotion.diffusion.model import MotionDiffusion
            from physmotion.eval.evaluator import Evaluator
            from physmotion.eval.table import EvaluateConfig, evaluate

            print(f"evaluating {label}: {evaluate_command(model_dir, evaluator, data, out / label, modes)}",
                  flush=True)  # fmt: skip
            table = evaluate(MotionDiffusion.load(model_dir), Evaluator.load(evaluator), data,
                             EvaluateConfig(modes=modes, repeats=REPEATS))  # fmt: skip
            table.meta["model"] = model_dir
            table.write(out / label)
        result[label] = json.loads(path.read_text())
        _check_meta(result[label]["meta"], data, path)
    return result


def rows(found: dict[str, dict], modes: tuple[str, ...] = MODES) -> list[dict]:
    """One row per (mode, model) where that model's table has the mode, the real data's row first; FID and
    R@3 of each new row against the old model's same mode, where both have it."""
    old = found["old"]["rows"]
    out = [{"model": "real", "physics": "-", **found["old"]["rows"]["real"]}]
    for mode in modes:
        for label in LABELS:
            r = found[label]["rows"].get(mode)
            if r is None:
                continue
            row = {"model": label, "physics": mode, **r}
            if label == "new" and mode in old:
                row["FID_within"] = within_interval(r["FID"]["mean"], old[mode]["FID"], False)
                row["R@3_within"] = within_interval(r["R@3"]["mean"], old[mode]["R@3"], True)
            out.append(row)
    return out


def _fmt(v: dict | None, digits: int) -> str:
    if v is None:
        return "-"
    return f"{v['mean']:.{digits}f}" + (f" ± {v['ci95']:.{digits}f}" if v["ci95"] else "")


def markdown(table_rows: list[dict], meta: dict) -> str:
    """The table with a header saying how it was made."""
    header = ["model", "physics", *GENERATION, *(f"{c} mm" if c != "reset_rate" else c for c in PHYSICAL),
              f"FID, R@3 within {meta['names']['old']}'s"]  # fmt: skip
    body = []
    for r in table_rows:
        within = (f"{'yes' if r['FID_within'] else 'no'}, {'yes' if r['R@3_within'] else 'no'}"
                  if "FID_within" in r else "-")  # fmt: skip
        name = meta["names"].get(r["model"], r["model"])
        body.append([name, r["physics"], *(_fmt(r.get(c), 3) for c in GENERATION),
                     *(_fmt(r.get(c), 2) for c in PHYSICAL), within])  # fmt: skip
    old, new = meta["names"]["old"], meta["names"]["new"]
    return (heading(meta["title"], meta) +
            f"{old}: `{meta['models']['old']}` ({meta['trained_on']['old']}); "
            f"{new}: `{meta['models']['new']}` ({meta['trained_on']['new']}). Evaluator "
            f"`{meta['evaluator']}`. `{meta['data']}` test split ({meta['motions']} motions), {REPEATS} "
            f"repeats, mean ± 95 % interval, the default sampler ({meta['sampler']}), seed 0; physical "
            f"metrics on the humanoid surface. {new}'s FID and R@3 are held against {old}'s in the same mode "
            f"(within the interval or better).\n\n" + markdown_table(header, body) + "\n")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--data", required=True, help="HumanML3D-layout build whose test split both are evaluated on"
    )
    ap.add_argument("--old", required=True, help="the old model folder")
    ap.add_argument("--new", required=True, help="the retrained model folder")
    ap.add_argument("--evaluator", required=True, help="evaluator folder (trained on --data's train split)")
    ap.add_argument(
        "--physics", default=",".join(MODES), help="physics modes, comma-separated (as evaluate's)"
    )
    ap.add_argument("--tables", type=Path, default=ROOT / "runs" / "retrained_default")
    ap.add_argument("--out", type=Path, default=ROOT / "results" / "retrained_default")
    ap.add_argument("--title", default="The old and the retrained default model (issue 50, item 4)")
    ap.add_argument("--names", default="old,new", help="what the table calls the two models, comma-separated")
    args = parse_args(ap, argv)

    def run() -> tuple[str, list[Path]]:
        modes = tuple(str(m) for m in parse_modes(args.physics))
        found = tables({"old": args.old, "new": args.new}, args.evaluator, args.data, args.tables, modes)
        m = found["new"]["meta"]
        names = args.names.split(",")
        if len(names) != 2:
            raise PhysmotionError(f"--names takes two names, got {args.names!r}")
        meta = run_meta(__file__, argv, args.tree, preset={"physdiff": "sampling"}, data=args.data,
                        evaluator=args.evaluator, title=args.title, names=dict(zip(LABELS, names)),
                        models={"old": args.old, "new": args.new}, motions=m["motions"], repeats=REPEATS,
                        trained_on={k: f"{v['meta']['model_trained_on']}, {v['meta']['model_steps']} steps, "
                                       f"licence {v['meta']['model_licence']}" for k, v in found.items()},
                        sampler=f"{m['sampler']['sampler']} {m['sampler']['steps']} steps, CFG "
                                f"{m['sampler']['cfg_scale']}")  # fmt: skip
        table_rows = rows(found, modes)
        plain = next(r for r in table_rows if r["model"] == "new" and r["physics"] == "none")
        payload = {
            "meta": meta,
            "rows": table_rows,
            "acceptance": {"FID_within": plain["FID_within"], "R@3_within": plain["R@3_within"]},
        }
        text = markdown(table_rows, meta)
        return text, write_results(args.out, text, payload)

    return report(run)


if __name__ == "__main__":
    raise SystemExit(main())
