"""Morph's synthetic data (Sec. 3.1, App. A): motions generated for every train caption, pre-processed
and refined by the physics projection P, written as a folder that fine-tuning reads.

Layout of ``SYNTH/`` (one item per planned sample, ids ``s{index:06d}``, caption-major, K per caption)::

    synth.json                     the run's settings (model and its sha256, config, items planned)
    index.csv                      one row per finished item: id,caption,frames,mpjpe_mean,mpjpe_max,
                                   success,resets,grounded,licence_tag (frames: its feature rows, T-1)
    new_joints/<id>.npy            P's simulated joints (T, 22, 3) float32, physical coordinates
    new_joint_vecs/<id>.npy        their HumanML3D features (T-1, 263) float32 (extract_features)
    input_joints/<id>.npy          the pre-processed generated joints (T, 22, 3) float32
    input_joint_vecs/<id>.npy      their features (T-1, 263) float32
    texts/<id>.txt                 "caption#tokens#0.0#0.0" (tokens empty)
    teacher/<id>.npz               with the search controller only: its teacher records (observations,
                                   offsets per control step: physics/search.py ``save_teacher``)

Every file is written atomically and an item's index row only after its files, so a killed run never
counts half an item; a run on a folder with the same settings continues where it stopped.
"""

from __future__ import annotations

import contextlib
import csv
import hashlib
import io
import json
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
import torch

from physmotion.checkpoint import WEIGHTS_FILE, weights_sha256
from physmotion.conventions import FPS, MIN_FRAMES
from physmotion.data.dataset import length_limit, read_captions, read_split
from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
from physmotion.diffusion.samplers import SamplerConfig, ddim_50, sample
from physmotion.errors import PhysmotionError
from physmotion.features.humanml3d import FEATURE_DIM, extract_features, recover_from_ric
from physmotion.metrics.report import residual_stats
from physmotion.morph.captions import is_grounded
from physmotion.morph.preprocess import PreprocessConfig, preprocess
from physmotion.morph.selection import HELP_FIELDS, INDEX, INDEX_FIELDS, SYNTH_INFO, TAU, read_index
from physmotion.motion import write_atomic
from physmotion.physics.projection import ProjectionConfig, project
from physmotion.physics.workers import map_in_workers

SUBDIRS = ("new_joints", "new_joint_vecs", "input_joints", "input_joint_vecs", "texts")


class SynthError(PhysmotionError):
    """A synthetic data run that cannot start: another model's or setting's folder, no captions."""


@dataclass
class SynthConfig:
    """Settings of :func:`synthesize`; all but ``batch_size`` and ``workers`` are part of the folder's
    identity (a run continues a folder only with the same ones)."""

    per_caption: int = 1  # K samples per distinct train caption
    seed: int = 0  # noise of item i: (seed, i); lengths: one draw seeded by seed
    batch_size: int = 16  # samples per denoiser batch
    workers: int = 0  # physics worker processes, 0: one per core
    ray: str | None = None  # refine on Ray at this address ("local": a Ray on this machine) instead of workers
    sampler: SamplerConfig = field(default_factory=ddim_50)  # the shipped Morph model's synthetic data
    tau: float = TAU  # Morph's selection threshold (App. B), also P's failure threshold
    preprocess: PreprocessConfig = field(default_factory=PreprocessConfig)
    split: str = "train"
    max_frames: int | None = None  # clip the drawn lengths further (quick runs); None: the model's
    ilc_passes: int = 0  # P with iterative learning control (ProjectionConfig.ilc_passes); 0: plain P
    controller: str = "tracker"  # P's controller (ProjectionConfig.controller): "tracker", "policy" or "search"
    policy: str | None = None  # the policy folder for "policy"; None: the shipped one
    captions: int | None = None  # a seeded random subset of this many distinct captions; None: every one

    def __post_init__(self) -> None:
        if self.captions is not None and self.captions < 1:
            raise SynthError(f"--captions must be at least 1, got {self.captions}")
        self.projection()  # P's settings checked before any work (ShapeError, one line)

    def projection(self) -> ProjectionConfig:
        """P as Morph's selection uses it: no reset on failure, the episode stops where MPJPE passes tau."""
        plain = ProjectionConfig(tau=self.tau, reset_on_fail=False, workers=1, ilc_passes=self.ilc_passes)
        return plain.with_controller(self.controller, self.policy)


