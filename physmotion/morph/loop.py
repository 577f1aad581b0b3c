"""Morph's multi-round iterative optimisation (Sec. 3.3 "Multi-Round Iterative Optimization", App. E):
round k generates a synthetic set with the current model and refines it with P
(:func:`physmotion.morph.synth.synthesize`), applies the imitation selection
(:func:`physmotion.morph.selection.select`) and fine-tunes the model on it
(:func:`physmotion.morph.finetune.finetune`); round k+1 starts from round k's weights.

Layout of a run folder::

    RUN/round_<k>/synth/    the synthetic set of round k (made by round k-1's model, the base for k = 1)
    RUN/round_<k>/model/    the fine-tuned model of round k (a training run: model, train_state.pt, loss.csv)
    RUN/rounds.md, .json    one row per finished round

A run resumes at round granularity: a round in ``rounds.json`` is skipped; an unfinished one continues
its synthesis (``synthesize`` goes on where it stopped) and its fine-tuning (``--resume``).
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING

from physmotion.checkpoint import weights_sha256
from physmotion.diffusion.train import STATE_FILE
from physmotion.errors import PhysmotionError
from physmotion.morph.finetune import FinetuneConfig, check_model_dir, finetune
from physmotion.motion import write_atomic

if TYPE_CHECKING:
    from physmotion.morph.synth import SynthConfig

ROUNDS_FILE = "rounds"  # rounds.md and rounds.json
COLUMNS = (("round", "round"), ("synthetic_items", "synthetic items"), ("refined", "refined kept"),
           ("inputs", "inputs kept"), ("non_grounded", "non-grounded"), ("ifr", "IFR"),
           ("finetune_steps", "fine-tune steps"), ("final_loss", "final loss"),
           ("synth_seconds", "synth s"), ("finetune_seconds", "fine-tune s"))  # fmt: skip


@dataclass
class RoundRow:
    """One finished round. Seconds are the wall time spent on it by the invocation(s) that ran it."""

    round: int
    synthetic_items: int
    refined: int
    inputs: int
    non_grounded: int
    ifr: float
    finetune_steps: int
    final_loss: float
    synth_seconds: float
    finetune_seconds: float
    model: str


def round_dir(out_dir: str | Path, k: int) -> Path:
    return Path(out_dir) / f"round_{k}"


def read_rounds(out_dir: str | Path) -> dict:
    """The run record of ``out_dir`` (``{"meta": ..., "rounds": [...]}``), empty for a new run."""
    path = Path(out_dir) / f"{ROUNDS_FILE}.json"
    if not path.is_file():
        return {"meta": {}, "rounds": []}
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return {"meta": dict(data["meta"]), "rounds": list(data["rounds"])}
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PhysmotionError(f"{path}: not a Morph run record ({type(exc).__name__}); move it away") from None


def check_run_dir(out_dir: str | Path, model_dir: str | Path) -> None:
    """``out_dir`` must be new, empty, or a run of this loop from the same base model (then it resumes)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise PhysmotionError(f"{out} is a file, not a folder; give a folder")
    if out.is_dir() and any(out.iterdir()):
        meta = read_rounds(out)["meta"]
        if not meta:
            raise PhysmotionError(f"{out} is a folder that is not empty and holds no Morph run; choose another -o")
        sha = weights_sha256(model_dir)
        if meta.get("base_model_sha256") != sha:
            raise PhysmotionError(f"{out} holds a Morph run from another base model ({meta.get('base_model')}); "
                                  "choose another -o")  # fmt: skip


