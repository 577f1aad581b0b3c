"""Physics projection on every captured clip of the bundled mocap, by category of motion: one table.

Usage: python -m experiments.projection_quality [--mocap ../shared/data/mocap] [--limit N] [--walks-runs]
       [--preset plain] [--out results/projection_quality]
One row per category (jump, kick, dance, run, turn, walk, other; from the captions), then "walks+runs"
(the 203 walking/running clips of earlier figures) and "all": success (no MPJPE past 0.5 m), MPJPE, the
physical metrics of input -> simulation (both on the clip's humanoid geometry, the input grounded on it:
the metrics' floor convention), airborne share of frames (no foot patch within 2 cm of the floor) of input
-> simulation, and the root residual used (force x W, torque x W m; mean and 95th percentile over frames).
P is the preset ``--preset`` (``ilc``: ``project --ilc 2``, ``fine``: ``project --fine-step``).

This module also holds what measuring P on captured clips takes (which clips the targets speak of, how
one clip is measured, the per-category summary), shared by ``experiments/projection_dynamic.py``,
``experiments/imitator.py`` and the tests.
"""

from __future__ import annotations

import argparse
import re
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import numpy as np

from experiments._results import markdown_table, parse_args, run_meta, write_results
from physmotion.io.importer import ClipInfo, import_clip, load_manifest
from physmotion.metrics import physical_metrics
from physmotion.metrics.physical import skate_factors
from physmotion.metrics.report import residual_stats
from physmotion.physics.presets import preset, preset_names
from physmotion.physics.projection import ProjectedMotion, ProjectionConfig, project
from physmotion.physics.surface import HumanoidSurface, ground_on_surface
from physmotion.physics.workers import map_in_workers

LOCOMOTION = re.compile(r"\b(walk|walks|walking|run|runs|running|jog|jogs|jogging)\b")
"""A clip whose first caption matches is a walking/running clip."""

CATEGORIES: dict[str, re.Pattern[str]] = {
    "jump": re.compile(r"\b(jump|jumps|jumping|hop|hops|hopping|leap|leaps|leaping)\b"),
    "kick": re.compile(r"\b(kick|kicks|kicking)\b"),
    "dance": re.compile(r"\b(dance|dances|dancing|ballet|charleston|lambada|salsa)\b"),
    "run": re.compile(r"\b(run|runs|running|jog|jogs|jogging|sprint|sprints|dash|dashes)\b"),
    "turn": re.compile(r"\b(turn|turns|turning|spin|spins|pivot|pivots|twirl|twirls)\b"),
    "walk": re.compile(r"\b(walk|walks|walking|step|steps|stroll|strolls|march|marches)\b"),
}
"""Categories of motion by the words of a clip's captions, checked in this order (a clip that "jumps and
turns" is a jump; "walks and turns" a turn); a clip no pattern matches is "other"."""

AIRBORNE_HEIGHT = 0.02
"""m: a frame is airborne when no foot contact patch (heel or toe box) is this close to the floor. 2 cm
rather than the metrics' 5 mm tolerance, because captured feet are modelled by rigid boxes: a captured
stance foot often hovers a centimetre above the floor on them."""


def category(captions: list[str]) -> str:
    """The category of a clip (:data:`CATEGORIES`, else "other") from all its captions."""
    text = " | ".join(captions).lower()
    return next((name for name, pattern in CATEGORIES.items() if pattern.search(text)), "other")


def airborne_share(joints: np.ndarray, surface: HumanoidSurface) -> float:
    """Share of the frames of ``joints`` (T, 22, 3) in which no foot patch of ``surface`` is within
    :data:`AIRBORNE_HEIGHT` of the floor (y = 0)."""
    feet = surface.foot_heights(np.asarray(joints, dtype=np.float64))  # (T, 4)
    return float((feet.min(axis=-1) > AIRBORNE_HEIGHT).mean())


def locomotion_clips(mocap_dir: str | Path) -> list[ClipInfo]:
    """The walking and running clips of a mocap directory, in manifest order."""
    return [c for c in load_manifest(mocap_dir) if LOCOMOTION.search(c.captions[0].lower())]