@dataclass
class SynthReport:
    """What one :func:`synthesize` call did. seconds: wall time; sampling_seconds: in the denoiser;
    physics_seconds: pre-processing, P, features and writing (the worker batch, waited for)."""

    out: Path
    planned: int
    done: int  # items finished by this call
    total_done: int  # items in index.csv now
    skipped: int  # items found finished and not redone
    seconds: float
    sampling_seconds: float
    physics_seconds: float

    @property
    def items_per_second(self) -> float:
        return self.done / self.seconds if self.seconds > 0 else 0.0


# --- the plan ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class PlannedItem:
    index: int
    caption: str
    frames: int

    @property
    def id(self) -> str:
        return f"s{self.index:06d}"


def train_captions(data_dir: str | Path, split: str = "train") -> list[str]:
    """Every distinct caption of a split, in first-seen order over the split file."""
    root = Path(data_dir)
    seen: dict[str, None] = {}
    for mid in read_split(root, split):
        path = root / "texts" / f"{mid}.txt"
        if path.is_file():
            for caption, _, _ in read_captions(path):
                seen.setdefault(caption.strip(), None)
    return [c for c in seen if c]


def caption_subset(captions: Sequence[str], n: int, seed: int) -> list[str]:
    """A seeded random choice of ``n`` of ``captions`` (all if fewer), in their order: a small run over
    the split's whole range of motion, where the split's own order groups captions by source."""
    if n >= len(captions):
        return list(captions)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xCA9]))
    return [captions[i] for i in sorted(rng.choice(len(captions), size=n, replace=False))]


def split_lengths(data_dir: str | Path, split: str = "train", max_length: int | None = None) -> np.ndarray:
    """Frames of every motion of a split (rows of its new_joint_vecs files, read from the .npy header);
    with ``max_length``, only the motions a training run with that max_length keeps (HumanML3D's filter:
    fewer than max_length + 4 frames)."""
    root = Path(data_dir)
    out = []
    for mid in read_split(root, split):
        path = root / "new_joint_vecs" / f"{mid}.npy"
        if path.is_file():
            out.append(np.load(path, mmap_mode="r").shape[0])
    lengths = np.asarray(out, dtype=np.int64)
    return lengths if max_length is None else lengths[lengths < length_limit(max_length)]


