"""Build a dataset in HumanML3D's folder layout from one or more mocap collections (manifest + raw files).

Layout written (HumanML3D's, plus two files of ours)::

    new_joints/<id>.npy       (T, 22, 3) float32 canonical joints the features encode (T = feature frames)
    new_joint_vecs/<id>.npy   (T, 263) float32 HumanML3D features (or (T, 329), BioMoDiffuse's, when built so)
    texts/<id>.txt            one caption per line
    train.txt val.txt test.txt   ids, one per line
    Mean.npy Std.npy          feature statistics of the train split (HumanML3D's cal_mean_variance)
    index.csv                 id, clip, take (the capture), source, licence_tag, split, window start/end
                              frames, mirrored, padded (frames held at the ends of a short clip)
    build_info.json           sources (minutes, clips, licences of each), options, counts, licence tags,
                              skipped clips with reasons
    sources/<name>.md         each source folder's README.md (its attribution and licence terms)
    activations/<id>.npy      (T, 8) float32 muscle-activation stand-ins, optional (:func:`build_activations`)

Differences from HumanML3D, on purpose: ``new_joints`` holds the processed joints that went into the
features rather than joints recovered from them, so the round trip features -> joints can be checked;
Mean/Std come from the train split only, so no statistic leaks from test data.

Several sources (folders with a ``manifest.csv`` in the same columns) build into one dataset: clip ids
must differ across them; a physical capture stays in one split (:func:`capture_of`); every licence tag
and each source's README travel with the data.
"""

from __future__ import annotations

import csv
import hashlib
import json
import os
import re
import shutil
import tempfile
import warnings
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS, MAX_FRAMES, MIN_FRAMES
from physmotion.errors import PhysmotionError
from physmotion.features.biomech import FEATURE_DIM_BIOMECH, extract_features_329
from physmotion.features.humanml3d import FEATURE_DIM, extract_features
from physmotion.features.normalize import compute_mean_std
from physmotion.io.bvh import Latin1Warning
from physmotion.io.importer import ClipInfo, import_clip, load_manifest
from physmotion.physics.activations import ACTIVATION_CHANNELS, activations
from physmotion.physics.workers import map_in_workers, worker_count
from physmotion.skeleton import mirror_joints

SPLITS = ("train", "val", "test")
BUILD_INFO = "build_info.json"
ACTIVATIONS = "activations"
_MISSING_ACTIVATIONS = "run `physmotion data build --activations` (or `physmotion data activations DIR`)"


@dataclass(frozen=True)
class BuildConfig:
    """Options of a dataset build; every field ends up in build_info.json."""

    exclude_licences: tuple[str, ...] = ()
    """Licence tags to leave out, e.g. ("NC",)."""
    split_ratios: tuple[float, float, float] = (0.8, 0.1, 0.1)
    seed: int = 0
    """Salts the take -> split hash; another seed gives another (still take-disjoint) split."""
    mirror: bool = True
    """Add a left/right mirrored copy of every window (ids prefixed "M"), as HumanML3D does."""
    max_frames: int = MAX_FRAMES
    min_frames: int = MIN_FRAMES
    pad_short: bool = True
    """A clip shorter than ``min_frames + 1`` joint frames is held still at both ends up to that length
    (index.csv: ``padded`` frames) rather than skipped: 121 of HDM05's 188 clips are single repetitions
    under 2 s (docs/decisions/data.md "several sources in one build")."""
    jobs: int = 0
    """Worker processes; 0 means one per CPU core."""
    features: int = FEATURE_DIM
    """263 (HumanML3D) or 329 (BioMoDiffuse: + joint accelerations) dimensions in new_joint_vecs."""


@dataclass
class SourceReport:
    """One source folder of a build: its clips, those built, minutes of distinct capture, its licences
    (licence tag -> licence names of its manifest; "" is the tag of clips with no restriction) and
    clips whose files were read as Latin-1."""

    path: str
    clips: int = 0
    built: int = 0
    minutes: float = 0.0
    licences: dict[str, list[str]] = field(default_factory=dict)
    latin1: int = 0


