"""The figures the docs quote are the ones results/*.json hold.

README.md's results table is docs/make_readme_table.py's output; docs/results.md, results/README.md and
the model cards quote figures in their text. The JSON files are written by the commands results/README.md
names (``physmotion evaluate``, ``experiments/physdiff_quality.py``, ``experiments/schedule_study.py``, ...);
a re-run that changes a figure fails here until the docs say the new one. docs/decisions/ is the dated
record of experiments (many from one-off scripts) and is not checked here.
"""

from __future__ import annotations

import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"
PHYSDIFF = "physdiff:end:4,space:1"  # the DDIM-50 tables' PhysDiff (physdiff_quality, new_prompts_*, morph)
DEFAULT_PHYSDIFF = "physdiff:end:2,space:1,fly:last"  # the default sampler's, in evaluate_default
END2 = "physdiff:end:2,space:1"  # the default before fly:last (evaluate_base, morph_retuned, sampling_steps, ...)
DOCS = {
    "README": ROOT / "README.md",
    "results": RESULTS / "README.md",
    "docs results": ROOT / "docs" / "results.md",
    "limitations": ROOT / "docs" / "limitations.md",
    "cli": ROOT / "docs" / "cli.md",
    "architecture": ROOT / "docs" / "architecture.md",
    "decisions": ROOT / "docs" / "decisions" / "README.md",
    "base card": ROOT / "physmotion" / "weights" / "base" / "README.md",
    "morph card": ROOT / "physmotion" / "weights" / "morph" / "README.md",
    "imitator card": ROOT / "physmotion" / "weights" / "imitator" / "README.md",
}
IMITATOR = ROOT / "physmotion" / "weights" / "imitator"


def _load(name: str) -> dict:
    return json.loads((RESULTS / name).read_text())


def _change(x: float, base: float) -> str:
    return f"{100 * (x / base - 1):+.0f} %"


def evaluate_quotes(name: str = "evaluate_default.json", pd: str = DEFAULT_PHYSDIFF) -> list[str]:
    """The test-split table (results/evaluate_default.json, the default model; evaluate_base.json, the base
    model, made when PhysDiff's default was ``END2``) as the docs quote it."""
    rows = _load(name)["rows"]
    modes = ("real", "none", "none+floor", "post:1", "post:4", pd)
    err = {m: rows[m]["phys_err"]["mean"] for m in modes}
    return [
        f"real Penetrate {rows['real']['penetrate']['mean']:.1f} mm",
        f"real {err['real']:.1f}",
        f"none {err['none']:.1f}",
        f"none+floor {err['none+floor']:.1f}",
        f"post:1 {err['post:1']:.1f}",
        f"post:4 {err['post:4']:.1f}",
        f"PhysDiff {err[pd]:.1f} ± {rows[pd]['phys_err']['ci95']:.1f} mm",
        f"{_change(err[pd], err['none'])} vs none",
        f"{_change(err[pd], err['none+floor'])} vs none+floor",
        f"FID {rows['none']['FID']['mean']:.3f} -> {rows[pd]['FID']['mean']:.3f}",
        f"R@3 {rows['none']['R@3']['mean']:.3f} -> {rows[pd]['R@3']['mean']:.3f}",
        f"reset_rate {rows[pd]['reset_rate']['mean']:.2f}",
    ]


def bench_quotes(name: str = "physdiff_quality.json") -> list[str]:
    """experiments/physdiff_quality.py's table (results/physdiff_quality.json, the default model;
    physdiff_quality_base.json, the base model): means over the seeds."""
    runs = _load(name)["runs"]
    err = {m: float(np.mean([r[m]["phys_err"] for r in runs])) for m in runs[0]}
    return [
        f"none {err['none']:.1f}",
        f"none+floor {err['none+floor']:.1f}",
        f"post:4 {err['post:4']:.1f}",
        f"PhysDiff {err[PHYSDIFF]:.1f} mm",
        f"{_change(err[PHYSDIFF], err['none'])} vs none",
        f"{_change(err[PHYSDIFF], err['none+floor'])} vs none+floor",
    ]


def schedule_quotes() -> list[str]:
    """The projection-schedule study (results/schedule_study.json) as results/README.md quotes it."""
    rows = _load("schedule_study.json")["rows"]
    counts = [c for c in rows if c != "real"]
    return [
        "Phys-Err " + " / ".join(f"{rows[c]['phys_err']['mean']:.1f}" for c in counts) + " mm",
        "FID " + " / ".join(f"{rows[c]['FID']['mean']:.3f}" for c in counts),
    ]


def morph_quotes() -> list[str]:
    """The Morph table (results/morph.json, by experiments/morph.py) as the docs quote it: each figure from
    the base model through every round."""
    rows = _load("morph.json")["rows"]

    def models_named(prefix: str) -> list[str]:  # "round 2 none" -> "round 2"
        return sorted({r.rsplit(" ", 1)[0] for r in rows if r.startswith(prefix)})

    models = ["base"] + models_named("round ")
    err = {r: rows[r]["phys_err"]["mean"] for r in rows if r != "real"}

    def chain(mode: str, values: dict, fmt: str) -> str:
        return " -> ".join(format(values[f"{m} {mode}"], fmt) for m in models)

    fid = {r: rows[r]["FID"]["mean"] for r in rows if r != "real"}
    return [
        f"none {chain('none', err, '.1f')} mm",
        f"none+floor {chain('none+floor', err, '.1f')} mm",
        f"morph {chain('morph', err, '.1f')} mm",
        f"post:1 {chain('post:1', err, '.1f')} mm",
        f"physdiff {chain(PHYSDIFF, err, '.1f')} mm",
        f"FID {chain('none', fid, '.3f')}",
        f"PhysDiff {err['base ' + PHYSDIFF]:.1f} mm",
    ] + [f"{name}: none {err[name + ' none']:.1f} mm, FID {fid[name + ' none']:.3f}"
         for name in models_named("control ")]


