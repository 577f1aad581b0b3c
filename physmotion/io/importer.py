"""The mocap manifest and one-call import of a clip (or any BVH / AMC file) to a canonical Motion."""

from __future__ import annotations

import csv
import warnings
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TypeVar

import numpy as np

from physmotion.errors import MotionFormatError, PhysmotionError
from physmotion.io.amc import read_amc, read_asf
from physmotion.io.bvh import Latin1Warning, bvh_joint_names, read_bvh
from physmotion.io.canonical import canonicalize
from physmotion.io.floor import STANCE, Grounding, UnevenGroundWarning
from physmotion.io.mapping import load_mapping
from physmotion.io.rigs import RIGS, JointSource, RigMotion, RigTable, parse_units, table_from_mapping
from physmotion.motion import Motion

_T = TypeVar("_T")
MANIFEST = "manifest.csv"
_COLUMNS = (
    "clip", "path", "format", "skeleton", "source", "licence", "licence_tag",
    "fps", "up_axis", "units", "captions", "take",
)  # fmt: skip


@dataclass(frozen=True)
class ClipInfo:
    """One row of ``manifest.csv``; ``path`` and, for AMC, ``skeleton`` are absolute paths."""

    clip: str
    path: Path
    format: str  # "bvh" or "amc"
    skeleton: str  # rig convention name (BVH) or the ASF path (AMC)
    source: str
    licence: str
    licence_tag: str
    fps: float
    up_axis: str
    units: str
    captions: list[str]
    take: str


@dataclass(frozen=True)
class ImportReport:
    """What an import did: the rig table used, source frames and rate, whether a T-pose frame 0 was
    dropped, the per-joint fit of the 22-joint body to the rig's points ((22,) metres, see
    :class:`~physmotion.io.canonical.Canonical`) and how the motion was put on the floor."""

    rig: str
    source_frames: int
    source_fps: float
    dropped_tpose: bool
    fit_mean: np.ndarray
    fit_max: np.ndarray
    grounding: Grounding