@dataclass
class BuildReport:
    out: Path
    num_clips: int = 0
    num_items: dict[str, int] = field(default_factory=dict)
    minutes: float = 0.0  # distinct capture: mirrored copies not counted
    skipped: dict[str, str] = field(default_factory=dict)
    minutes_with_mirrors: float = 0.0  # every item, mirrored copies included (what training draws from)
    sources: dict[str, SourceReport] = field(default_factory=dict)  # by source name (source_names)


@dataclass
class _Item:
    id: str
    clip: str
    take: str
    source: str
    licence_tag: str
    start: int
    end: int
    mirrored: bool
    texts: list[str]
    features: np.ndarray
    joints: np.ndarray
    padded: int = 0  # frames held at the ends of a short clip (not capture: minutes leave them out)


# HDM05's clips are segments of longer captures (consecutive segments of one actor and class often join
# frame to frame), but its manifest names each segment its own take: the capture is actor + class.
_HDM05_FILE = re.compile(r"^HDM_(?P<actor>[A-Za-z]+)_(?P<label>[A-Za-z0-9]+)_\d+_\d+$")


def capture_of(info: ClipInfo) -> str:
    """The physical capture a clip comes from, which a split must keep on one side: the manifest's
    ``take``, except for HDM05 segments (``HDM_<actor>_<class>_<index>_<fps>``): ``hdm05_<actor>_<class>``."""
    match = _HDM05_FILE.match(info.path.stem)
    return f"hdm05_{match['actor']}_{match['label']}" if match else info.take


def source_names(sources: Sequence[Path]) -> list[str]:
    """A short name per source folder: its folder name, or its whole path where two names clash."""
    names = [Path(s).name or str(s) for s in sources]
    return [n if names.count(n) == 1 else str(s) for n, s in zip(names, sources)]


def split_of(take: str, config: BuildConfig) -> str:
    """The split a take belongs to: a stable hash, so a take never straddles two splits and adding
    clips to a collection does not move the others."""
    digest = hashlib.sha1(f"{config.seed}:{take}".encode()).digest()
    u = int.from_bytes(digest[:8], "big") / 2**64
    train, val, _ = config.split_ratios
    return "train" if u < train else "val" if u < train + val else "test"