def dynamic_quotes() -> list[str]:
    """P on every captured clip by category (results/projection_dynamic.json, experiments/projection_dynamic.py)."""
    configs = _load("projection_dynamic.json")["configs"]
    now, before = configs["default"], configs["tracker v0.1"]
    loco, run, jump = now["walks+runs"], now["run"], now["jump"]
    ilc = configs["default + ILC"]["run"]
    fine, fine_jump = configs["default at 1/720 s"]["run"], configs["default at 1/720 s"]["jump"]
    return [
        f"{100 * loco['success']:.1f} % tracked at {loco['mpjpe_mm']:.1f} mm",
        f"(tracker v0.1: {100 * before['walks+runs']['success']:.1f} % at {before['walks+runs']['mpjpe_mm']:.1f} mm)",
        f"residual {loco['residual_force_mean']:.3f} W mean, {loco['residual_force_p95']:.2f} W p95",
        f"runs: Float {run['float_in']:.1f} -> {run['float_out']:.1f} mm (tracker v0.1: {before['run']['float_out']:.1f})",
        f"airborne {100 * run['airborne_in']:.0f} -> {100 * run['airborne_out']:.0f} % "
        f"(tracker v0.1: {100 * before['run']['airborne_out']:.0f} %)",
        f"Skate {run['skate_in']:.1f} -> {run['skate_out']:.1f} mm",
        f"MPJPE {run['mpjpe_mm']:.1f} mm",
        f"jumps: Float {jump['float_in']:.1f} -> {jump['float_out']:.1f} mm",
        f"ILC: runs MPJPE {ilc['mpjpe_mm']:.1f} mm, Float {ilc['float_out']:.1f} mm, "
        f"Skate {ilc['skate_out']:.1f} mm",
        f"1/720 s: runs MPJPE {fine['mpjpe_mm']:.1f} mm, Float {fine['float_out']:.1f} mm, "
        f"Skate {fine['skate_out']:.1f} mm; jumps Skate {fine_jump['skate_out']:.1f} mm",
    ]


def dynamic_doc_quotes() -> list[str]:
    """docs/results.md quotes dynamic_quotes and the clip counts of each category."""
    configs = _load("projection_dynamic.json")["configs"]
    now, fine_walk = configs["default"], configs["default at 1/720 s"]["walk"]
    fails = round((1 - fine_walk["success"]) * fine_walk["clips"])
    return dynamic_quotes() + [
        f"all {now['all']['clips']} bundled clips",
        f"Walks and runs ({now['walks+runs']['clips']} clips)",
        f"The {now['run']['clips']} runs",
        f"The {now['jump']['clips']} jumps",
        f"{fails} of the {fine_walk['clips']} walks fail",
    ]


def _prompts_mean(runs: dict, mode: str, key: str = "phys_err", seed: int | None = None) -> float:
    """An experiments/physdiff_quality.py figure (category -> one row per seed) averaged over the categories in
    ``runs`` and over the seeds, or at one ``seed``."""
    return float(np.mean([r[mode][key] for rows in runs.values() for s, r in enumerate(rows)
                          if seed in (None, s)]))  # fmt: skip


def new_prompts_quotes() -> list[str]:
    """The unseen-prompt bench (results/new_prompts_default.json): PhysDiff against none per category, and
    the share of its projections in which the humanoid fell, both means over the seeds (as the bench
    prints)."""
    runs = _load("new_prompts_default.json")["runs"]

    def quote(cat: str) -> str:
        one = {cat: runs[cat]}
        return (f"{cat} {_change(_prompts_mean(one, PHYSDIFF), _prompts_mean(one, 'none'))} "
                f"({100 * (1 - _prompts_mean(one, PHYSDIFF, 'tracked')):.0f} % fell)")

    return [quote(cat) for cat in runs]


def new_prompts_recovery_quotes() -> list[str]:
    """The unseen-prompt bench with the search carrying a falling body (new_prompts_default.json) against
    the same bench before it (new_prompts_default_before_recovery.json): PhysDiff's falls and resets over
    every category; Phys-Err over the categories whose plain samples read the same under both files' metric
    surfaces; PhysDiff's seconds a motion on the fast categories and on kicks."""
    before = _load("new_prompts_default_before_recovery.json")["runs"]
    after = _load("new_prompts_default.json")["runs"]

    def mean(runs: dict, mode: str, key: str, cats: list[str] | None = None) -> float:
        return _prompts_mean({c: runs[c] for c in cats or runs}, mode, key)

    plain = {c: ([r["none"]["phys_err"] for r in before[c]], [r["none"]["phys_err"] for r in after[c]])
             for c in after}  # fmt: skip
    same = [c for c, (was, now) in plain.items() if np.allclose(was, now, atol=1e-3)]
    assert len(same) == 7, same  # turns and standing changed with the flat hand
    fast = ["run", "jog", "jump", "hop", "kick"]
    fell = [100 * (1 - mean(runs, PHYSDIFF, "tracked")) for runs in (before, after)]
    reset = [100 * mean(runs, PHYSDIFF, "reset_rate") for runs in (before, after)]
    err = {m: [mean(runs, m, "phys_err", same) for runs in (before, after)] for m in (PHYSDIFF, "post:1")}
    return [
        f"fell {fell[0]:.1f} -> {fell[1]:.1f} %",
        f"with a reset {reset[0]:.0f} -> {reset[1]:.0f} %",
        f"({err[PHYSDIFF][0]:.1f} -> {err[PHYSDIFF][1]:.1f} mm)",
        f"({err['post:1'][0]:.1f} -> {err['post:1'][1]:.1f} mm)",
        f"PhysDiff took {mean(after, PHYSDIFF, 'seconds_per_motion', fast):.0f} s a motion against "
        f"{mean(after, 'none', 'seconds_per_motion', fast):.1f} s",
        f"(before: {mean(before, PHYSDIFF, 'seconds_per_motion', fast):.1f} s)",
        f"{mean(after, PHYSDIFF, 'seconds_per_motion', ['kick']):.0f} against "
        f"{mean(after, 'none', 'seconds_per_motion', ['kick']):.1f} s",
    ]


