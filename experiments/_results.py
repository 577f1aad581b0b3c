"""What every experiment writes: ``results/<name>.md`` (the table) and ``results/<name>.json`` (the
figures), the JSON with a ``meta`` block saying what made it: P's preset(s) by name
(:mod:`physmotion.physics.presets`), the commit, the CPU, the date and the command line.

A figure must come from committed code: :func:`parse_args` gives every experiment the shared
``--allow-dirty`` flag and refuses, before any work, a tree whose tracked files differ from HEAD unless it
is given; the meta then records ``"dirty": true`` and the commit with "+dirty"."""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from collections.abc import Callable, Sequence
from datetime import datetime, timezone
from pathlib import Path

from physmotion.errors import PhysmotionError
from physmotion.motion import write_atomic
from physmotion.provenance import Checkout, checkout, cpu_model

ROOT = Path(__file__).resolve().parents[1]
Presets = str | dict[str, str] | None  # one preset, a preset per role or row, or None where P does not run


Tree = Checkout  # the checkout an experiment ran from (physmotion.provenance)


def tree_state(root: Path | None = None) -> Tree:
    """The state of the git checkout at ``root`` (default: this repository); outside a git checkout the
    commit reads "unknown+dirty" (nothing says it is clean)."""
    state = checkout(root or ROOT)
    return state if state.commit is not None else Tree("unknown+dirty", True)


def parse_args(parser: argparse.ArgumentParser, argv: Sequence[str] | None) -> argparse.Namespace:
    """``parser.parse_args(argv)`` with the flag every experiment shares, ``--allow-dirty``, added; then the
    checkout is read once, before any work, into ``args.tree`` (:class:`Tree`, what :func:`run_meta`
    records). A dirty tree without ``--allow-dirty`` exits with one ``error:`` line (status 1)."""
    parser.add_argument("--allow-dirty", action="store_true",
                        help="run although tracked files differ from HEAD (the results' meta records "
                             '"dirty": true); without it a dirty tree is refused')  # fmt: skip
    args = parser.parse_args(argv)
    args.tree = tree_state(ROOT)
    if args.tree.dirty and not args.allow_dirty:
        unknown = args.tree.commit.startswith("unknown")
        where = "not a git checkout" if unknown else "tracked files differ from HEAD"
        raise SystemExit(f"error: {ROOT}: {where}; commit first so the figures name the code that "
                         "made them, or pass --allow-dirty")  # fmt: skip
    return args


def run_meta(script: str, argv: Sequence[str] | None, tree: Tree, preset: Presets, **extra) -> dict:
    """The meta block of a run of the experiment ``script`` (its ``__file__``) with arguments ``argv``
    (None: this process's) from the checkout ``tree`` (``args.tree`` of :func:`parse_args`, read when the
    run began: its own outputs written since do not count); ``extra`` (the experiment's own settings)
    follows the common keys."""
    args = sys.argv[1:] if argv is None else argv
    command = shlex.join(["python", "-m", f"experiments.{Path(script).stem}", *args])
    return {"preset": preset, "commit": tree.commit, "dirty": tree.dirty, "cpu": cpu_model(),
            "date": datetime.now(timezone.utc).isoformat(timespec="seconds"), "command": command, **extra}  # fmt: skip


def write_results(stem: str | Path, markdown: str, payload: dict) -> list[Path]:
    """Write ``<stem>.md`` and ``<stem>.json`` (``payload``: strict JSON, NaN written as null) atomically;
    returns their paths."""
    stem = Path(stem)
    md, js = stem.with_name(stem.name + ".md"), stem.with_name(stem.name + ".json")
    text = json.dumps(_finite(payload), indent=2, allow_nan=False) + "\n"
    write_atomic(md, lambda f: f.write(markdown if markdown.endswith("\n") else markdown + "\n"), "w")
    write_atomic(js, lambda f: f.write(text), "w")
    return [md, js]


def report(run: Callable[[], tuple[str, list[Path]]]) -> int:
    """Run an experiment (``run`` returns its table and the files it wrote) and print both; a user's
    error (:class:`PhysmotionError`, ``ValueError``) becomes one ``error:`` line. The exit status."""
    try:
        table, paths = run()
    except (PhysmotionError, ValueError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    print(table)
    print("wrote " + ", ".join(map(str, paths)))
    return 0


def heading(title: str, meta: dict) -> str:
    """A results file's first lines: ``# title``, then the command, commit, CPU and date of ``meta``."""
    return f"# {title}\n\n`{meta['command']}` (commit {meta['commit']}, {meta['cpu']}, {meta['date']})\n\n"


def within_interval(value: float, ref: dict, higher_better: bool) -> bool:
    """``value`` inside ``ref``'s 95 % interval (``{"mean", "ci95"}``) or better than it: at least its lower
    edge where higher is better (R@3), at most its upper edge otherwise (FID)."""
    return value >= ref["mean"] - ref["ci95"] if higher_better else value <= ref["mean"] + ref["ci95"]


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A Markdown table: one header row, then one row per entry of ``rows`` (cells as ``str`` gives them)."""
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _finite(value: object) -> object:
    """``value`` with every NaN or infinite float (nested in dicts, lists and tuples) replaced by None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite(v) for v in value]
    return value