def plan_items(captions: Sequence[str], lengths: np.ndarray, per_caption: int, seed: int,
               max_frames: int) -> list[PlannedItem]:  # fmt: skip
    """The planned samples: caption-major, ``per_caption`` each, each length drawn (one seeded draw
    for the whole plan, so it does not change on resume) from ``lengths`` and clipped to
    [MIN_FRAMES // 2, max_frames]."""
    n = len(captions) * per_caption
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x5EED]))
    drawn = np.clip(rng.choice(lengths, size=n), min(MIN_FRAMES // 2, max_frames), max_frames)
    return [PlannedItem(i, captions[i // per_caption], int(drawn[i])) for i in range(n)]


def item_noise(seed: int, index: int, frames: int, dim: int) -> torch.Tensor:
    """x_T (frames, dim) of planned item ``index``: from (seed, index) only, drawn at a fixed width
    (``frames`` = the network's max_frames) and cropped by the caller, so neither the batch nor its
    padding changes it."""
    state = int(np.random.SeedSequence([seed, index]).generate_state(1)[0])
    return torch.randn(frames, dim, generator=torch.Generator().manual_seed(state))


# --- the run ----------------------------------------------------------------------------------------


def _identity(info: dict) -> dict:
    """The synth.json fields a continued run must share."""
    keys = ("model_sha256", "feature_dim", "skeleton", "fps", "split", "per_caption", "seed", "tau",
            "preprocess", "projection", "sampler", "max_frames", "captions", "items_planned",
            "plan_sha256", "lengths")  # fmt: skip
    return {k: info.get(k) for k in keys}


def _setting_sections(
    preprocess: PreprocessConfig, projection: ProjectionConfig, sampler: SamplerConfig
) -> dict:
    """The configuration sections of synth.json (pre-processing, P, sampler) as it stores them: P without
    its worker count, which does not change the results."""
    proj = asdict(projection)
    proj.pop("workers")
    return {"preprocess": asdict(preprocess), "projection": proj, "sampler": asdict(sampler)}


# Fields whose default changed after they were added: the value a folder written before the field existed
# was made with (the arm fit came in off, then became the default).
_BEFORE_FIELD = {"projection": {"reach_arms": False}}


def _setting_defaults() -> dict:
    """The configuration sections of synth.json as a re-read synth.json has them, at the values that a
    folder written before a field existed was made with: the field's default, or :data:`_BEFORE_FIELD`'s."""
    defaults = json.loads(json.dumps(_setting_sections(PreprocessConfig(), ProjectionConfig(), ddim_50())))
    return {k: v | _BEFORE_FIELD.get(k, {}) for k, v in defaults.items()}


def _with_defaults(stored: object, defaults: dict) -> object:
    """``stored`` settings (a synth.json's) with the fields it lacks taken from ``defaults``: a field is
    added to a configuration with a default that keeps what the code did before, so a folder written
    before the field existed was made with that default (or :data:`_BEFORE_FIELD`'s value, where the
    default changed later)."""
    if not isinstance(stored, dict):
        return stored
    filled = {k: _with_defaults(stored[k], v) if k in stored else v for k, v in defaults.items()}
    return filled | {k: v for k, v in stored.items() if k not in defaults}


def _check_resume(out: Path, info: dict) -> None:
    """Refuse a folder made by another model or with other settings; nothing is written before this."""
    path = out / SYNTH_INFO
    if not path.exists():
        # synth.json is the first file a run writes, so a folder without it holds no run of ours
        if out.is_dir() and any(out.iterdir()):
            raise SynthError(f"{out} is a folder that is not empty and not a synthetic data folder "
                             f"(no {SYNTH_INFO}); choose another -o")  # fmt: skip
        return
    try:
        old = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SynthError(f"{path}: not readable ({exc}); choose another -o") from None
    if old.get("model_sha256") != info["model_sha256"]:
        raise SynthError(f"{out} was made by another model ({old.get('model')}, sha256 "
                         f"{str(old.get('model_sha256'))[:12]}); choose another -o")  # fmt: skip
    old = _with_defaults(old, _setting_defaults())
    diff = _first_difference(_identity(old), _identity(info))
    if diff:
        k, there, now = diff
        raise SynthError(f"{out} was made with other settings ({k}: {there} there, {now} now); "
                         "choose another -o or the same settings")  # fmt: skip


def _first_difference(a: object, b: object, path: str = "") -> tuple[str, object, object] | None:
    """(dotted key, value in a, value in b) of the first setting where ``a`` and ``b`` differ, down to the
    innermost key (P's settings nest three deep), or None."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in list(a) + [k for k in b if k not in a]:
            diff = _first_difference(a.get(k), b.get(k), f"{path}.{k}" if path else k)
            if diff:
                return diff
        return None
    return None if a == b else (path, a, b)


def _save_npy(path: Path, array: np.ndarray) -> None:
    write_atomic(path, lambda f: np.save(f, array))


def _write_index(out: Path, rows: list[dict]) -> None:
    """The whole index.csv, atomically: a reader never sees a half row."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=[*INDEX_FIELDS, *HELP_FIELDS], lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    data = buf.getvalue().encode("utf-8")
    write_atomic(out / INDEX, lambda f: f.write(data))


def refine_item(joints: np.ndarray, preprocess_config: PreprocessConfig,
                projection: ProjectionConfig) -> dict[str, np.ndarray | float | bool | int]:  # fmt: skip
    """Pre-process one generated motion (T, 22, 3), refine it with P, and compute both features.

    Runs in a worker process (numpy, scipy and MuJoCo only). Returns input_joints (T, 22, 3),
    input_vecs (T-1, 263), sim_joints (T, 22, 3) (always the simulation), sim_vecs (T-1, 263), float32,
    and mpjpe_mean, mpjpe_max (m), success, resets, and P's help (``HELP_FIELDS``): residual_force (mean,
    x W), residual_at_cap and over_limit (shares of frames).
    """
    x = preprocess(joints, preprocess_config)
    result = project(x, fps=FPS, config=projection)
    sim = result.simulated.astype(np.float32)
    helped = residual_stats(result.residual, projection.residual_bound(), result.at_cap, result.residual_peak)
    return {
        "input_joints": x,
        "input_vecs": extract_features(x)[0],
        "sim_joints": sim,
        "sim_vecs": extract_features(sim)[0],
        "mpjpe_mean": float(result.mpjpe.mean()),
        "mpjpe_max": float(result.mpjpe.max()),
        "success": bool(result.success),
        "resets": int(result.resets),
        "residual_force": helped["residual_force"],
        "residual_at_cap": helped["residual_at_cap"],
        "over_limit": float(np.mean(result.over_limit)),
        # the search's teacher records (None under the tracker and the policy)
        "teacher_obs": result.teacher_obs,
        "teacher_offsets": result.teacher_offsets,
    }


def synthesize(
    model_dir: str | Path | None,
    data_dir: str | Path,
    out_dir: str | Path,
    config: SynthConfig | None = None,
    progress: bool = False,
    captions: Sequence[str] | None = None,
    limit: int | None = None,
    model: MotionDiffusion | None = None,
) -> SynthReport:
    """Generate, pre-process and refine Morph's synthetic data set into ``out_dir`` (layout: module doc).

    model_dir: the generator's folder (None: the shipped model). data_dir: a HumanML3D-layout folder;
    its ``config.split`` captions are generated (each distinct caption ``per_caption`` times) at lengths
    drawn from that split's motions. captions: generate these instead (tests, small runs). limit: stop
    after this many new items (a later call continues). model: the loaded model of ``model_dir``, if the
    caller has it. Deterministic: an item's files depend on the seed and its index only.
    Raises SynthError for a folder made by another model or with other settings (nothing overwritten).
    """
    from physmotion.paths import check_output

    cfg = config or SynthConfig()
    out = Path(out_dir)
    check_output(out, "folder", overwrite=True)
    cfg.sampler.check()
    if not 1 <= cfg.per_caption <= 1000:
        raise SynthError(f"--per-caption must be between 1 and 1000, got {cfg.per_caption}")
    if cfg.batch_size < 1:
        raise SynthError(f"batch size must be at least 1, got {cfg.batch_size}")
    folder = Path(model_dir) if model_dir is not None else DEFAULT_MODEL_DIR
    net = model or MotionDiffusion.load(folder)
    if not (folder / WEIGHTS_FILE).is_file():
        raise SynthError(f"{folder}: no {WEIGHTS_FILE}")
    sha = weights_sha256(folder)
    if net.denoiser.feature_dim != FEATURE_DIM:
        raise SynthError(f"the model makes {net.denoiser.feature_dim}-d features; Morph's data needs {FEATURE_DIM}")
    texts = list(captions) if captions is not None else train_captions(data_dir, cfg.split)
    if not texts:
        raise SynthError(f"{data_dir}: no captions in its {cfg.split} split")
    if cfg.captions is not None:
        texts = caption_subset(texts, cfg.captions, cfg.seed)
    trained = net.trained_max_length
    lengths = split_lengths(data_dir, cfg.split, trained)  # the lengths the model trained on
    if not len(lengths):
        raise SynthError(f"{data_dir}: no motions in its {cfg.split} split to draw lengths from")
    max_frames = min(trained, cfg.max_frames or trained)
    plan = plan_items(texts, lengths, cfg.per_caption, cfg.seed, max_frames)
    projection = cfg.projection()
    plan_sha = hashlib.sha256("\n".join(f"{p.caption}\t{p.frames}" for p in plan).encode()).hexdigest()
    info = {
        "model": str(folder), "model_sha256": sha, "feature_dim": FEATURE_DIM, "skeleton": "smpl22",
        "fps": FPS, "data": str(data_dir), "split": cfg.split, "per_caption": cfg.per_caption,
        "seed": cfg.seed, "tau": cfg.tau, "licence_tags": list(net.info.get("licence_tags", [])),
        "licence_tag": net.licence_tag, **_setting_sections(cfg.preprocess, projection, cfg.sampler),
        "max_frames": max_frames, "items_planned": len(plan), "plan_sha256": plan_sha,
        "lengths": "features",  # a planned length counts feature rows (docs/decisions/morph.md)
        "captions": cfg.captions,
    }  # fmt: skip
    info = json.loads(json.dumps(info))  # tuples -> lists, as a re-read synth.json has them
    _check_resume(out, info)

    rows = read_index(out)
    done_ids = {r["id"] for r in rows}
    todo = [p for p in plan if p.id not in done_ids]
    skipped = len(plan) - len(todo)
    if limit is not None:
        todo = todo[: max(0, limit)]
    if not (out / SYNTH_INFO).exists():
        data = json.dumps(info, indent=2, ensure_ascii=False).encode("utf-8")
        write_atomic(out / SYNTH_INFO, lambda f: f.write(data))
    for sub in SUBDIRS:
        (out / sub).mkdir(parents=True, exist_ok=True)

    start = time.perf_counter()
    t_sample = t_phys = 0.0
    done = 0
    with _session(cfg.ray), _bar(progress, len(plan), skipped) as tick:
        for b in range(0, len(todo), cfg.batch_size):
            batch = todo[b : b + cfg.batch_size]
            t0 = time.perf_counter()
            joints = _sample_batch(net, batch, cfg)
            t1 = time.perf_counter()
            results = _refine(joints, cfg, projection)
            for item, res in zip(batch, results):
                rows.append(_write_item(out, item, res, net.licence_tag))
                _write_index(out, rows)  # last: the item counts only once its files exist
                done += 1
                tick(1)
            t_sample += t1 - t0
            t_phys += time.perf_counter() - t1
    return SynthReport(out=out, planned=len(plan), done=done, total_done=len(rows), skipped=skipped,
                       seconds=time.perf_counter() - start, sampling_seconds=t_sample,
                       physics_seconds=t_phys)  # fmt: skip


def _session(ray: str | None):
    """One Ray session for the whole run where ``ray`` is given (each batch's tasks join it)."""
    if ray is None:
        return contextlib.nullcontext()
    from physmotion.physics.cluster import ray_session

    return ray_session(ray)


def _refine(joints: list[np.ndarray], cfg: SynthConfig, projection: ProjectionConfig) -> list[dict]:
    """:func:`refine_item` of each motion of a batch, in order: on Ray (one task per motion) or in the
    local worker processes."""
    if cfg.ray is None:
        return map_in_workers(partial(refine_item, preprocess_config=cfg.preprocess, projection=projection),
                              joints, cfg.workers)  # fmt: skip
    from physmotion.physics.cluster import map_on_ray, one_core

    fn = partial(refine_item, preprocess_config=cfg.preprocess, projection=one_core(projection))
    results: list[dict] = [{}] * len(joints)
    for i, res in map_on_ray(fn, joints, cfg.ray):
        results[i] = res
    return results


def _sample_batch(net: MotionDiffusion, batch: list[PlannedItem], cfg: SynthConfig) -> list[np.ndarray]:
    """Plain sampling (no physics) of one batch: joints (T_i, 22, 3) float64 per item, T_i = frames + 1
    (at most the network's width), so that their features, one row fewer, have the planned length: a
    length drawn from the data is a feature length, and the shortest would otherwise fall under the
    training minimum (docs/decisions/morph.md, "synthetic lengths count feature rows")."""
    full = net.denoiser.max_frames
    lengths = [min(p.frames + 1, full) for p in batch]
    width, dim = max(lengths), net.denoiser.feature_dim
    noise = torch.stack([item_noise(cfg.seed, p.index, full, dim)[:width] for p in batch])
    x = sample(net, [p.caption for p in batch], lengths, cfg.sampler, seed=cfg.seed, noise=noise)
    feats = net.normalizer.denormalize(x.float().cpu().numpy())
    return [recover_from_ric(f[:n].astype(np.float64)) for f, n in zip(feats, lengths)]


def _write_item(out: Path, item: PlannedItem, res: dict, licence_tag: str) -> dict:
    """Write one item's files (each atomically); returns its index row."""
    _save_npy(out / "new_joints" / f"{item.id}.npy", np.asarray(res["sim_joints"], dtype=np.float32))
    _save_npy(out / "new_joint_vecs" / f"{item.id}.npy", np.asarray(res["sim_vecs"], dtype=np.float32))
    _save_npy(out / "input_joints" / f"{item.id}.npy", np.asarray(res["input_joints"], dtype=np.float32))
    _save_npy(out / "input_joint_vecs" / f"{item.id}.npy", np.asarray(res["input_vecs"], dtype=np.float32))
    if res.get("teacher_obs") is not None:
        records = {"observations": res["teacher_obs"], "offsets": res["teacher_offsets"],
                   "text": np.array(item.caption), "licence_tag": np.array(licence_tag)}  # fmt: skip
        (out / "teacher").mkdir(exist_ok=True)
        write_atomic(out / "teacher" / f"{item.id}.npz", lambda f: np.savez_compressed(f, **records))
    line = f"{item.caption.replace('#', ' ')}##0.0#0.0\n".encode()
    write_atomic(out / "texts" / f"{item.id}.txt", lambda f: f.write(line))
    return {
        "id": item.id, "caption": item.caption, "frames": item.frames,
        "mpjpe_mean": f"{res['mpjpe_mean']:.6f}", "mpjpe_max": f"{res['mpjpe_max']:.6f}",
        "success": int(res["success"]), "resets": int(res["resets"]),
        "grounded": int(is_grounded(item.caption)), "licence_tag": licence_tag,
        **{k: f"{res[k]:.6f}" for k in HELP_FIELDS},
    }  # fmt: skip


def _bar(enabled: bool, total: int, already: int):
    """A context manager yielding tick(n): a rich bar with ETA on stderr (silent where not enabled)."""
    from contextlib import contextmanager

    from rich.console import Console
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    @contextmanager
    def bar():
        prog = Progress(TextColumn("synthesizing"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(),
                        console=Console(stderr=True), disable=not enabled)  # fmt: skip
        with prog:
            task = prog.add_task("synth", total=total, completed=already)
            yield lambda n: prog.advance(task, n)

    return bar()