def new_prompts_fine_quotes() -> list[str]:
    """The unseen-prompt bench with P at 1/720 s (results/new_prompts_fine.json) against 1/360 s on the same
    model (the step-8304 one, results/new_prompts_8304.json): each
    projected mode's mean Phys-Err, and PhysDiff against none per category as new_prompts_quotes."""
    default, fine = _load("new_prompts_8304.json")["runs"], _load("new_prompts_fine.json")["runs"]  # one model
    quotes = [f"{'PhysDiff' if mode == PHYSDIFF else mode} {_prompts_mean(default, mode):.1f} -> "
              f"{_prompts_mean(fine, mode):.1f}" for mode in ("post:1", PHYSDIFF, "morph")]
    for cat in fine:
        one = {cat: fine[cat]}
        quotes.append(f"{cat} {_change(_prompts_mean(one, PHYSDIFF), _prompts_mean(one, 'none'))} "
                      f"({100 * (1 - _prompts_mean(one, PHYSDIFF, 'tracked')):.0f} % fell)")
    return quotes


def new_prompts_base_quotes() -> list[str]:
    """The default (Morph-tuned) model against the base it was tuned from on the unseen prompts
    (results/new_prompts_default_before_recovery.json, new_prompts_base.json: one P, before the search
    carried a falling body): each mode's Phys-Err, mean over categories and seeds, and plain sampling's
    change per seed."""
    base = _load("new_prompts_base.json")["runs"]
    default = _load("new_prompts_default_before_recovery.json")["runs"]
    seeds = range(len(next(iter(base.values()))))
    ratios = (_prompts_mean(default, "none", seed=s) / _prompts_mean(base, "none", seed=s) for s in seeds)
    per_seed = " / ".join(f"{100 * (r - 1):.0f}" for r in ratios)
    none_before, none_after = _prompts_mean(base, "none"), _prompts_mean(default, "none")
    quotes = [f"none {none_before:.1f} -> {none_after:.1f} mm ({_change(none_after, none_before)}; "
              f"per seed {per_seed} %)"]
    modes = ("none+floor", "post:1", PHYSDIFF, "morph")
    return quotes + [f"{'PhysDiff' if mode == PHYSDIFF else mode} {_prompts_mean(base, mode):.1f} -> "
                     f"{_prompts_mean(default, mode):.1f}" for mode in modes]


def biomodiffuse_quotes() -> list[str]:
    """BioMoDiffuse's ablation (results/biomodiffuse.json): the baseline and the full model, and Table 6."""
    result = _load("biomodiffuse.json")
    rows, speed = result["rows"], result["speed"]
    base, full = rows["UNet baseline (263-d)"], rows["+ physics guidance"]
    return [
        f"FID {base['FID'][0]:.3f} -> {full['FID'][0]:.3f}",
        f"Phys-Err {base['phys_err'][0]:.1f} -> {full['phys_err'][0]:.1f} mm",
        f"better on {len(result['full_vs_baseline']['wins'])} of 6",
        "speed " + " / ".join(f"{speed[s]['speed'][0]:.2f}" for s in ("0.5", "1", "1.5")) + " m/s",
    ]


def _refine_rows(name: str) -> dict:
    """A refine table (experiments/refine.py) by setting: "2 cm | refine 0.3" -> its row."""
    return {r["setting"]: r for r in _load(name)["rows"]}


def refine_quotes() -> list[str]:
    """Refine against the noisy input and the low-pass filters (results/refine.json, refine_biomo.json)."""
    rows, biomo = _refine_rows("refine.json"), _refine_rows("refine_biomo.json")

    def err(row: dict) -> str:
        return f"{row['mpjpe_mm']:.1f} mm and {row['accel_err']:.2f} m/s^2"

    refined = rows["2 cm | refine 0.3"]
    return [
        f"MPJPE {refined['mpjpe_mm']:.1f} mm and acceleration error {refined['accel_err']:.2f} m/s^2",
        f"4 Hz low-pass filter's {err(rows['2 cm | low-pass 4 Hz'])}",
        f"noisy input's {err(rows['2 cm | noisy input'])}",
        f"at {rows['2 cm | refine 0.3 plain']['mpjpe_mm']:.1f} mm",
        f"MPJPE is {rows['1 cm | refine 0.3']['mpjpe_mm']:.1f} mm against the filter's "
        f"{rows['1 cm | low-pass 4 Hz']['mpjpe_mm']:.1f} mm",
        f"({rows['2 cm | low-pass 3 Hz']['accel_err']:.2f} m/s^2 at 2 cm)",
        f"{err(biomo['2 cm | refine 0.3'])} at 2 cm",
    ]


def imitator_quotes() -> list[str]:
    """P's controllers on captured and generated motion (results/imitator_captured.json, _generated.json)."""
    cap = {(r["category"], r["controller"]): r for r in _load("imitator_captured.json")["rows"]}
    gen = _load("imitator_generated.json")["rows"]

    def mean(ctrl: str, key: str) -> float:
        return float(np.mean([r[key] for r in gen if r["controller"] == ctrl]))

    def reset(ctrl: str) -> str:
        return f"{100 * np.mean([r['resets'] > 0 for r in gen if r['controller'] == ctrl]):.0f} %"

    t, c, p = cap["all", "tracker"], cap["all", "tracker at cap"], cap["all", "policy"]
    return [
        f"tracker {100 * t['success']:.1f} % tracked at {t['mpjpe_mm']:.1f} mm with a residual of "
        f"{t['residual_force_mean']:.3f} W",
        f"tracker at the bound {100 * c['success']:.1f} % at {c['mpjpe_mm']:.1f} mm",
        f"policy {100 * p['success']:.1f} % at {p['mpjpe_mm']:.1f} mm with {p['residual_force_mean']:.3f} W",
        f"outputs with a reset {reset('tracker')} (tracker), {reset('policy')} (policy)",
        f"none+floor in {100 * mean('tracker', 'below_floor'):.0f} % and {100 * mean('policy', 'below_floor'):.0f} %",
        f"residual {mean('tracker', 'residual_force'):.3f} W and {mean('policy', 'residual_force'):.3f} W, torque "
        f"{mean('tracker', 'residual_torque'):.3f} W m and {mean('policy', 'residual_torque'):.3f} W m",
    ]


