"""The papers' tables on our data: generation metrics with our evaluator plus every physical metric, one
row per generation mode (PhysDiff Tables 1 and 4, Morph Table 2), and a reference row for real motions.

Protocol (Guo et al. 2022, as run by MDM's ``eval/eval_humanml.py``), scaled to our split:
- every motion of the split is generated once per repeat, from one of its captions and at its length;
  each motion's caption is drawn once (seeded) and kept for every repeat and mode, so modes are compared
  on the same requests and the repeats give MultiModality's several generations per text;
- FID: generated embeddings against the real motions' embeddings;
- R-Precision top 1/2/3 and MM-Dist: captions against the generated motions in shuffled batches of 32
  (an incomplete last batch is dropped);
- Diversity: mean distance between random pairs of generated motions (300 pairs, at most N);
- MultiModality: mean distance between generations of the same caption across repeats;
- every figure is the mean over ``repeats`` runs with a 95% interval (1.96 std / sqrt(repeats)), except
  MultiModality, whose interval is over captions.
The real row uses HumanML3D's evaluation crops of the real motions (lengths rounded down to multiples of
4, one unit shorter a third of the time, random start), so its FID is close to, not exactly, zero.

Physical metrics use the humanoid's collision geometry (:class:`HumanoidSurface`) by default, under the
metrics' floor convention (:mod:`physmotion.metrics.physical`): the real motions are grounded on that
surface (:func:`ground_on_surface`, the constant shift with the least Phys-Err) as the ``none+floor``
row is; ``none`` is measured as sampled.
``reset_rate`` is the share of output motions whose projection put the fallen humanoid back on the motion
at least once (MPJPE past tau, 0.15 m in generation) and ``resets`` the mean number of those jumps per
motion. ``recovered_rate`` is the share of output motions in which the search carried the body, with no
outside hand, where it would have been put back (``ProjectionConfig.recover``). ``residual_force`` and
``residual_torque`` (with their 95th percentiles) are the root residual P applied to its outputs, the outside
help its body got, over every frame, in body weights (x 1 m for the torque), and ``residual_at_cap`` the
share of frames in which it was held at one of its caps (force, lift or torque). Against the ``none`` row's
plain samples of the same requests (when it is evaluated): ``flight_kept``, the median share of a flying
sample's flight the output keeps, and ``step_jumps``, the share of outputs with a frame-to-frame jump 2 cm
beyond the sample's largest
(:mod:`physmotion.metrics.dynamics`): Phys-Err alone rewards a flattened jump. In every mode with P,
``step_jumps_p``: the same against what the last P was given, so the jumps P made apart from a faster
motion PhysDiff's denoising made after an earlier P. None is Morph's imitation failure rate:
``imitation_failure_rate``, given for the ``morph`` mode, is the share of its motions whose imitation failed
(MPJPE past 0.5 m), so that the sampled motion was kept.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS
from physmotion.data.dataset import MotionItem, load_items
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import joints_to_features, on_data_floor, projection_settings
from physmotion.errors import PhysmotionError
from physmotion.eval.evaluator import Evaluator
from physmotion.eval.parts import RunParts, digest, model_digest
from physmotion.eval.physics_columns import imitation_columns, metric_surface, reset_columns, residual_columns
from physmotion.features.humanml3d import recover_from_ric
from physmotion.generate import GenerateConfig, generate
from physmotion.metrics import ragged_physical_metrics
from physmotion.metrics.generation import (
    confidence_interval,
    diversity,
    fid,
    multimodality_per_text,
    r_precision,
)
from physmotion.motion import write_atomic
from physmotion.physics.surface import ground_on_surface
from physmotion.pipelines.modes import DEFAULT_SCHEDULE, PhysicsMode
from physmotion.provenance import provenance

REAL = "real"
GENERATION_COLUMNS = ("R@1", "R@2", "R@3", "FID", "MM-Dist", "Diversity", "MModality", "sec/motion")
BETTER = {"R@1": "↑", "R@2": "↑", "R@3": "↑", "FID": "↓", "MM-Dist": "↓", "Diversity": "→", "MModality": "↑",
          "sec/motion": "↓"}  # fmt: skip
RESET_COLUMNS = {"reset_rate": "reset_rate (share)", "resets": "resets (per motion)",
                 "fell": "projections that fell (share)",
                 "recovered_rate": "carried by the search, not reset (share)",
                 "residual_force": "root force (W)", "residual_force_p95": "root force p95 (W)",
                 "residual_at_cap": "root help at a cap (share)",
                 "flight_kept": "flight kept (median)", "step_jumps": "jumps past the sample's (share)",
                 "step_jumps_p": "jumps past P's input (share)",
                 "residual_torque": "root torque (W m)", "residual_torque_p95": "root torque p95 (W m)",
                 "over_limit": "joint torque over limit (share)",
                 "imitation_failure_rate": "imitation_failure_rate (share)"}


@dataclass
class EvaluateConfig:
    """One evaluation run. ``quick()`` is the smoke-test preset."""

    modes: tuple[str, ...] = ("none", "none+floor", "post:1", "post:4", f"physdiff:{DEFAULT_SCHEDULE}")
    split: str = "test"
    repeats: int = 3  # Guo: 20; one repeat of four modes costs minutes here
    max_motions: int | None = None  # a seeded subset of the split
    batch_size: int = 32  # R-Precision batch
    generate_batch: int = 16  # motions per sampling call
    diversity_times: int = 300
    mm_times: int = 10
    surface: str = "humanoid"
    seed: int = 0
    real_row: bool = True  # False: skip the real-motion row (a caller that has it from another run)
    base: GenerateConfig = field(default_factory=GenerateConfig)

    @classmethod
    def quick(cls, **kw) -> EvaluateConfig:
        """32 motions, 2 repeats, 10 DDIM steps: a smoke run that exercises every code path."""
        base = GenerateConfig()
        base.sampler = replace(base.sampler, steps=10)
        return cls(**{"repeats": 2, "max_motions": 32, "base": base, **kw})


@dataclass
class EvalTable:
    """Rows: name -> metric -> (mean, 95% half-width). ``meta``: what was evaluated, how."""

    rows: dict[str, dict[str, tuple[float, float]]]
    meta: dict

    def to_json(self) -> str:
        rows = {r: {m: {"mean": v[0], "ci95": v[1]} for m, v in vals.items()} for r, vals in self.rows.items()}
        return json.dumps({"meta": self.meta, "rows": rows}, indent=2)

    @classmethod
    def from_json(cls, path: str | Path) -> EvalTable:
        """Read a table written by :meth:`write` (``<stem>.json``)."""
        try:
            data = json.loads(Path(path).read_text())
            rows = {r: {m: (v["mean"], v["ci95"]) for m, v in vals.items()} for r, vals in data["rows"].items()}
            return cls(rows=rows, meta=data["meta"])
        except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
            raise PhysmotionError(f"{path}: not an evaluation table ({type(exc).__name__})") from None

    def physical_columns(self) -> list[str]:
        from physmotion.metrics.physical import METRICS

        return [m for m in METRICS if any(m in r for r in self.rows.values())]

    def to_markdown(self) -> str:
        from physmotion.metrics.physical import METRICS

        lines = [_markdown_table(self.rows, [(c, f"{c} {BETTER[c]}") for c in GENERATION_COLUMNS]), ""]
        phys = [(c, f"{c} ({METRICS[c].unit})") for c in self.physical_columns()]
        phys += [(c, label) for c, label in RESET_COLUMNS.items() if any(c in r for r in self.rows.values())]
        lines.append(_markdown_table(self.rows, phys))
        return "\n".join(lines) + "\n"

    def write(self, stem: str | Path) -> list[Path]:
        """Write ``<stem>.md`` and ``<stem>.json`` atomically (:func:`table_paths`)."""
        md, js = table_paths(stem)
        md.parent.mkdir(parents=True, exist_ok=True)
        write_atomic(md, lambda f: f.write(_markdown_header(self.meta) + self.to_markdown()), "w")
        write_atomic(js, lambda f: f.write(self.to_json()), "w")
        return [md, js]


def table_paths(stem: str | Path) -> tuple[Path, Path]:
    """``(<stem>.md, <stem>.json)``. The suffixes are appended, so a stem with a dot ("eval_0.5") keeps
    it; a stem given as ``x.md`` or ``x.json`` stands for ``x``."""
    stem = Path(stem)
    if stem.suffix in (".md", ".json"):
        stem = stem.with_suffix("")
    return stem.with_name(stem.name + ".md"), stem.with_name(stem.name + ".json")


def parts_folder(stem: str | Path) -> Path:
    """Where a run writing ``<stem>.md``/``.json`` keeps its finished runs until then: ``<stem>.parts``."""
    md, _ = table_paths(stem)
    return md.with_name(md.name[: -len(".md")] + ".parts")


def evaluate(
    model: MotionDiffusion,
    evaluator: Evaluator,
    data: str | Path,
    config: EvaluateConfig | None = None,
    on_progress: Callable[[int, int], None] | None = None,
    parts: str | Path | None = None,
) -> EvalTable:
    """The table for ``config.modes`` on ``data``'s split, with a real-data row first.

    ``parts``: a folder where each (mode, repeat) run is saved as it finishes and reused when this is
    called again with the same model, data and settings (:mod:`physmotion.eval.parts`), so a killed run
    resumes; the caller removes it once the table is written."""
    cfg = config or EvaluateConfig()
    modes = [PhysicsMode.parse(m) for m in cfg.modes]  # bad modes and sampler settings fail before any work
    cfg.base.sampler.check()
    cfg.base.sampler.check_model(model)
    for mode in modes:
        mode.hook_steps(cfg.base.sampler.steps)
    gen_configs = {str(mode): replace(cfg.base, physics=mode) for mode in modes}
    if cfg.repeats < 1:
        raise PhysmotionError("--repeats must be at least 1")
    items = _items(data, cfg, model.denoiser.max_frames)
    captions = draw_captions(items, cfg.seed)
    real_emb = evaluator.encode_motions([it.features for it in items])
    text_emb = evaluator.encode_texts(captions)
    metric_surface(cfg.surface)  # a bad name fails before any work
    total, done = cfg.repeats * len(items) * len(cfg.modes), 0
    store = None
    if parts is not None:
        settings = {k: v for k, v in asdict(cfg).items() if k not in ("modes", "repeats", "base", "real_row")}
        common = digest(model_digest(model), real_emb, text_emb, settings, "none" in gen_configs)
        store = RunParts(parts, common)

    rows: dict[str, dict[str, tuple[float, float]]] = {}
    plain: dict[int, list[np.ndarray]] = {}  # repeat -> the none row's samples, for what the others kept
    if cfg.real_row:
        real_phys = _real_physical(items, cfg)  # the same in every repeat: measured once
        runs = [_real_run(evaluator, items, r, cfg, real_emb, text_emb) | real_phys for r in range(cfg.repeats)]
        rows[REAL] = _summarise(runs, None)
    for mode, gen_cfg in gen_configs.items():
        runs, per_text = [], []
        for r in range(cfg.repeats):
            run_cfg = replace(gen_cfg, seed=cfg.seed + 1000 * r)

            def tick(n: int, _done: int = done) -> None:
                if on_progress:
                    on_progress(_done + n, total)

            key = store.key(mode, r, run_cfg) if store else ""
            saved = store.load(mode, r, key) if store else None
            if saved is not None:
                run, emb, joints = saved
                tick(len(items))
            else:
                joints, bodies, seconds, resets = _generate(model, captions, items, run_cfg,
                                                            cfg.generate_batch, tick)
                emb = evaluator.encode_motions([joints_to_features(on_data_floor(j)) for j in joints])
                run = _scores(emb, text_emb, real_emb, r, cfg)
                run.update(ragged_physical_metrics(joints, FPS, body=metric_surface(cfg.surface, bodies)))
                run["sec/motion"] = seconds / len(items)
                run.update(resets)
                if mode != "none" and r in plain:
                    run.update(_kept(joints, plain[r]))
                if store:
                    store.save(mode, r, key, run, emb, joints if mode == "none" else None)
            done += len(items)
            if mode == "none":
                plain[r] = joints
            runs.append(run)
            per_text.append(emb)
        rows[mode] = _summarise(runs, np.stack(per_text, axis=1) if cfg.repeats > 1 else None)
    meta = {"split": cfg.split, "motions": len(items), "repeats": cfg.repeats, "modes": list(gen_configs),
            "model_trained_on": model.info.get("data", ""), "model_steps": model.info.get("steps"),
            "model_licence": model.licence_tag, "evaluator_licence": evaluator.licence_tag,
            "sampler": asdict(cfg.base.sampler),
            "projection": projection_settings(cfg.base.projection),
            "morph_projection": projection_settings(cfg.base.morph_projection),
            "surface": cfg.surface, "seed": cfg.seed,
            "data": str(data), "made": provenance()}  # fmt: skip
    return EvalTable(rows=rows, meta=meta)


# ------------------------------------------------------------------------------------------------


def _items(data: str | Path, cfg: EvaluateConfig, max_frames: int) -> list[MotionItem]:
    items = load_items(data, cfg.split, max_frames=max_frames)
    if cfg.max_motions is not None and cfg.max_motions < len(items):
        keep = np.sort(np.random.default_rng(cfg.seed).choice(len(items), cfg.max_motions, replace=False))
        items = [items[i] for i in keep]
    if len(items) < cfg.batch_size:
        raise PhysmotionError(f"{data}: split '{cfg.split}' has {len(items)} usable motions; "
                              f"R-Precision needs at least {cfg.batch_size}")  # fmt: skip
    return items


def draw_captions(items: list[MotionItem], seed: int) -> list[str]:
    """One caption per motion of ``items``, drawn as every evaluation run draws them (seeded by ``seed``)."""
    rng = np.random.default_rng((seed, 1))
    return [it.captions[rng.integers(len(it.captions))] for it in items]


def _crop(features: np.ndarray, rng: np.random.Generator, unit: int = 4) -> np.ndarray:
    """HumanML3D's evaluation crop: length down to a multiple of ``unit``, one unit less a third of the time."""
    units = len(features) // unit
    if rng.integers(3) == 2 and units > 1:
        units -= 1
    length = units * unit
    start = int(rng.integers(len(features) - length + 1))
    return features[start : start + length]