def windows(num_frames: int, max_frames: int = MAX_FRAMES) -> list[tuple[int, int]]:
    """Cut ``num_frames`` joint frames into windows of at most ``max_frames`` feature frames.

    Features have one frame fewer than the joints they come from, so a window [s, e) of joints
    gives e - s - 1 feature frames; neighbouring windows share one joint frame. Windows are of
    near-equal length. Returns [(start, end)] joint-frame ranges.
    """
    steps = num_frames - 1
    count = max(1, -(-steps // max_frames))
    bounds = np.linspace(0, steps, count + 1).round().astype(int)
    return [(int(a), int(b) + 1) for a, b in zip(bounds[:-1], bounds[1:])]


_SWAP = re.compile(r"\b(left|right)\b", re.IGNORECASE)


def mirror_text(text: str) -> str:
    """Caption of the mirrored motion: 'left' and 'right' swapped, case kept."""

    def swap(m: re.Match[str]) -> str:
        word = m.group(0)
        new = "right" if word.lower() == "left" else "left"
        return new.capitalize() if word[0].isupper() else new

    return _SWAP.sub(swap, text)


def _process_clip(info: ClipInfo, config: BuildConfig) -> tuple[list[_Item] | str, bool]:
    """Import one clip and cut it into feature windows (a string: the reason it was skipped); and
    whether its files were read as Latin-1 (the build reports that once, not once per clip)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", Latin1Warning)
        try:
            result = _windows_of(info, config)
        except PhysmotionError as exc:
            result = str(exc)
    latin1 = any(issubclass(w.category, Latin1Warning) for w in caught)
    for w in caught:
        if not issubclass(w.category, Latin1Warning):
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return result, latin1


def pad_ends(joints: np.ndarray, frames: int) -> tuple[np.ndarray, int]:
    """``joints`` (T, ...) lengthened to ``frames`` by holding its first and last frames (half before, half
    after: a still start and end, as a capture of one short action would hold), and the frames added."""
    need = max(frames - len(joints), 0)
    before = need // 2
    out = np.concatenate([np.repeat(joints[:1], before, 0), joints, np.repeat(joints[-1:], need - before, 0)])
    return out, need


def _windows_of(info: ClipInfo, config: BuildConfig) -> list[_Item] | str:
    motion = import_clip(info)
    whole = motion.joints
    padded = 0
    if motion.num_frames - 1 < config.min_frames:
        if not config.pad_short:
            return f"too short: {motion.num_frames} frames at {FPS} fps, need {config.min_frames + 1}"
        whole, padded = pad_ends(whole, config.min_frames + 1)
    items: list[_Item] = []
    for k, (s, e) in enumerate(windows(len(whole), config.max_frames)):
        if e - s - 1 < config.min_frames:
            continue
        for mirrored in (False, True) if config.mirror else (False,):
            joints = whole[s:e]
            joints = mirror_joints(joints) if mirrored else joints
            feats, canon = _extract(joints, config.features)
            texts = [mirror_text(t) for t in motion.texts] if mirrored else list(motion.texts)
            items.append(
                _Item(
                    id=f"{'M' if mirrored else ''}{info.clip}_{k:02d}",
                    clip=info.clip, take=capture_of(info), source=info.source, licence_tag=info.licence_tag,
                    start=s, end=e, mirrored=mirrored, texts=texts,
                    features=feats.astype(np.float32), joints=canon[:-1].astype(np.float32), padded=padded,
                )  # fmt: skip
            )
    return items


def _extract(joints: np.ndarray, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(features (T-1, dim), canonical joints (T, 22, 3)) for dim 263 or 329."""
    return extract_features_329(joints) if dim == FEATURE_DIM_BIOMECH else extract_features(joints)


def build_dataset(
    source: str | Path | Sequence[str | Path],
    out: str | Path,
    config: BuildConfig | None = None,
    progress: bool = True,
) -> BuildReport:
    """Import every clip of the sources' manifests and write a HumanML3D-layout dataset to ``out``.

    source: one mocap folder or several (each with a ``manifest.csv`` in the same columns; clip ids must
    not repeat across them). The folder appears whole or not at all: it is written next to ``out`` and
    renamed into place. An existing ``out`` is replaced only if it is an earlier build (has
    build_info.json). Deterministic: the same sources and config give byte-identical files.
    """
    config = config or BuildConfig()
    if config.features not in (FEATURE_DIM, FEATURE_DIM_BIOMECH):
        raise PhysmotionError(f"features must be {FEATURE_DIM} or {FEATURE_DIM_BIOMECH}, got {config.features}")
    folders = [Path(source)] if isinstance(source, (str, Path)) else [Path(s) for s in source]
    if not folders:
        raise PhysmotionError("no source folder given")
    if len({f.resolve() for f in folders}) < len(folders):
        raise PhysmotionError(f"a source folder is given twice: {', '.join(str(f) for f in folders)}")
    out = Path(out)
    if out.exists() and not (out / BUILD_INFO).is_file():
        raise PhysmotionError(f"{out} exists and is not a physmotion dataset build; choose another --out")
    names = source_names(folders)
    report = BuildReport(out=out)
    clips: list[ClipInfo] = []
    name_of: dict[str, str] = {}  # clip id -> source name
    for folder, name in zip(folders, names):
        rows = [c for c in load_manifest(folder) if c.licence_tag not in config.exclude_licences]
        for c in rows:
            if c.clip in name_of:
                raise PhysmotionError(f"clip id {c.clip!r} is in both {name_of[c.clip]} and {name}: ids must be unique")
            name_of[c.clip] = name
        licences: dict[str, set[str]] = {}
        for c in rows:
            licences.setdefault(c.licence_tag, set()).add(c.licence)
        report.sources[name] = SourceReport(
            str(folder), clips=len(rows), licences={t: sorted(v) for t, v in sorted(licences.items())}
        )
        clips.extend(rows)
    where = ", ".join(str(f) for f in folders)
    if not clips:
        raise PhysmotionError(f"{where}: no clips left to build (all excluded by licence?)")

    report.num_clips = len(clips)
    results = _run_all(clips, config, progress)
    items: list[_Item] = []
    for info, (result, latin1) in zip(clips, results):
        src = report.sources[name_of[info.clip]]
        src.latin1 += int(latin1)
        if isinstance(result, str):
            report.skipped[info.clip] = result
        else:
            items.extend(result)
            src.built += 1
            src.minutes += sum(i.features.shape[0] - i.padded for i in result if not i.mirrored) / FPS / 60
    if not items:
        raise PhysmotionError(f"{where}: no clip could be imported")

    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(dir=out.parent, prefix=f".{out.name}."))
    try:
        report.num_items, report.minutes, report.minutes_with_mirrors = _write_layout(tmp, items, config)
        readmes = tmp / "sources"
        readmes.mkdir()
        for folder, name in zip(folders, names):  # attribution and licence terms go with the data (SA)
            if (folder / "README.md").is_file():
                shutil.copyfile(folder / "README.md", readmes / f"{name.replace('/', '_')}.md")
        info = {
            "source": str(folders[0]) if len(folders) == 1 else [str(f) for f in folders],
            "sources": {name: asdict(src) | {"minutes": round(src.minutes, 3)} for name, src in report.sources.items()},
            "config": asdict(config),
            "clips": report.num_clips,
            "items": report.num_items,
            "minutes": round(report.minutes, 3),
            "licence_tags": sorted({i.licence_tag or "open" for i in items}),
            "padded_clips": sorted({i.clip for i in items if i.padded}),
            "skipped": report.skipped,
        }
        (tmp / BUILD_INFO).write_text(json.dumps(info, indent=2, sort_keys=True) + "\n")
        _replace_dir(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return report


def _run_all(
    clips: list[ClipInfo], config: BuildConfig, progress: bool
) -> list[tuple[list[_Item] | str, bool]]:
    from rich.progress import Progress

    jobs = config.jobs or os.cpu_count() or 1
    with Progress(disable=not progress, transient=True) as bar:
        task = bar.add_task("importing clips", total=len(clips))
        if jobs == 1:
            results = []
            for info in clips:
                results.append(_process_clip(info, config))
                bar.advance(task)
            return results
        with ProcessPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_process_clip, info, config) for info in clips]
            results = []
            for fut in futures:  # in manifest order, so the build is deterministic
                results.append(fut.result())
                bar.advance(task)
            return results