def imitator_card_quotes() -> list[str]:
    """The imitator's card (physmotion/weights/imitator/README.md): its training from card.json, and how good
    it is from results/imitator_captured.json (the policy and the tracker at the policy's bound and at its
    own)."""
    card = json.loads((IMITATOR / "card.json").read_text())
    cap = {r["controller"]: r for r in _load("imitator_captured.json")["rows"] if r["category"] == "all"}
    t, c, p = cap["tracker"], cap["tracker at cap"], cap["policy"]
    return [
        f"{card['iterations']} iterations",
        f"{card['samples'] / 1e6:.2f} M control steps",
        f"{card['wall_minutes']:.1f} minutes",
        f"residual bounded at {p['residual_force_p95']:.2f} W",
        f"({100 * p['success']:.1f} % against {100 * c['success']:.1f} % of {p['clips']} clips)",
        f"(MPJPE {p['mpjpe_mm']:.1f} against {c['mpjpe_mm']:.1f} mm)",
        f"full {t['residual_force_p95']:.1f} W residual ({100 * t['success']:.1f} %, {t['mpjpe_mm']:.1f} mm)",
    ]


def _pair_rows(name: str) -> dict[tuple[str, str], dict]:
    """An experiments/retrained_default.py table (results/<name>.json) by (model label, physics mode)."""
    return {(r["model"], r["physics"]): r for r in _load(name)["rows"]}


def morph_retuned_quotes() -> list[str]:
    """The shipped Morph model against its base (results/morph_retuned.json) and against the control
    fine-tuned on real motions alone (results/morph_control.json)."""
    rows, ctrl = _pair_rows("morph_retuned.json"), _pair_rows("morph_control.json")
    pd = END2

    def err(row: dict) -> str:
        return f"{row['phys_err']['mean']:.1f}"

    base, tuned = rows["old", "none"], rows["new", "none"]
    return [
        f"none {err(base)} -> {err(tuned)} mm ({_change(tuned['phys_err']['mean'], base['phys_err']['mean'])})",
        f"FID {base['FID']['mean']:.3f} -> {tuned['FID']['mean']:.3f}",
        f"R@3 {base['R@3']['mean']:.3f} -> {tuned['R@3']['mean']:.3f}",
        f"none+floor {err(rows['old', 'none+floor'])} -> {err(rows['new', 'none+floor'])}",
        f"post:1 {err(rows['old', 'post:1'])} -> {err(rows['new', 'post:1'])}",
        f"PhysDiff {err(rows['old', pd])} -> {err(rows['new', pd])} ± {rows['new', pd]['phys_err']['ci95']:.1f} mm",
        f"inference mode {err(rows['new', 'morph'])} mm",
        f"control none {err(ctrl['new', 'none'])} mm, FID {ctrl['new', 'none']['FID']['mean']:.3f}",
        f"control none+floor {err(ctrl['new', 'none+floor'])}, post:1 {err(ctrl['new', 'post:1'])}",
    ]


def _carried(words: str, row: dict) -> str:
    """A controller row of the learning experiments as the docs quote it: carried to the end on captured /
    generated motion, share survived, CPU seconds per second."""
    c, g = row["captured"], row["generated"]
    return (f"{words}: {100 * c['completed']:.0f} % / {100 * g['completed']:.0f} % (survived "
            f"{c['survived']:.2f} / {g['survived']:.2f}, CPU {c['cpu_s_per_s']:.2f} / {g['cpu_s_per_s']:.2f} s per s)")


LEARN_ROWS = {  # the rows of results/learn_from_search.json the docs quote, by the words they use
    "the bare tracker with its hand off": "tracker, hand off",
    "the full search": "search default (full)",
    "the MPPI labeller itself": "MPPI labeller as a controller (32 x 1, lookahead 15)",
    "BC on the search's choices": "BC on the search's choices student",
    "DAgger 2 on MPPI labels": "DAgger 2 on MPPI labels student",
    "PPO warm from it": "PPO on the searched trajectories, warm from DAgger 2 on MPPI labels",
    "a 16 x 2 search with the student proposing": "amortized: dagger2 + search 16x2, lookahead 10",
    "the same search alone": "search 16x2, lookahead 10",
}


def learn_quotes() -> list[str]:
    """Learning from the search (results/learn_from_search.json, teacher_data.json): per quoted row, carried to
    the end on captured / generated motion, share survived, CPU seconds per second; the teacher set's size."""
    rows = {r["row"]: r for r in _load("learn_from_search.json")["rows"]}
    teacher = _load("teacher_data.json")
    out = [f"{teacher['written']} searches, {sum(r['motion s'] for r in teacher['rows']):.0f} s of motion, "
           f"{teacher['cpu_seconds']:.0f} CPU s"]  # fmt: skip
    for words, name in LEARN_ROWS.items():
        out.append(_carried(words, rows[name]))
    return out


SCALE_ROWS = {  # the rows of results/learn_at_scale.json the docs quote, by the words they use
    "the bare tracker with its hand off": "tracker, hand off",
    "BC on all of them, last step": "BC, {refs} references ({pairs} pairs), last step student",
    "BC on all of them, kept on validation": "BC, {refs} references ({pairs} pairs), least validation error student",
    "a DAgger round": "DAgger 1 on 120 references ({dagger} pairs), least validation error student",
    "a 16 x 2 search with it proposing": "amortized: DAgger 1 on 120 references + search 16x2, lookahead 10",
}