def _real_run(evaluator, items, r, cfg, real_emb, text_emb) -> dict[str, float]:
    rng = np.random.default_rng((cfg.seed, 2, r))
    crops = [_crop(it.features, rng) for it in items]
    return _scores(evaluator.encode_motions(crops), text_emb, real_emb, r, cfg)


def _real_physical(items: list[MotionItem], cfg: EvaluateConfig) -> dict[str, float]:
    """The physical metrics of the real motions (whole, not cropped)."""
    real = [recover_from_ric(it.features.astype(np.float64)) for it in items]
    if cfg.surface == "humanoid":  # the metrics' floor convention: grounded on the surface they measure
        real, bodies = (list(z) for z in zip(*(ground_on_surface(j) for j in real)))
        return ragged_physical_metrics(real, FPS, body=metric_surface(cfg.surface, bodies))
    return ragged_physical_metrics(real, FPS, body=metric_surface(cfg.surface))


def _generate(model, captions, items, gen_cfg, batch, tick) -> tuple[list, list, float, dict[str, float]]:
    """Final joints of every motion, the body of each (or None), wall seconds, and the reset columns."""
    joints: list[np.ndarray] = []
    bodies: list[np.ndarray | None] = []
    results = []
    start = time.perf_counter()
    for i in range(0, len(items), batch):
        chunk = slice(i, i + batch)
        lengths = [len(it.features) for it in items[chunk]]
        out = generate(captions[chunk], replace(gen_cfg, seed=gen_cfg.seed + i), model, lengths=lengths)
        joints += [m.joints for m in out.motions]
        bodies += out.bodies
        results.append(out)
        tick(len(joints))
    columns = reset_columns(results) | residual_columns(results) | imitation_columns(results)
    given = [s for out in results for s in out.projections.last_input_steps(len(out.motions))]
    if given:  # a mode with P: the jumps its last P made, apart from what denoising after an earlier P did
        from physmotion.metrics.dynamics import jumps_past

        columns["step_jumps_p"] = jumps_past(joints, given)
    return joints, bodies, time.perf_counter() - start, columns