def _write_layout(root: Path, items: list[_Item], config: BuildConfig) -> tuple[dict[str, int], float, float]:
    for sub in ("new_joints", "new_joint_vecs", "texts"):
        (root / sub).mkdir()
    split_ids: dict[str, list[str]] = {s: [] for s in SPLITS}
    for item in items:
        np.save(root / "new_joints" / f"{item.id}.npy", item.joints)
        np.save(root / "new_joint_vecs" / f"{item.id}.npy", item.features)
        (root / "texts" / f"{item.id}.txt").write_text("\n".join(item.texts) + "\n")
        split_ids[split_of(item.take, config)].append(item.id)
    for split, ids in split_ids.items():
        (root / f"{split}.txt").write_text("".join(f"{i}\n" for i in ids))

    train = set(split_ids["train"]) or {i.id for i in items}
    mean, std = compute_mean_std([i.features for i in items if i.id in train])
    np.save(root / "Mean.npy", mean.astype(np.float32))
    np.save(root / "Std.npy", std.astype(np.float32))

    with open(root / "index.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "clip", "take", "source", "licence_tag", "split", "start", "end", "mirrored", "padded"])
        for i in items:
            w.writerow([i.id, i.clip, i.take, i.source, i.licence_tag, split_of(i.take, config),
                        i.start, i.end, int(i.mirrored), i.padded])  # fmt: skip
    counts = {s: len(ids) for s, ids in split_ids.items()}
    # Minutes of distinct motion: mirrored copies are not counted twice, frames held by padding not at all.
    minutes = sum(i.features.shape[0] - i.padded for i in items if not i.mirrored) / FPS / 60
    with_mirrors = sum(i.features.shape[0] for i in items) / FPS / 60
    return counts, minutes, with_mirrors


def _replace_dir(new: Path, out: Path) -> None:
    """Swap ``new`` into ``out`` with renames, so readers never see a half-written folder."""
    if out.exists():
        trash = out.with_name(f".{out.name}.old")
        shutil.rmtree(trash, ignore_errors=True)
        os.replace(out, trash)
        os.replace(new, out)
        shutil.rmtree(trash, ignore_errors=True)
    else:
        os.replace(new, out)


# ----------------------------------------------------------------------------------------------
# Activation cache (physics/activations.py): one (T, 8) array per item, next to new_joints/.


def build_activations(root: str | Path, progress: bool = True, jobs: int = 0) -> int:
    """Write ``activations/<id>.npy`` (T, 8) float32 for every item in ``root/new_joints``.

    The folder appears whole or not at all (written next to it and renamed into place; an earlier
    cache is replaced), and build_info.json records it. Deterministic: the same joints give
    byte-identical files. jobs: worker processes, 0 = one per core. Returns the number of items.
    """
    from rich.progress import Progress

    root = Path(root)
    if not (root / BUILD_INFO).is_file() or not (root / "new_joints").is_dir():
        raise PhysmotionError(f"{root} is not a physmotion dataset build (no {BUILD_INFO} or new_joints/)")
    paths = sorted((root / "new_joints").glob("*.npy"))
    if not paths:
        raise PhysmotionError(f"{root}/new_joints holds no motions")
    # Chunks of a few items per worker: the bar moves while the pool stays busy.
    chunk = 4 * worker_count(jobs, len(paths))
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=f".{ACTIVATIONS}."))
    try:
        with Progress(disable=not progress, transient=True) as bar:
            task = bar.add_task("activations", total=len(paths))
            for k in range(0, len(paths), chunk):
                part = paths[k : k + chunk]
                for path, act in zip(part, map_in_workers(_activations_of, part, jobs)):
                    np.save(tmp / path.name, act)
                bar.advance(task, len(part))
        _replace_dir(tmp, root / ACTIVATIONS)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    info = json.loads((root / BUILD_INFO).read_text())
    info[ACTIVATIONS] = {
        "channels": list(ACTIVATION_CHANNELS),
        "source": "inverse dynamics of the physmotion humanoid",
        "fps": FPS,
        "items": len(paths),
    }
    _write_atomic(root / BUILD_INFO, json.dumps(info, indent=2, sort_keys=True) + "\n")
    return len(paths)


def load_activations(root: str | Path, id: str) -> np.ndarray:
    """The cached activations (T, 8) float32 of item ``id``, channels :data:`ACTIVATION_CHANNELS`."""
    folder = Path(root) / ACTIVATIONS
    if not folder.is_dir():
        raise PhysmotionError(f"{root} has no activation cache; {_MISSING_ACTIVATIONS}")
    path = folder / f"{id}.npy"
    if not path.is_file():
        raise PhysmotionError(f"{root}: no cached activations for '{id}'; {_MISSING_ACTIVATIONS}")
    return np.load(path)


def _activations_of(path: Path) -> np.ndarray:
    return activations(np.load(path), float(FPS))


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