def learn_at_scale_quotes() -> list[str]:
    """Learning from the search at scale (results/learn_at_scale.json): its size, the all-data fit's held-out
    error against predicting 0, and per quoted row what learn_quotes gives."""
    got = _load("learn_at_scale.json")
    rows = {r["row"]: r for r in got["rows"]}
    fits = list(got["fits"].values())
    last_bc, dagger = fits[-2], fits[-1]
    out = [f"{got['references']} references, {got['pairs']} labelled pairs",
           f"held-out error {last_bc['val_mse']:.3f} against {last_bc['val_mse_zero']:.3f} for predicting nothing"]
    for words, name in SCALE_ROWS.items():
        name = name.format(refs=got["references"], pairs=got["pairs"], dagger=dagger["pairs"])
        out.append(_carried(words, rows[name]))
    return out


PPO_SCALE_ROWS = {  # the rows of results/ppo_at_scale.json the docs quote, by the words they use
    "the bare tracker with its hand off": "tracker, hand off",
    "the DAgger 2 student it starts from": "warm start (student)",
    "PPO on 2 cores": "PPO, 2 cores, 7 min",
    "PPO on the device": "PPO, device, 16 cores + H200, 7 min",
}


def ppo_at_scale_quotes() -> list[str]:
    """PPO at two sample budgets (results/ppo_at_scale.json): each run's samples, and per quoted row what
    learn_quotes gives."""
    got = _load("ppo_at_scale.json")
    rows = {r["row"]: r for r in got["rows"]}
    out = [f"{card['samples']:,} samples" for card in got["cards"].values()]
    for words, name in PPO_SCALE_ROWS.items():
        out.append(_carried(words, rows[name]))
    return out


def morph_search_quotes() -> list[str]:
    """A Morph round refined by the search (issue 61, item 8): the refined synthetic motions, the models on
    the test split and their plain samples of jump prompts, tracker-refined then search-refined."""
    t, s = (r for r in _load("synth_refinement.json")["rows"])
    base = {r["physics"]: r for r in _load("morph_search.json")["rows"] if r["model"] == "old"}["none"]
    ctrl = {(r["model"], r["physics"]): r for r in _load("morph_search_control.json")["rows"]}
    tr, se = ctrl["old", "none"], ctrl["new", "none"]
    fl = {r["name"]: r for r in _load("model_flight.json")["rows"]}

    def three(key: str, digits: int) -> str:
        return " / ".join(f"{r[key]['mean']:.{digits}f}" for r in (base, tr, se))

    return [
        f"refined kept {t['refined']} / {s['refined']}, IFR {t['ifr']:.3f} / {s['ifr']:.3f}",
        f"Phys-Err {t['output']['phys_err']:.1f} / {s['output']['phys_err']:.1f} mm "
        f"(inputs {t['input']['phys_err']:.1f})",
        f"Skate {t['output']['skate']:.1f} / {s['output']['skate']:.1f} mm",
        f"outside help {t['residual_force']:.3f} / {s['residual_force']:.3f} W",
        f"base {base['phys_err']['mean']:.1f}, tracker-refined {tr['phys_err']['mean']:.1f}, search-refined "
        f"{se['phys_err']['mean']:.1f} mm Phys-Err",
        f"FID {three('FID', 3)}, R@3 {three('R@3', 3)}",
        f"base {fl['base']['flying']}, tracker-refined {fl['tracker-refined']['flying']}, search-refined "
        f"{fl['search-refined']['flying']}, shipped Morph {fl['shipped']['flying']}",
        f"flight kept against the base {fl['tracker-refined']['flight_kept']:.2f} / "
        f"{fl['search-refined']['flight_kept']:.2f} / {fl['shipped']['flight_kept']:.2f}",
    ]


def step_jumps_quotes(name: str = "step_jumps.json", physdiff: str = END2) -> list[str]:
    """Whose jumps are "jumps past the sample's" (results/step_jumps.json, or ``name`` with PhysDiff as
    ``physdiff``): PhysDiff's against the plain sample and against what its last P was given, the denoiser's
    share, and the resets among the flagged."""
    rows = _load(name)["modes"]
    d, p = rows[physdiff], rows["post:1"]

    def pct(x: float) -> str:
        return f"{100 * x:.0f} %"

    return [f"{pct(d['past_sample'])} of PhysDiff's outputs", f"{pct(d['input_past_sample'])} of the motions the last P",
            f"{pct(d['past_input'])} of PhysDiff's outputs and {pct(p['past_input'])} of post:1's",
            f"{pct(d['past_sample_with_reset'])} and {pct(p['past_sample_with_reset'])} of the flagged outputs"]


def flight_fly_quotes() -> list[str]:
    """PhysDiff's flight on jump and hop prompts before and after ``fly:last`` (results/flight_kept_fly.json)."""
    rows = _load("flight_kept_fly.json")["rows"]
    old, new = rows[END2], rows[DEFAULT_PHYSDIFF]
    return [f"{old['flight_kept']:.2f} of the sample's flight", f"now keeps {new['flight_kept']:.2f}",
            f"resets {100 * new['with_reset']:.0f} % of jump and hop outputs "
            f"(before: {100 * old['with_reset']:.0f} %)",
            f"the search carrying {100 * new['recovered']:.0f} % of them "
            f"(before: {100 * old['recovered']:.0f} %)",
            f"{100 * new['step_jumps']:.0f} % of them jump past the sample's "
            f"(before: {100 * old['step_jumps']:.0f} %)"]


