"""What ``physmotion metrics`` prints or writes: one column (or row) per file, labelled so that files of
the same name in different folders stay apart, as a table that fits the terminal, JSON or CSV."""

from __future__ import annotations

import csv
import io
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
from rich.console import Console
from rich.table import Table

from physmotion.errors import PhysmotionError
from physmotion.metrics.physical import METRICS, RECORDED, format_table

# For motions that predate the per-update record (``Motion.residual_at_cap``): a frame's root residual force
# this close to its cap counts as at the cap. The frame value is the mean of its residual updates, so it
# reaches the cap only when every update was clipped, and the lift and torque caps are not seen at all
# (docs/decisions/metrics.md: "frames at the residual's cap and projections that fell", "help in full").
AT_CAP = 0.99


def path_labels(paths: Sequence[str | Path]) -> list[str]:
    """One label per path: its shortest trailing part that no other path shares.

    ``a/x.npz, b/x.npz, c/y.npz`` -> ``a/x.npz, b/x.npz, y.npz``. The same path given twice gets
    ``#2``, ``#3`` appended, so every argument keeps its own label.
    """
    parts = [Path(os.path.normpath(p)).parts for p in paths]
    labels = []
    for i, own in enumerate(parts):
        for k in range(1, len(own) + 1):
            tail = own[-k:]
            if all(other[-k:] != tail for j, other in enumerate(parts) if j != i):
                break
        labels.append(str(Path(*tail)))
    seen: dict[str, int] = {}
    for i, label in enumerate(labels):
        seen[label] = seen.get(label, 0) + 1
        if seen[label] > 1:
            labels[i] = f"{label}#{seen[label]}"
    return labels