@dataclass
class ClipProjection:
    """One projected clip: P's result and the physical metrics of its input and of the simulation, both
    on the humanoid's geometry of the clip's own body, under the metrics' floor convention (the input
    grounded on that surface, :func:`ground_on_surface`; the simulation as it is)."""

    result: ProjectedMotion
    before: dict[str, float]
    after: dict[str, float]
    airborne_before: float = 0.0  # share of frames with both feet off the floor (airborne_share)
    airborne_after: float = 0.0
    contact_before: tuple[float, float] = (0.0, 0.0)  # skate_factors: (share touching, slide mm)
    contact_after: tuple[float, float] = (0.0, 0.0)


def measure_projection(
    joints: np.ndarray, fps: float, config: ProjectionConfig | None = None
) -> ClipProjection:
    """Project ``joints`` (T, 22, 3), data convention, at ``fps`` and measure input and output."""
    result = project(joints, fps, config)
    grounded, body = ground_on_surface(joints)
    surface = HumanoidSurface(body)
    before = physical_metrics(grounded, fps=fps, body=surface)
    after = physical_metrics(result.simulated, fps=fps, body=surface)
    sim = result.simulated
    return ClipProjection(result, before, after,
                          airborne_share(grounded, surface), airborne_share(sim, surface),
                          skate_factors(grounded, fps, body=surface), skate_factors(sim, fps, body=surface))


def measure_clips(
    clips: list[ClipInfo], config: ProjectionConfig | None = None, workers: int = 0
) -> list[ClipProjection]:
    """:func:`measure_projection` of each clip (imported from the manifest), in input order, the clips
    spread over ``workers`` processes (0: one per core)."""
    return map_in_workers(partial(_measure_clip, config=config), clips, workers)


def _measure_clip(info: ClipInfo, config: ProjectionConfig | None) -> ClipProjection:
    motion = import_clip(info, floor="frame0")  # P's input convention (the importer's default grounds the soles)
    return measure_projection(motion.joints, motion.fps, config)


SUMMARY_METRICS = ("penetrate", "float", "skate", "phys_err")


def summarize(measured: list[ClipProjection], bound: float | None = None) -> dict[str, float]:
    """One row over clips: ``clips``, ``success`` (share), ``mpjpe_mm`` (mean over all clips), the metrics of
    input and output (``<metric>_in`` / ``_out``, mm, means over clips), airborne shares of input and
    output, Skate's two factors (``contact_in/out``, ``slide_in/out``: ``metrics.physical.skate_factors``,
    means over clips), the residual force and torque (mean over all frames, p95 over all frames;
    x W, x W m), ``over_limit`` (the share of frames with a joint's torque over its actuator's limit) and,
    with ``bound`` (P's force cap, x W), ``residual_at_cap`` (the share of frames at it)."""
    if not measured:
        return {"clips": 0}
    force = np.concatenate([m.result.residual_force for m in measured])
    torque = np.concatenate([m.result.residual_torque for m in measured])
    row = {
        "clips": len(measured),
        "success": float(np.mean([bool(m.result.success) for m in measured])),
        "mpjpe_mm": float(1000 * np.mean([m.result.mpjpe.mean() for m in measured])),
    }
    for key in SUMMARY_METRICS:
        row[f"{key}_in"] = float(np.mean([m.before[key] for m in measured]))
        row[f"{key}_out"] = float(np.mean([m.after[key] for m in measured]))
    row |= {
        "airborne_in": float(np.mean([m.airborne_before for m in measured])),
        "airborne_out": float(np.mean([m.airborne_after for m in measured])),
        "contact_in": float(np.mean([m.contact_before[0] for m in measured])),
        "contact_out": float(np.mean([m.contact_after[0] for m in measured])),
        "slide_in": float(np.mean([m.contact_before[1] for m in measured])),
        "slide_out": float(np.mean([m.contact_after[1] for m in measured])),
        "residual_force_mean": float(force.mean()), "residual_force_p95": float(np.percentile(force, 95)),
        "residual_torque_mean": float(torque.mean()), "residual_torque_p95": float(np.percentile(torque, 95)),
        "over_limit": float(np.mean(np.concatenate([m.result.over_limit for m in measured]))),
    }
    if bound is not None:  # the reports' rule for "at the cap" (metrics/report.py)
        row["residual_at_cap"] = residual_stats(np.stack([force, torque], axis=-1), bound)["residual_at_cap"]
    return row