def flight_search_quotes() -> list[str]:
    """One P of the held-out seeds' plain samples by the tracker and by the search
    (results/flight_kept_search.json)."""
    rows = _load("flight_kept_search.json")["rows"]
    t, s = rows["sampling"], rows["search"]
    cpu = s["cpu_s_per_s"] / t["cpu_s_per_s"]
    return [f"one P by the search keeps {s['flight_kept']:.2f} (the tracker's {t['flight_kept']:.2f})",
            f"{100 * s['step_jumps']:.0f} % of its outputs jump past the sample's ({100 * t['step_jumps']:.0f} %)",
            f"Phys-Err {s['phys_err']:.1f} against {t['phys_err']:.1f} mm", f"{cpu:.0f}x the CPU"]


def import_floor_quotes() -> list[str]:
    """Where imported clips meet the floor (results/import_floor.json): the uneven-ground clips, mean
    Penetrate per source over the level clips, and the clips at 2 mm or more."""
    src = _load("import_floor.json")["sources"]
    level = {k: v["penetrate_level_mean"] for k, v in src.items()}
    clips = sum(v["clips"] for v in src.values())
    return [f"({sum(v['not_level'] for v in src.values())} of {clips} clips",
            f"at most {max(level.values()):.1f} mm per source (cmu_iclone {level['cmu_iclone']:.1f} mm;",
            f"cmu_amc {level['cmu_amc']:.1f} mm, {src['cmu_amc']['penetrate_mean']:.1f} mm with the uneven",
            f"single clips reach {max(v['penetrate_level_max'] for v in src.values()):.1f} mm",
            f"and {sum(v['over_2mm'] for v in src.values())} of {clips} clips"]


QUOTES = {  # which doc quotes which result file
    ("docs results", "evaluate"): evaluate_quotes,
    ("docs results", "bench"): bench_quotes,
    ("docs results", "schedule"): schedule_quotes,
    ("docs results", "morph"): morph_quotes,
    ("docs results", "dynamic"): dynamic_doc_quotes,
    ("docs results", "new prompts"): new_prompts_quotes,
    ("docs results", "new prompts fine"): new_prompts_fine_quotes,
    ("docs results", "new prompts base"): new_prompts_base_quotes,
    ("docs results", "new prompts recovery"): new_prompts_recovery_quotes,
    ("limitations", "new prompts recovery"): new_prompts_recovery_quotes,
    ("docs results", "biomodiffuse"): biomodiffuse_quotes,
    ("docs results", "refine"): refine_quotes,
    ("docs results", "imitator"): imitator_quotes,
    ("docs results", "morph retuned"): morph_retuned_quotes,
    ("morph card", "morph retuned"): morph_retuned_quotes,
    ("results", "evaluate"): evaluate_quotes,
    ("results", "schedule"): schedule_quotes,
    ("base card", "evaluate base"): lambda: evaluate_quotes("evaluate_base.json", END2),
    ("base card", "bench base"): lambda: bench_quotes("physdiff_quality_base.json"),
    ("docs results", "bench base"): lambda: bench_quotes("physdiff_quality_base.json"),
    ("morph card", "morph"): morph_quotes,
    ("results", "dynamic"): dynamic_quotes,
    ("results", "new prompts"): new_prompts_quotes,
    ("results", "new prompts base"): new_prompts_base_quotes,
    ("results", "new prompts fine"): new_prompts_fine_quotes,
    ("morph card", "new prompts base"): new_prompts_base_quotes,
    ("morph card", "evaluate"): evaluate_quotes,
    ("morph card", "bench"): bench_quotes,
    ("results", "biomodiffuse"): biomodiffuse_quotes,
    ("imitator card", "imitator captured"): imitator_card_quotes,
    ("results", "learn"): learn_quotes,
    ("results", "morph search"): morph_search_quotes,
    ("limitations", "learn"): learn_quotes,
    ("results", "learn at scale"): learn_at_scale_quotes,
    ("limitations", "learn at scale"): learn_at_scale_quotes,
    ("results", "ppo at scale"): ppo_at_scale_quotes,
    ("limitations", "ppo at scale"): ppo_at_scale_quotes,
    ("limitations", "step jumps arms"): lambda: step_jumps_quotes("step_jumps_arms.json", DEFAULT_PHYSDIFF),
    ("results", "step jumps"): step_jumps_quotes,
    ("limitations", "flight fly"): flight_fly_quotes,
    ("limitations", "flight search"): flight_search_quotes,
    ("limitations", "import floor"): import_floor_quotes,
}


def _section(text: str, source: str) -> str:
    """The paragraph(s) of a doc that quote ``source``: those naming its file or command."""
    files = {"evaluate": "evaluate_default", "bench": "physdiff_quality.", "schedule": "schedule_study",
             "evaluate base": "evaluate_base", "bench base": "physdiff_quality_base",
             "morph": "results/morph.md", "morph retuned": "results/morph_retuned.md",
             "dynamic": "projection_dynamic",
             "new prompts": "new_prompts_default", "new prompts base": "new_prompts_base",
             "new prompts recovery": "new_prompts_default_before_recovery",
             "new prompts fine": "new_prompts_fine",
             "biomodiffuse": "results/biomodiffuse", "refine": "results/refine", "imitator": "results/imitator_",
             "imitator captured": "results/imitator_captured", "learn": "learn_from_search", "learn at scale": "learn_at_scale",
             "ppo at scale": "ppo_at_scale",
             "morph search": "morph_search.*", "step jumps": "results/step_jumps",
             "step jumps arms": "results/step_jumps_arms",
             "flight fly": "flight_kept_fly", "flight search": "flight_kept_search", "import floor": "import_floor"}
    marker = files[source]
    return "\n\n".join(p for p in re.split(r"\n\s*\n", text) if marker in p)


@pytest.mark.parametrize(("doc", "source"), list(QUOTES))
def test_docs_quote_the_results_files(doc: str, source: str) -> None:
    text = _section(DOCS[doc].read_text(), source)
    assert text, f"{doc} has no paragraph citing the {source} results"
    flat = " ".join(text.split())
    missing = [q for q in QUOTES[doc, source]() if q not in flat]
    assert not missing, f"{doc} does not quote these {source} figures: {missing}"


