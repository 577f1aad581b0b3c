"""Morph's Tables 1/2 on our data: the base model and each fine-tuned round, each in several physics modes.

    python -m experiments.morph --data data_build/mocap --run runs/morph -o results/morph

runs `physmotion evaluate` on the base model and on every ``<run>/round_<k>/model`` that `physmotion morph
run` wrote, on the same split, captions, lengths and seeds, and writes one table (<out>.md, <out>.json):
rows "<model> <mode>" (e.g. "base physdiff:end:4,space:1", "round 1 morph"), plus the real motions, with
each round's synthetic-data figures (items, refined kept, IFR) from ``<run>/rounds.json`` in the JSON's meta.
Each (model, mode) table is kept in ``<out>.parts/`` and reused by a re-run with the same settings and
the same weights (sha256). The base model is the one the run recorded; a folder whose weights changed
since (the shipped default after a new release) is refused: pass the run's base with ``--base``.
With ``--control DIR`` (repeatable) a model fine-tuned by `morph finetune --mix 0` (the same fine-tune
on the real train split alone) adds rows "control <steps> steps none" and "... none+floor": what the
synthetic items add beyond continued training on the re-floored real motions.
It is a script rather than a command because it is a study over several models. P: the ``sampling``
preset in post:1 and PhysDiff, ``plain`` in morph (the table's meta records both).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from experiments._results import parse_args, report, run_meta
from physmotion.checkpoint import weights_sha256
from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
from physmotion.diffusion.samplers import ddim_50
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.table import REAL, EvalTable, EvaluateConfig, evaluate
from physmotion.generate import GenerateConfig
from physmotion.morph.loop import read_rounds
from physmotion.pipelines.modes import parse_modes

# post:1 is one P with the sampling preset's reset instead of Morph's selection: the cheapest projection
# after sampling, and what one P can do for a tuned model (docs/decisions/morph.md "one P on the Morph
# model").
MODES = "none,none+floor,post:1,morph,physdiff:end:4,space:1"
CONTROL_MODES = "none,none+floor"


def _rounds(run: Path) -> list[tuple[str, Path]]:
    """("round k", model folder) of every finished round of a `morph run` folder, in order."""
    found = sorted((int(p.parent.name.split("_")[1]), p) for p in run.glob("round_*/model")
                   if (p / "config.json").is_file())  # fmt: skip
    if not found:
        raise PhysmotionError(f"{run}: no finished round (round_<k>/model with config.json)")
    return [(f"round {k}", p) for k, p in found]


def _base(run: Path, base: str | None) -> Path:
    """The run's base model folder: ``base``, else the one ``<run>/rounds.json`` names; its weights must be
    the ones the run started from."""
    meta = read_rounds(run)["meta"]
    folder = Path(base or meta.get("base_model") or DEFAULT_MODEL_DIR)
    if meta.get("base_model_sha256") and weights_sha256(folder) != meta["base_model_sha256"]:
        raise PhysmotionError(f"{folder}'s weights are not those {run} started from (sha256 "
                              f"{meta['base_model_sha256'][:12]}): pass --base with that model")
    return folder


def _control(folder: Path) -> tuple[str, Path]:
    """("control <steps> steps", folder) of a model fine-tuned with ``morph finetune --mix 0``."""
    morph = MotionDiffusion.load(folder).info.get("morph", {})
    if morph.get("mix") != 0:
        raise PhysmotionError(f"{folder} is not a `morph finetune --mix 0` model (mix {morph.get('mix')})")
    return f"control {morph['steps']} steps", folder


def morph_table(data: str, run: Path, base: str | None, cfg: EvaluateConfig, evaluator: Evaluator,
                parts: Path, controls: list[Path] = ()) -> EvalTable:  # fmt: skip
    """One EvalTable over the base model and every round of ``run`` (MODES), and each real-only control
    (CONTROL_MODES).

    Each (model, mode) table is kept in ``parts/<model>__<mode>.json`` and reused by a re-run with the same
    settings: an interrupted study loses at most one evaluation, and a changed mode is re-run alone
    (evaluate draws captions and noise per repeat, not per mode, so the parts are the rows of one run)."""
    from dataclasses import replace

    rows: dict = {}
    meta: dict = {"models": {}, "rounds": {}}
    models = [("base", _base(run, base), MODES)] + [(n, f, MODES) for n, f in _rounds(run)]
    models += [(*_control(Path(c)), CONTROL_MODES) for c in controls]
    for name, folder, modes in models:
        net, sha = None, weights_sha256(folder)
        for mode in (str(m) for m in parse_modes(modes)):
            run_cfg = replace(cfg, modes=(mode,))
            part = parts / f"{name.replace(' ', '_')}__{mode.replace(':', '_').replace(',', '_')}.json"
            table = EvalTable.from_json(part) if part.is_file() else None
            wanted = {"modes": [mode], "repeats": run_cfg.repeats, "split": run_cfg.split, "seed": run_cfg.seed,
                      "model_sha256": sha}  # fmt: skip
            if table is None or {k: table.meta.get(k) for k in wanted} != wanted:
                net = net or MotionDiffusion.load(folder)
                table = evaluate(net, evaluator, data, run_cfg)
                table.meta.update(model_folder=str(folder), model_sha256=sha)
                table.write(part.with_suffix(""))
            rows.setdefault(REAL, table.rows[REAL])
            rows[f"{name} {mode}"] = table.rows[mode]
            meta["models"].setdefault(name, {"folder": str(folder), **table.meta, "modes": []})
            meta["models"][name]["modes"].append(mode)
    first = next(iter(meta["models"].values()))  # every model ran on the same split, sampler and surface
    meta.update({k: first[k] for k in ("split", "motions", "repeats", "sampler", "surface", "seed", "data")})
    summary = run / "rounds.json"
    if summary.is_file():
        meta["rounds"] = json.loads(summary.read_text())
    return EvalTable(rows=rows, meta=meta)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True, help="HumanML3D-layout folder")
    parser.add_argument("--run", required=True, type=Path, help="a `physmotion morph run` folder")
    parser.add_argument("-o", "--out", default="results/morph", help="output stem")
    parser.add_argument("--base", default=None, help="base model folder (default: the one the run names)")
    parser.add_argument("--evaluator", default=None, help="evaluator folder (default: the shipped one)")
    parser.add_argument("--split", default="test")
    parser.add_argument("--repeats", type=int, default=EvaluateConfig.repeats)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--control", action="append", default=[], type=Path,
                        help="a model made by `morph finetune --mix 0` (repeatable)")
    args = parse_args(parser, argv)

    def run() -> tuple[str, list[Path]]:
        cfg = EvaluateConfig(split=args.split, repeats=args.repeats, seed=args.seed,
                             base=GenerateConfig(sampler=ddim_50()))  # the schedules of MODES are DDIM 50's
        parts = Path(f"{args.out}.parts")
        table = morph_table(args.data, args.run, args.base, cfg, Evaluator.load(args.evaluator), parts,
                            args.control)
        presets = {"post, physdiff": "sampling", "morph": "plain"}
        table.meta.update(run_meta(__file__, argv, args.tree, presets))
        return table.to_markdown(), table.write(args.out)

    return report(run)


if __name__ == "__main__":
    sys.exit(main())