def by_category(clips: list[ClipInfo], measured: list[ClipProjection],
                bound: float | None = None) -> dict[str, dict[str, float]]:  # fmt: skip
    """:func:`summarize` (with P's force cap ``bound``) per category (:func:`category`, in the order of
    :data:`CATEGORIES`, then "other", then "walks+runs": :func:`locomotion_clips`' rule, the set the
    residual target speaks of, where there are any; then "all"). Categories without clips are left out."""
    groups: dict[str, list[ClipProjection]] = {name: [] for name in (*CATEGORIES, "other")}
    for info, m in zip(clips, measured):
        groups[category(info.captions)].append(m)
    rows = {name: summarize(ms, bound) for name, ms in groups.items() if ms}
    locomotion = [m for info, m in zip(clips, measured) if LOCOMOTION.search(info.captions[0].lower())]
    if locomotion:
        rows["walks+runs"] = summarize(locomotion, bound)
    rows["all"] = summarize(measured, bound)
    return rows


def category_table(rows: dict[str, dict[str, float]]) -> str:
    """:func:`by_category`'s rows as one Markdown table."""
    header = ("category", "clips", "success", "MPJPE mm", "Penetrate in→out", "Float in→out", "Skate in→out",
              "Phys-Err in→out", "airborne in→out", "feet touching in→out", "slide per touch in→out",
              "residual F mean / p95 (W) (at cap)", "residual τ mean / p95 (W m)", "torque over limit")  # fmt: skip
    lines = []
    for name, r in rows.items():
        cells = [name, str(r["clips"]), f"{100 * r['success']:.1f} %", f"{r['mpjpe_mm']:.1f}"]
        cells += [f"{r[k + '_in']:.2f} → {r[k + '_out']:.2f}" for k in SUMMARY_METRICS]
        cells += [f"{100 * r['airborne_in']:.1f} → {100 * r['airborne_out']:.1f} %",
                  f"{100 * r['contact_in']:.1f} → {100 * r['contact_out']:.1f} %",
                  f"{r['slide_in']:.1f} → {r['slide_out']:.1f}",
                  f"{r['residual_force_mean']:.3f} / {r['residual_force_p95']:.3f}"
                  + (f" ({100 * r['residual_at_cap']:.0f} %)" if "residual_at_cap" in r else ""),
                  f"{r['residual_torque_mean']:.3f} / {r['residual_torque_p95']:.3f}",
                  f"{100 * r['over_limit']:.1f} %" if "over_limit" in r else "-"]  # fmt: skip
        lines.append(cells)
    return markdown_table(header, lines)


def spread(clips: list[ClipInfo], limit: int) -> list[ClipInfo]:
    """``limit`` clips spread evenly over ``clips`` (every k-th); all of them for 0."""
    return clips[:: max(1, len(clips) // limit)][:limit] if limit else clips


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--mocap", default="../shared/data/mocap")
    parser.add_argument("--limit", type=int, default=0, help="only the first N clips")
    parser.add_argument("--walks-runs", action="store_true", help="only the walking/running clips")
    parser.add_argument("--preset", default="plain", choices=preset_names(), help="P's preset")
    parser.add_argument("--out", default="results/projection_quality", help="writes OUT.md and OUT.json")
    args = parse_args(parser, argv)
    clips = locomotion_clips(args.mocap) if args.walks_runs else load_manifest(args.mocap)
    clips = clips[: args.limit] if args.limit else clips
    start = time.perf_counter()
    config = preset(args.preset)
    measured = measure_clips(clips, config)  # one worker process per core
    seconds = time.perf_counter() - start
    rows = by_category(clips, measured, config.residual_bound())
    failed = [c.clip for c, m in zip(clips, measured) if not m.result.success]
    md = (f"# P on {len(clips)} captured clips by category (preset {args.preset}, {seconds:.0f} s)\n\n"
          f"{category_table(rows)}\n\nfailed: {', '.join(failed) or '-'}\n")
    print(md)
    meta = run_meta(__file__, argv, args.tree, args.preset, clips=len(clips), mocap=str(args.mocap),
                    seconds=seconds)
    write_results(args.out, md, {"meta": meta, "rows": rows, "failed": failed})


if __name__ == "__main__":
    main()