def _kept(joints: list[np.ndarray], samples: list[np.ndarray]) -> dict[str, float]:
    """``flight_kept`` (where some sample flies) and ``step_jumps`` of outputs against their samples."""
    from physmotion.metrics.dynamics import flight_kept, step_jumps

    kept = flight_kept(joints, samples)
    return {"step_jumps": step_jumps(joints, samples)} | ({} if kept is None else {"flight_kept": kept})


def _scores(emb, text_emb, real_emb, r, cfg) -> dict[str, float]:
    """FID, R@1-3, MM-Dist and Diversity of one run; R-Precision batches are shuffled per repeat."""
    order = np.random.default_rng((cfg.seed, 3, r)).permutation(len(emb))
    acc, mm_dist = r_precision(text_emb[order], emb[order], top_k=3, batch_size=cfg.batch_size)
    return {"R@1": float(acc[0]), "R@2": float(acc[1]), "R@3": float(acc[2]), "FID": fid(real_emb, emb),
            "MM-Dist": mm_dist, "Diversity": diversity(emb, cfg.diversity_times, seed=cfg.seed + r)}  # fmt: skip



def _summarise(runs: list[dict[str, float]], per_text: np.ndarray | None) -> dict[str, tuple[float, float]]:
    """Mean and 95% half-width over runs; MultiModality from per_text (N, repeats, D) over captions."""
    keys = dict.fromkeys(k for run in runs for k in run)  # flight_kept: only in runs where a sample flies
    out = {k: confidence_interval([run[k] for run in runs if k in run]) for k in keys}
    if per_text is not None:
        out["MModality"] = confidence_interval(multimodality_per_text(per_text))
    return out


def _fmt(value: tuple[float, float] | None, column: str) -> str:
    if value is None:
        return "-"
    digits = 2 if column in ("sec/motion",) or value[0] >= 10 else 3
    return f"{value[0]:.{digits}f} ± {value[1]:.{digits}f}" if value[1] > 0 else f"{value[0]:.{digits}f}"


def _markdown_table(rows: dict, columns: list[tuple[str, str]]) -> str:
    head = "| | " + " | ".join(label for _, label in columns) + " |"
    sep = "|---|" + "---:|" * len(columns)
    body = ["| " + name + " | " + " | ".join(_fmt(vals.get(c), c) for c, _ in columns) + " |"
            for name, vals in rows.items()]  # fmt: skip
    return "\n".join([head, sep, *body])


def _markdown_header(meta: dict) -> str:
    return (f"Split `{meta['split']}` ({meta['motions']} motions), {meta['repeats']} repeats, "
            f"mean ± 95% interval. Sampler: {meta['sampler']['sampler']} {meta['sampler']['steps']} steps, "
            f"CFG {meta['sampler']['cfg_scale']}. Physical metrics on the {meta['surface']} surface.\n\n")  # fmt: skip