def load_manifest(mocap_dir: str | Path) -> list[ClipInfo]:
    """Every clip listed in ``<mocap_dir>/manifest.csv``, in file order."""
    mocap_dir = Path(mocap_dir)
    path = mocap_dir / MANIFEST
    if not path.is_file():
        raise PhysmotionError(f"{path}: no such file (is {mocap_dir} the mocap folder?)")
    with path.open(newline="", encoding="utf-8") as f:
        reader = csv.DictReader(f)
        missing = [c for c in _COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise PhysmotionError(f"{path}: missing column(s) {', '.join(missing)}")
        rows = list(reader)
    clips: list[ClipInfo] = []
    for n, row in enumerate(rows, start=2):
        try:
            fps = float(row["fps"])
        except ValueError:
            raise PhysmotionError(f"{path}:{n}: fps is not a number ({row['fps']!r})") from None
        skeleton = row["skeleton"]
        clips.append(
            ClipInfo(
                clip=row["clip"],
                path=mocap_dir / row["path"],
                format=row["format"].lower(),
                skeleton=str(mocap_dir / skeleton) if row["format"].lower() == "amc" else skeleton,
                source=row["source"],
                licence=row["licence"],
                licence_tag=row["licence_tag"],
                fps=fps,
                up_axis=row["up_axis"].upper(),
                units=row["units"],
                captions=[c.strip() for c in row["captions"].split(" | ") if c.strip()],
                take=row["take"],
            )
        )
    return clips


def import_clip(
    info_or_path: ClipInfo | str | Path,
    *,
    rig: str | RigTable | None = None,
    fps: float | None = None,
    up_axis: str | None = None,
    units: str | float | None = None,
    mapping: Mapping[str, JointSource] | str | Path | None = None,
    asf: str | Path | None = None,
    drop_tpose: bool = True,
    floor: str = STANCE,
) -> Motion:
    """Import a manifest clip, or a bare BVH / AMC file, as a canonical :class:`Motion`.

    Motion: joints (T, 22, 3) float32 at 20 fps, metres, Y up, the stance soles on the floor y = 0
    (:mod:`physmotion.io.floor`), root over the origin and facing +Z at frame 0 (our own BVH export,
    rig ``smpl22``, keeps the placement it was written with: the round trip returns the motion);
    rotations and offsets from the 22-joint IK (FK of them gives ``joints``); texts, licence_tag
    and source (clip id) from the manifest. Each setting comes from the first of these that has it:
    units: the argument, the rig table, the ASF file, the manifest; up axis: the argument, the rig
    table, the manifest, "Y"; fps: the argument, the manifest (the file's true rate), the BVH header.

    rig: a name in :data:`~physmotion.io.rigs.RIGS` or a RigTable; mapping: a user rig's dict of
    SMPL joint -> rig joint (or blend), or the path of a mapping JSON file
    (:mod:`physmotion.io.mapping`), whose units, up axis and fps rank just after the arguments;
    asf: the skeleton of a bare AMC path (default: the only ``.asf`` next to it, or
    ``<subject>.asf`` for ``<subject>_<trial>.amc``); floor: ``"stance"`` (the stance soles on y = 0,
    :mod:`physmotion.io.floor`) or ``"frame0"`` (frame 0's lowest foot joint: the earlier rule,
    which the physics projection's benches and tests feed P).
    Every failure is a :class:`PhysmotionError` with a one-line message naming the file.
    """
    return import_clip_with_report(
        info_or_path,
        rig=rig,
        fps=fps,
        up_axis=up_axis,
        units=units,
        mapping=mapping,
        asf=asf,
        drop_tpose=drop_tpose,
        floor=floor,
    )[0]


# Overflowing numbers in a file end as one error line (non-finite joints are refused), not numpy warnings.
@np.errstate(all="ignore")
def import_clip_with_report(
    info_or_path: ClipInfo | str | Path,
    *,
    rig: str | RigTable | None = None,
    fps: float | None = None,
    up_axis: str | None = None,
    units: str | float | None = None,
    mapping: Mapping[str, JointSource] | str | Path | None = None,
    asf: str | Path | None = None,
    drop_tpose: bool = True,
    floor: str = STANCE,
) -> tuple[Motion, ImportReport]:
    """:func:`import_clip`, also returning an :class:`ImportReport`.

    Files read as Latin-1 (not UTF-8) are named in one :class:`~physmotion.io.bvh.Latin1Warning`."""
    with _one_latin1_warning():
        return _import(info_or_path, rig, fps, up_axis, units, mapping, asf, drop_tpose, floor)


@contextmanager
def _one_latin1_warning() -> Iterator[None]:
    """Gather the Latin-1 warnings of one import (an AMC and its ASF, a file read twice) into one line,
    emitted also when the import fails; other warnings pass through unchanged."""
    caught: list[warnings.WarningMessage] = []
    try:
        with warnings.catch_warnings(record=True) as record:
            warnings.simplefilter("always")
            try:
                yield
            finally:
                caught = list(record or [])
    finally:
        latin1 = [w.message for w in caught if isinstance(w.message, Latin1Warning)]
        for w in caught:
            if not isinstance(w.message, Latin1Warning):
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        paths = list(dict.fromkeys(m.path for m in latin1))
        if len(paths) == 1:
            warnings.warn(latin1[0], stacklevel=4)
        elif paths:
            names = ", ".join(str(p) for p in paths)
            warnings.warn(Latin1Warning(f"{names}: not UTF-8: read as Latin-1", paths[0]), stacklevel=4)


def _import(
    info_or_path: ClipInfo | str | Path,
    rig: str | RigTable | None,
    fps: float | None,
    up_axis: str | None,
    units: str | float | None,
    mapping: Mapping[str, JointSource] | str | Path | None,
    asf: str | Path | None,
    drop_tpose: bool,
    floor: str,
) -> tuple[Motion, ImportReport]:
    info = info_or_path if isinstance(info_or_path, ClipInfo) else None
    path = Path(info.path if info else info_or_path)
    try:
        if isinstance(mapping, (str, Path)):  # a mapping file: its settings rank after the arguments
            loaded = load_mapping(mapping)
            mapping, units = loaded.joints, _first(units, loaded.units)
            up_axis, fps = _first(up_axis, loaded.up_axis), _first(fps, loaded.fps)
        fmt = info.format if info else path.suffix.lower().lstrip(".")
        table = _resolve_table(rig, mapping, info, fmt)
        skeleton: str | Path = ""
        if fmt == "bvh":
            motion = read_bvh(path, keep=table.nodes() if table else None)
        elif fmt == "amc":
            skeleton = asf or (info.skeleton if info else _find_asf(path))
            motion = read_amc(path, skeleton, table.nodes() if table else None)
        else:
            raise MotionFormatError(f"unknown motion format {fmt!r} (expected .bvh or .amc)")
        table = table or _detect_table(motion, units)
        _check_fits(table, motion, path, skeleton, mapping is not None)
        rate = _first(fps, info.fps if info else None, motion.fps)
        if rate is None:
            raise PhysmotionError("the file has no frame rate: give --fps")
        metres = _first(
            parse_units(units) if units is not None else None,
            table.units,
            motion.units,
            parse_units(info.units) if info else None,
        )
        if metres is None:
            raise PhysmotionError(f"units unknown for rig {table.name!r}: give --units")
        up = _first(up_axis.upper() if up_axis else None, table.up_axis, info.up_axis if info else None, "Y")
        canon = canonicalize(
            motion, table, float(rate), units=float(metres), up_axis=str(up), drop_tpose=drop_tpose, floor=floor
        )
        result = Motion(
            joints=canon.joints.astype(np.float32),
            rotations=canon.rotations.astype(np.float32),
            offsets=canon.offsets.astype(np.float32),
            texts=list(info.captions) if info else [],
            licence_tag=info.licence_tag if info else "",
            source=info.clip if info else path.stem,
        )
    except PhysmotionError as exc:
        message = " ".join(str(exc).split())  # one line
        if str(path) not in message:
            message = f"{path}: {message}"
        raise type(exc)(message) from None
    report = ImportReport(
        table.name, motion.num_frames, float(rate), canon.dropped_tpose, canon.fit_mean, canon.fit_max,
        canon.grounding,
    )
    if not canon.grounding.level:
        spread = 100 * canon.grounding.stance_spread
        warnings.warn(UnevenGroundWarning(f"{path}: the body stands at heights {spread:.0f} cm apart: the ground "
                                          "is not level, so on a level floor some steps sink in and some float"),
                      stacklevel=3)  # fmt: skip
    return result, report


def _first(*options: _T | None) -> _T | None:
    return next((o for o in options if o is not None), None)


def _resolve_table(
    rig: str | RigTable | None,
    mapping: Mapping[str, JointSource] | None,
    info: ClipInfo | None,
    fmt: str,
) -> RigTable | None:
    """The rig table named by the arguments or the manifest row; None when it must be detected."""
    if isinstance(rig, RigTable):
        return rig
    if mapping is not None:
        if rig is not None:
            raise PhysmotionError(f"give a rig ({rig!r}) or a mapping, not both")
        return table_from_mapping(mapping, name="mapping")
    name = rig or (info.skeleton if info and fmt == "bvh" else None) or ("cmu_asf" if fmt == "amc" else None)
    if name is None:
        return None
    if name not in RIGS:
        raise PhysmotionError(
            f"unknown rig {name!r} (known: {', '.join(RIGS)}; `physmotion import --rig list` describes "
            "them; for another rig write its joints in a JSON file and give --mapping map.json)"
        )
    return RIGS[name]


def _check_fits(table: RigTable, motion: RigMotion, path: Path, asf: str | Path, is_mapping: bool) -> None:
    """Raise naming each of our joints whose rig joint the file lacks, and the file's joints.

    asf: the skeleton of an AMC file, "" for BVH.
    """
    have = set(motion.names)
    lacking = [
        (joint, node)
        for joint, src in table.joints.items()
        for node in ((src,) if isinstance(src, str) else tuple(n for n, _ in src))
        if node not in have
    ]
    if not lacking:
        return
    # the motion was read pruned to the table's joints: list the file's own
    names = tuple(read_asf(asf).bones) if asf else bvh_joint_names(path)
    label = "mapping:" if is_mapping else f"rig {table.name} does not fit this file:"
    pairs = ", ".join(f"{joint} -> {node!r}" for joint, node in lacking[:3])
    more = f" and {len(lacking) - 3} more" if len(lacking) > 3 else ""
    shown = ", ".join(n[:40] for n in names[:12])
    if len(names) > 12:
        shown += f", ... ({len(names)} in all)"
    raise PhysmotionError(f"{label} {pairs}{more} not found in {path.name} (joints: {shown})")


def _detect_table(motion: RigMotion, units: str | float | None) -> RigTable:
    """The known table whose joints all exist in the file; tables that differ only in units need units=."""
    fits = [t for t in RIGS.values() if t.nodes() <= set(motion.names)]
    if not fits:
        raise PhysmotionError(
            f"unknown rig (joints {', '.join(motion.names[:4])}, ...): give --rig NAME (see --rig list) "
            "or --mapping map.json"
        )
    if len({t.units for t in fits}) > 1 and units is None:
        listed = ", ".join(t.name for t in fits)
        raise PhysmotionError(f"rig is one of {listed}, which differ in units: give --rig or --units")
    return fits[0]


def _find_asf(amc: Path) -> Path:
    """The ASF of a bare AMC path: ``<subject>.asf`` for ``<subject>_<trial>.amc`` (CMU), or the longest
    name prefix of it (HDM05: ``HDM_bd.asf`` for ``HDM_bd_squat1Reps_001_120.amc``), next to it, a folder
    up, or in an ``asf/`` folder beside either; else the sole .asf next to it."""
    parts = amc.stem.split("_")
    folders = [amc.parent, amc.parent.parent, amc.parent / "asf", amc.parent.parent / "asf",
               amc.parent.parent.parent / "asf"]  # fmt: skip
    for n in range(len(parts) - 1, 0, -1):  # the longest prefix first
        for folder in folders:
            guess = folder / ("_".join(parts[:n]) + ".asf")
            if guess.is_file():
                return guess
    candidates = sorted(amc.parent.glob("*.asf")) if amc.parent.is_dir() else []
    if len(candidates) == 1:
        return candidates[0]
    raise MotionFormatError(f"{amc}: cannot tell which .asf skeleton goes with it: give --asf")