def run_rounds(
    model_dir: str | Path,
    data_dir: str | Path,
    out_dir: str | Path,
    rounds: int,
    synth_config: SynthConfig,
    finetune_config: FinetuneConfig,
    progress: bool = True,
    *,
    synthesize_fn: Callable | None = None,
) -> list[RoundRow]:
    """Run (or continue) ``rounds`` Morph rounds from ``model_dir``; returns every finished round's row.

    finetune_config: the settings of each fine-tuning (its model, synth, data and out are set per round).
    synthesize_fn: ``synthesize(model_dir, data_dir, out_dir, config, progress)``, by default
    :func:`physmotion.morph.synth.synthesize` (a test passes a stand-in)."""
    if rounds < 1:
        raise PhysmotionError(f"--rounds must be at least 1, got {rounds}")
    model_dir = check_model_dir(model_dir)
    check_run_dir(out_dir, model_dir)
    if synthesize_fn is None:
        from physmotion.morph.synth import synthesize as synthesize_fn
    out = Path(out_dir)
    record = read_rounds(out)
    record["meta"] = record["meta"] or {
        "base_model": str(model_dir), "base_model_sha256": weights_sha256(model_dir),
        "data": str(data_dir), "synth": _settings(synth_config),
        "finetune": {k: v for k, v in asdict(finetune_config).items() if k not in ("model", "synth", "data", "out")},
    }  # fmt: skip
    if not (out / f"{ROUNDS_FILE}.json").is_file():
        write_table(out, record)  # marks the folder as this run's before any round, so it resumes
    done = {int(r["round"]): r for r in record["rounds"]}
    current = model_dir
    for k in range(1, rounds + 1):
        rdir = round_dir(out, k)
        if k in done and (rdir / "model" / "config.json").is_file():
            current = rdir / "model"  # a finished round: its weights start the next
            continue
        t0 = time.monotonic()
        synthesize_fn(current, data_dir, rdir / "synth", synth_config, progress)
        t1 = time.monotonic()
        cfg = replace(finetune_config, model=str(current), synth=str(rdir / "synth"), data=str(data_dir),
                      out=str(rdir / "model"))  # fmt: skip
        result = finetune(cfg, resume=(rdir / "model" / STATE_FILE).is_file(), progress=progress)
        t2 = time.monotonic()
        c = result.selection.counts
        row = RoundRow(round=k, synthetic_items=c.get("items", 0), refined=c.get("refined", 0),
                       inputs=c.get("input", 0), non_grounded=c.get("non_grounded", 0), ifr=result.selection.ifr,
                       finetune_steps=result.train.step,
                       final_loss=result.train.losses[-1][1] if result.train.losses else float("nan"),
                       synth_seconds=round(t1 - t0, 1), finetune_seconds=round(t2 - t1, 1),
                       model=str(rdir / "model"))  # fmt: skip
        done[k] = asdict(row)
        record["rounds"] = [done[i] for i in sorted(done)]
        write_table(out, record)
        current = rdir / "model"
    names = {f.name for f in fields(RoundRow)}  # a record may carry more (a note written by hand): kept, not read
    return [RoundRow(**{k: v for k, v in done[i].items() if k in names}) for i in sorted(done) if i <= rounds]


def _settings(config) -> dict:
    try:
        return asdict(config)
    except TypeError:
        return {}


def write_table(out_dir: str | Path, record: dict) -> list[Path]:
    """``rounds.md`` and ``rounds.json`` of a run, atomically."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    md, js = out / f"{ROUNDS_FILE}.md", out / f"{ROUNDS_FILE}.json"
    lines = [f"Morph rounds from `{record['meta'].get('base_model', '')}` on `{record['meta'].get('data', '')}`.", "",
             "| " + " | ".join(label for _, label in COLUMNS) + " |", "|" + "---:|" * len(COLUMNS)]  # fmt: skip
    for row in record["rounds"]:
        lines.append("| " + " | ".join(_cell(row.get(key)) for key, _ in COLUMNS) + " |")
    text = "\n".join(lines) + "\n"
    write_atomic(md, lambda f: f.write(text), "w")
    data = json.dumps(record, indent=2)
    write_atomic(js, lambda f: f.write(data), "w")
    return [md, js]


def _cell(value) -> str:
    if isinstance(value, float):
        return f"{value:.4f}" if abs(value) < 10 else f"{value:.1f}"
    return "-" if value is None else str(value)