def test_imitator_card_json_is_its_training_record() -> None:
    """card.json's figures are those of the files the training wrote: its last evaluation per bound is
    train_eval.csv's last row for that bound, its iterations and samples train_log.csv's last row's and the
    sum of its two runs' (as are the minutes); and results/imitator_captured.json was made with this policy."""
    import csv

    card = json.loads((IMITATOR / "card.json").read_text())
    with open(IMITATOR / "train_eval.csv", newline="") as f:
        evals = list(csv.DictReader(f))
    last = {row["cap"]: {k: v for k, v in row.items() if k != "run"} for row in evals}  # the last row per cap
    assert card["last_evaluation"] == [last[e["cap"]] for e in card["last_evaluation"]]
    assert {e["cap"] for e in card["last_evaluation"]} == set(last)
    with open(IMITATOR / "train_log.csv", newline="") as f:
        final = list(csv.DictReader(f))[-1]
    assert (int(final["iteration"]), int(final["samples"])) == (card["iterations"], card["samples"])
    runs = card["training_runs"]
    assert sum(r["samples"] for r in runs) == card["samples"]
    assert round(sum(r["minutes"] for r in runs), 1) == card["wall_minutes"]
    assert runs[-1]["iterations"].endswith(f"-{card['iterations']}")
    made_with = _load("imitator_captured.json")["meta"]["policy_card"]
    assert made_with == {k: card[k] for k in made_with}


def test_the_length_card_quotes_the_caption_split() -> None:
    """physmotion/weights/length's card (card.json and README.md) gives results/length_split.json's figures:
    the length model on a split by caption (experiments/length_split.py)."""
    split = _load("length_split.json")["caption_split"]
    folder = ROOT / "physmotion" / "weights" / "length"
    assert json.loads((folder / "card.json").read_text())["report"]["caption_split"] == split
    n = split["examples"]
    quotes = [
        f"{n['train']} train, {n['val']} val, {n['test']} test examples",
        f"| refit on its train + val (ridge {split['refit_alpha']:g}) | {split['refit_test_mae']:.2f} |",
        f"saw {split['test_captions_seen']} of the {n['test']} captions) | {split['model_test_mae']:.2f} |",
        f"errs by {split['refit_test_mae']:.2f} s (the constant mean: {split['test_mae_mean']:.2f} s)",
    ]
    flat = " ".join((folder / "README.md").read_text().split())
    assert all(q in flat for q in quotes), [q for q in quotes if q not in flat]