def check_npz(path: str | Path) -> Path:
    """``path`` if it names an .npz; a one-line PhysmotionError for any other file (a .bvh, say)."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise PhysmotionError(f"{path}: metrics expects .npz; run `physmotion import` first")
    return path


def fit_table(results: Mapping[str, Mapping[str, float]], title: str, width: int) -> tuple[Table, list[str]]:
    """The metrics table for a terminal ``width`` columns wide, and the lines of a legend under it.

    Columns are labelled by ``results``' keys where the table fits; otherwise by ``#1``, ``#2`` ... with
    the legend naming each (and, if that is still too wide, without the paper column), so a rich table
    never cuts a file name short. A table too wide even then is
    returned as is: print it with no width limit (``table_width``).
    """
    table = format_table(results, title=title)
    if table_width(table) <= width:
        return table, []
    numbered = {f"#{i + 1}": r for i, r in enumerate(results.values())}
    legend = [f"#{i + 1}  {label}" for i, label in enumerate(results)]
    table = format_table(numbered, title=title)
    if table_width(table) > width:
        table.columns.pop(2)  # the "paper" column (rich keeps cells in their column); --json has it
    return table, legend


def table_width(table: Table) -> int:
    """Columns ``table`` needs to print without squeezing any cell."""
    console = Console(width=100_000, file=io.StringIO())
    return console.measure(table).maximum


def to_json(results: Mapping[str, Mapping[str, float]], paths: Sequence[str | Path], surface: str) -> str:
    """``{"surface", "units", "files": [{"label", "path", "metrics"}]}`` as indented JSON."""
    files = [{"label": label, "path": str(path), "metrics": dict(r)}
             for (label, r), path in zip(results.items(), paths)]  # fmt: skip
    known = METRICS | RECORDED
    units = {name: known[name].unit for name in known if any(name in r for r in results.values())}
    return json.dumps({"surface": surface, "units": units, "files": files}, indent=2) + "\n"


def to_csv(results: Mapping[str, Mapping[str, float]], paths: Sequence[str | Path]) -> str:
    """One row per file: ``label, path`` and one column per metric (its name, units in the JSON)."""
    known = METRICS | RECORDED
    names = [m for m in known if any(m in r for r in results.values())]
    names += sorted({k for r in results.values() for k in r} - set(known))
    buf = io.StringIO()
    writer = csv.writer(buf, lineterminator="\n")
    writer.writerow(["label", "path", *names])
    for (label, r), path in zip(results.items(), paths):
        writer.writerow([label, str(path), *(repr(float(r[n])) if n in r else "" for n in names)])
    return buf.getvalue()


def residual_summary(motion) -> dict[str, float]:
    """What a projected :class:`~physmotion.motion.Motion` records of P's help as metrics rows
    (:func:`help_stats`); {} for a motion P did not make."""
    return help_stats([motion])


def help_stats(motions: Sequence) -> dict[str, float]:
    """P's help over every frame of the projected motions among ``motions`` (:func:`residual_stats` of
    :func:`pooled_help`), and the share of frames with a joint's torque over its actuator's limit where
    they record it (``over_limit``). {} where none was projected."""
    pooled = pooled_help(motions)
    if pooled is None:
        return {}
    over = pooled.over_limit
    return residual_stats(pooled.residual, pooled.cap, pooled.at_cap, pooled.peak) | (
        {} if over is None else {"over_limit": float(over.mean())})  # fmt: skip


class PooledHelp(NamedTuple):
    """P's records pooled over motions: root residual (N, 2) per-frame means; the force cap they share (x W;
    None where one records none or they differ); over-limit flags (N,) bool; frames held at a cap (N,)
    bool; per-frame peaks (N, 2). Each of the last three None unless every motion records it."""

    residual: np.ndarray
    cap: float | None
    over_limit: np.ndarray | None
    at_cap: np.ndarray | None
    peak: np.ndarray | None


def pooled_help(motions: Sequence) -> PooledHelp | None:
    """The records of P's help pooled over the projected motions among ``motions`` (those with
    ``Motion.residual``); None where none was projected."""
    done = [m for m in motions if m.residual is not None]
    if not done:
        return None
    caps = {m.residual_cap for m in done}

    def pooled(name: str) -> np.ndarray | None:
        arrays = [getattr(m, name) for m in done]
        return None if any(a is None for a in arrays) else np.concatenate(arrays)

    return PooledHelp(np.concatenate([m.residual for m in done]), caps.pop() if len(caps) == 1 else None,
                      pooled("over_limit"), pooled("residual_at_cap"), pooled("residual_peak"))  # fmt: skip


def residual_stats(residual: np.ndarray, bound: float | None = None, at_cap: np.ndarray | None = None,
                   peak: np.ndarray | None = None) -> dict[str, float]:  # fmt: skip
    """Mean and 95th percentile of a root residual (..., 2) of per-frame means: force (x W) and torque
    (x W x 1 m), over frames. ``residual_at_cap``: the share of frames in which the body was held by the
    most outside help P allows: from ``at_cap`` (frames,) bool where given (a residual update of the frame
    at the force, lift or torque cap), else, with ``bound`` (the force's cap, x W), frames whose mean force
    is within 1 % of it (files that predate the record); 0 for a P with no hand (``bound`` 0). With
    ``peak`` (..., 2), the per-frame peaks, their 95th percentiles too (``*_peak_p95``)."""
    r = np.asarray(residual, dtype=np.float64).reshape(-1, 2)
    out = {"residual_force": float(r[:, 0].mean()), "residual_force_p95": float(np.percentile(r[:, 0], 95)),
           "residual_torque": float(r[:, 1].mean()), "residual_torque_p95": float(np.percentile(r[:, 1], 95))}
    if peak is not None:
        p = np.asarray(peak, dtype=np.float64).reshape(-1, 2)
        out |= {"residual_force_peak_p95": float(np.percentile(p[:, 0], 95)),
                "residual_torque_peak_p95": float(np.percentile(p[:, 1], 95))}  # fmt: skip
    if bound == 0.0:
        out["residual_at_cap"] = 0.0
    elif at_cap is not None:
        out["residual_at_cap"] = float(np.mean(at_cap))
    elif bound is not None:
        out["residual_at_cap"] = float(np.mean(r[:, 0] >= AT_CAP * bound))
    return out


NO_HELP = "no outside help (root residual 0; no joint torque over its actuator's limit)"


def help_words(residual: np.ndarray, bound: float | None = None, over_limit: np.ndarray | None = None,
               at_cap: np.ndarray | None = None, peak: np.ndarray | None = None) -> str:  # fmt: skip
    """:func:`residual_line` with the unit it uses spelt out where it uses one."""
    line = residual_line(residual, bound, over_limit, at_cap, peak)
    return line if line == NO_HELP else f"{line} (W: body weight)"


def residual_line(residual: np.ndarray, bound: float | None = None, over_limit: np.ndarray | None = None,
                  at_cap: np.ndarray | None = None, peak: np.ndarray | None = None) -> str:  # fmt: skip
    """One plain line for a CLI summary: the root residual's mean and p95 (and, with ``peak``, the p95 of
    the per-frame peaks), force and torque; the share of frames held at a cap (``at_cap`` (frames,) bool:
    force, lift or torque; else, with ``bound``, the force's cap alone); with ``over_limit`` (frames,) bool
    the share of frames with a joint's torque over its actuator's limit. A P with no outside hand
    (``bound`` 0, as the search controller's) that used none says so in words."""
    if bound == 0.0 and not np.any(residual) and (over_limit is None or not np.any(over_limit)):
        return NO_HELP
    s = residual_stats(residual, bound, at_cap, peak)
    share = 100 * s.get("residual_at_cap", 0.0)
    if at_cap is not None and bound:
        cap = f", held at a cap (force {bound:.2f} W, lift or torque) in {share:.1f} % of frames"
    else:
        cap = "" if bound is None else f", at its {bound:.2f} W cap in {share:.1f} % of frames"
    over = "" if over_limit is None else \
        f"; a joint's torque over its actuator's limit in {100 * np.mean(over_limit):.1f} % of frames"
    peaks = "" if peak is None else f", peak p95 {s['residual_torque_peak_p95']:.3f} W m"
    return (f"root residual force mean {s['residual_force']:.3f} W, p95 {s['residual_force_p95']:.3f} W{cap}; "
            f"torque mean {s['residual_torque']:.3f} W m, p95 {s['residual_torque_p95']:.3f} W m{peaks}{over}")