def test_readme_table_is_the_scripts_output() -> None:
    """README.md's results table is docs/make_readme_table.py's output for results/evaluate_default.json,
    between its two marker comments."""
    spec = importlib.util.spec_from_file_location("make_readme_table", ROOT / "docs" / "make_readme_table.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    text = DOCS["README"].read_text()
    found = re.search(r"<!-- table: python docs/make_readme_table.py[^>]*-->\n(.*?)\n<!-- end table -->",
                      text, re.S)
    assert found, "README.md has no table between its '<!-- table: ...' and '<!-- end table -->' comments"
    assert found.group(1) == script.table(), "README.md's table is not docs/make_readme_table.py's output"


def test_refine_claims_hold() -> None:
    """docs/results.md: a 3 Hz filter has less acceleration error than refine at every level, and refine beats
    the 4 Hz filter and the noisy input on both errors at 2 cm."""
    rows = _refine_rows("refine.json")
    for level in ("1 cm", "2 cm", "4 cm"):
        assert rows[f"{level} | low-pass 3 Hz"]["accel_err"] < rows[f"{level} | refine 0.3"]["accel_err"]
    for key in ("mpjpe_mm", "accel_err"):
        for other in ("low-pass 4 Hz", "noisy input"):
            assert rows["2 cm | refine 0.3"][key] < rows[f"2 cm | {other}"][key]


def test_plain_samples_more_jerky_than_captured() -> None:
    """docs/limitations.md: "Plain samples are about 1.4 times as jerky as captured motion" (the base model's
    1.5 times)."""
    flat = " ".join(DOCS["limitations"].read_text().split())
    for name, said in (("evaluate_default.json", "about 1.4 times"), ("evaluate_base.json", "base model's 1.5 times")):
        rows = _load(name)["rows"]
        ratio = rows["none"]["smoothness"]["mean"] / rows["real"]["smoothness"]["mean"]
        assert said in flat and round(ratio, 1) == float(said.split()[-2]), (name, ratio)


def test_real_motion_stands_on_the_floor_in_the_results() -> None:
    """The metrics' floor convention: captured motion on its feet (the mocap test split), grounded on the body
    surface, barely sinks. (The test split with HDM05 reads more: lying down puts the humanoid's torso shapes
    into the floor, docs/results.md.)"""
    for name in ("retrained_default_mocap.json", "schedule_study.json"):
        rows = _load(name)["rows"]
        real = rows[0] if isinstance(rows, list) else rows["real"]
        assert real["penetrate"]["mean"] < 2.0, name


def test_physdiff_beats_the_grounded_baseline_in_every_seed() -> None:
    for run in _load("physdiff_quality.json")["runs"]:
        assert run[PHYSDIFF]["phys_err"] < run["none+floor"]["phys_err"] < run["none"]["phys_err"]


@pytest.mark.parametrize("doc", list(DOCS))
def test_relative_links_exist(doc: str) -> None:
    path = DOCS[doc]
    for target in re.findall(r"\]\(([^)#:]+)\)", path.read_text()):
        assert (path.parent / target).exists(), f"{path.name} links to a missing {target}"


def test_every_result_names_its_preset_commit_and_command() -> None:
    """Each results/*.json an experiment wrote carries its meta block (experiments/_results.py): P's
    preset(s) by their registry names (null where no projection runs), the commit, the CPU, the date and
    the command. (evaluate_default.json is `physmotion evaluate`'s own table; its meta records P's settings.)"""
    from physmotion.physics.presets import preset_names

    for path in sorted(p for p in RESULTS.glob("*.json") if p.name != "evaluate_default.json"):
        meta = json.loads(path.read_text())["meta"]
        missing = {"preset", "commit", "cpu", "date", "command"} - set(meta)
        assert not missing, f"{path.name}: its meta lacks {sorted(missing)}"
        named = meta["preset"].values() if isinstance(meta["preset"], dict) else [meta["preset"]]
        assert all(p is None or p in preset_names() for p in named), f"{path.name}: preset {meta['preset']}"


DIRTY_PENDING: set[str] = set()  # files still to be re-made from a clean tree (issue 62 item 6)


def test_a_result_from_a_dirty_tree_says_so_and_what_is_known() -> None:
    """Figures come from committed code (issue 62 item 6): experiments refuse a dirty tree unless given
    --allow-dirty, and then record "dirty": true; each older file made from a dirty tree ("+dirty" in its
    commit) carries "dirty": true and a "dirty_note" saying what the uncommitted change is known to be."""
    for path in sorted(RESULTS.glob("*.json")):
        meta = json.loads(path.read_text())["meta"]
        if path.name in DIRTY_PENDING or "commit" not in meta:
            continue
        dirty = meta["commit"].endswith("+dirty")
        assert meta.get("dirty", dirty) == dirty, f"{path.name}: 'dirty' disagrees with its commit"
        if dirty:
            assert meta.get("dirty") is True, f"{path.name}: made from a dirty tree without saying so"
            assert len(meta.get("dirty_note", "")) > 40, f"{path.name}: no dirty_note on what was uncommitted"


def test_the_default_sampler_is_within_the_ddim50_rows_intervals() -> None:
    """docs/results.md: DPM-Solver++ 10 (plain, and PhysDiff at its last 2 steps), the default, has FID and R@3
    within DDIM 50's 95 % intervals (or better) in the sampling study (results/sampling_steps.json, one model
    and evaluator for all its rows; made before ``fly:last``, which changes which motions the first of the
    two steps projects, not the sampler); and evaluate_default was sampled with it."""
    from physmotion.diffusion.samplers import SamplerConfig
    from physmotion.pipelines.modes import PhysicsMode

    rows = json.loads((ROOT / "results" / "sampling_steps.json").read_text())["rows"]
    default = SamplerConfig()
    assert str(PhysicsMode()) == DEFAULT_PHYSDIFF == END2 + ",fly:last"
    mine = {r["physics"]: r for r in rows if (r["sampler"], r["steps"]) == (default.sampler, default.steps)}
    ddim = {r["physics"]: r for r in rows if (r["sampler"], r["steps"]) == ("ddim", 50)}
    for physics, base in (("none", "none"), (END2, PHYSDIFF)):
        got, ref = mine[physics], ddim[base]
        assert got["FID"]["mean"] <= ref["FID"]["mean"] + ref["FID"]["ci95"], physics
        assert got["R@3"]["mean"] >= ref["R@3"]["mean"] - ref["R@3"]["ci95"], physics
    sampler = _load("evaluate_default.json")["meta"]["sampler"]
    assert (sampler["sampler"], sampler["steps"]) == (default.sampler, default.steps)


def test_limitations_quote_the_first_motion_bench() -> None:
    """docs/limitations.md's speed figures are results/first_motion.json's medians."""
    times = json.loads((RESULTS / "first_motion.json").read_text())["seconds"]
    plain = times["warm library: generate(), none, batch 1"]["median"]
    cold = times["cold CLI: generate, none, batch 1"]["median"]
    physdiff = times["warm library: generate(), physdiff, batch 1"]["median"]
    quotes = [f"takes {plain:.2f} s", f"`physmotion generate` {cold:.2f} s", f"PhysDiff takes {physdiff / plain:.1f}x plain"]
    flat = " ".join(DOCS["limitations"].read_text().split())
    assert all(q in flat for q in quotes), [q for q in quotes if q not in flat]



def search_quotes() -> list[str]:
    """results/search_quality.json (P with no outside hand) as docs/limitations.md and results/README.md
    quote it: the search at the default effort against the tracker."""
    from experiments.search_quality import summary

    per = _load("search_quality.json")["per_motion"]
    cap, gen = (summary(per[g]["search default, elliptic"]) for g in ("captured", "generated"))
    tracker = summary(per["captured"]["tracker, hand on, pyramidal"])
    off = [summary(per[g]["tracker, hand off, pyramidal"])["completed"] for g in ("captured", "generated")]
    return [
        f"hand taken away fell in {100 * (1 - off[0]):.0f} % and {100 * (1 - off[1]):.0f} % of them",
        f"{round(cap['completed'] * cap['motions'])} of {cap['motions']} captured clips",
        f"{round(gen['completed'] * gen['motions'])} of {gen['motions']} generated",
        f"world MPJPE {cap['mpjpe_mm']:.0f} mm (pelvis-relative {cap['rel_mpjpe_mm']:.0f})",
        f"pelvis-relative {gen['rel_mpjpe_mm']:.0f} mm",
        f"flight kept {gen['flight_kept']:.2f}",
        f"Penetrate {cap['penetrate_out']:.1f} mm",
        f"Skate {cap['skate_out']:.1f} mm against the input's {cap['skate_in']:.1f} (the tracker: "
        f"{tracker['skate_out']:.1f})",
        f"at or under the grounded sample's in {100 * gen['skate_not_above_in']:.0f} %",
    ]


@pytest.mark.parametrize("doc", ["limitations", "results"])
def test_docs_quote_the_search_quality_table(doc: str) -> None:
    flat = " ".join(DOCS[doc].read_text().split())
    quotes = search_quotes()
    assert all(q in flat for q in quotes), [q for q in quotes if q not in flat]
