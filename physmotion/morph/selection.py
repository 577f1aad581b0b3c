"""Morph's imitation selection (Sec. 3.3) over a synthetic data folder written by
:func:`physmotion.morph.synth.synthesize`.

Per item, the refined motion (P's simulation) is kept where the imitation succeeded: the episode ran to
the end (``success``) and the MPJPE between the motion before and after refinement is under ``tau``
(``mpjpe_mean < tau``, metres), and the caption describes grounded motion (Morph annotates non-grounded
and interaction motions by hand and leaves them out of the physics terms; we flag them by rule, see
:mod:`physmotion.morph.captions`). Otherwise the pre-processed input motion is kept.

IFR (Morph's imitation failure rate) is the share of *grounded* items whose refinement was rejected by
the MPJPE/success test; non-grounded items are not counted in it (as Morph leaves them out of MPR) and
are reported separately (``counts["non_grounded"]``).
"""

from __future__ import annotations

import csv
import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.physics.projection import ProjectionConfig

# Morph's imitation selection threshold (Sec. 4: 0.5 m): P's own, one source of truth.
TAU: float = ProjectionConfig.tau

SYNTH_INFO = "synth.json"
INDEX = "index.csv"
INDEX_FIELDS = ("id", "caption", "frames", "mpjpe_mean", "mpjpe_max", "success", "resets", "grounded",
                "licence_tag")  # fmt: skip
# P's help per item (shares and mean over its frames): written since these columns exist, optional to read.
HELP_FIELDS = ("residual_force", "residual_at_cap", "over_limit")
REFINED_DIR, INPUT_DIR = "new_joint_vecs", "input_joint_vecs"

Source = Literal["refined", "input"]


class SelectionError(PhysmotionError):
    """A synthetic data folder that cannot be selected from: missing, unreadable, or nothing selected."""


@dataclass(frozen=True)
class SelectedItem:
    """One synthetic motion chosen for fine-tuning.

    features_path: the (T, 263) float32 un-normalised features file of the chosen motion
    (``new_joint_vecs/<id>.npy`` for 'refined', ``input_joint_vecs/<id>.npy`` for 'input').
    """

    id: str
    features_path: Path
    caption: str
    source: Source


@dataclass
class Selection:
    """The outcome of :func:`select`.

    items: one per index row, in index order. ifr: failed refinements / grounded items (0.0 with no
    grounded item). counts: "items", "refined", "input", "grounded", "non_grounded", "failed"
    (grounded items whose refinement was rejected), "episode_failed" (grounded items that did not run to
    the end). licence_tags: the distinct licence tags of the items (plus the generator's, from synth.json).
    help: P's help on the refined items, over their frames (``HELP_FIELDS``: root residual force mean in
    body weights, share of frames at its cap, share with a joint over its torque limit); {} where the
    index does not record it.
    """

    items: list[SelectedItem] = field(default_factory=list)
    ifr: float = 0.0
    counts: dict[str, int] = field(default_factory=dict)
    licence_tags: list[str] = field(default_factory=list)
    tau: float = TAU
    help: dict[str, float] = field(default_factory=dict)

    def training_items(self) -> list[tuple[str, Path, str]]:
        """(id, features path, caption) of every selected item, for fine-tuning.

        Raises SelectionError where the selection is empty."""
        if not self.items:
            raise SelectionError("the selection is empty: the synthetic folder has no finished item")
        return [(s.id, s.features_path, s.caption) for s in self.items]


def read_synth_info(synth_dir: str | Path) -> dict:
    """The run settings of a synthetic data folder (``SYNTH/synth.json``); SelectionError if missing."""
    path = Path(synth_dir) / SYNTH_INFO
    if not path.is_file():
        raise SelectionError(f"{synth_dir} is not a synthetic data folder (no {SYNTH_INFO}); "
                             "make one with 'physmotion morph synth'")  # fmt: skip
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SelectionError(f"{path}: not readable as JSON ({exc})") from None
    if not isinstance(info, dict):
        raise SelectionError(f"{path}: not a synth.json settings object")
    return info


def read_index(synth_dir: str | Path) -> list[dict[str, str]]:
    """The finished items of a synthetic data folder (``index.csv`` rows as strings; [] if none yet).

    A row is appended only after all its files exist, so every row read here is a whole item."""
    path = Path(synth_dir) / INDEX
    if not path.exists():
        return []
    try:
        with open(path, newline="", encoding="utf-8") as f:
            reader = csv.DictReader(f)
            if reader.fieldnames is None:
                return []
            missing = set(INDEX_FIELDS) - set(reader.fieldnames)
            if missing:
                raise SelectionError(f"{path}: not a synthetic index (missing columns {sorted(missing)})")
            return [row for row in reader if row.get("id")]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SelectionError(f"{path}: not readable ({exc})") from None


def _flag(value: object) -> bool:
    return str(value).strip().lower() in ("1", "true", "yes")


def select_rows(rows: Iterable[Mapping[str, object]], synth_dir: str | Path = ".", tau: float = TAU,
                extra_tags: Iterable[str] = ()) -> Selection:  # fmt: skip
    """Morph's selection over index rows (dicts with the ``index.csv`` columns; values as strings or
    numbers). Feature paths are made under ``synth_dir``. See the module docstring for the rule."""
    if not tau > 0:
        raise SelectionError(f"tau must be a positive distance in metres, got {tau}")
    synth_dir = Path(synth_dir)
    items: list[SelectedItem] = []
    counts = dict.fromkeys(("items", "refined", "input", "grounded", "non_grounded", "failed",
                            "episode_failed"), 0)  # fmt: skip
    tags = {t for t in extra_tags if t}
    helped: list[tuple[float, list[float]]] = []  # (frames, HELP_FIELDS) of refined items that record them
    for row in rows:
        try:
            item_id, caption = str(row["id"]), str(row["caption"])
            mpjpe, success, grounded = float(row["mpjpe_mean"]), _flag(row["success"]), _flag(row["grounded"])
        except (KeyError, ValueError) as exc:
            raise SelectionError(f"index row {dict(row)} is not a synthetic item ({exc})") from None
        tag = str(row.get("licence_tag") or "")
        if tag:
            tags.add(tag)
        counts["items"] += 1
        # Sec. 3.3: the refinement is trusted where the humanoid imitated the motion (it did not fall, and
        # the MPJPE between before and after refinement stays under tau); non-grounded motions (App. B)
        # are kept as generated, since P cannot reproduce sitting on a chair it does not have.
        imitated = success and mpjpe < tau  # NaN mpjpe compares False: rejected
        if grounded:
            counts["grounded"] += 1
            counts["failed"] += not imitated
            counts["episode_failed"] += not success
        else:
            counts["non_grounded"] += 1
        source: Source = "refined" if imitated and grounded else "input"
        counts[source] += 1
        if source == "refined" and all(row.get(k) not in (None, "") for k in HELP_FIELDS):
            helped.append((float(row["frames"]), [float(row[k]) for k in HELP_FIELDS]))
        folder = REFINED_DIR if source == "refined" else INPUT_DIR
        items.append(SelectedItem(item_id, synth_dir / folder / f"{item_id}.npy", caption, source))
    ifr = counts["failed"] / counts["grounded"] if counts["grounded"] else 0.0
    help_ = {}
    if helped:
        frames = np.array([f for f, _ in helped])
        values = np.average(np.array([v for _, v in helped]), axis=0, weights=frames)
        help_ = dict(zip(HELP_FIELDS, map(float, values)))
    return Selection(items=items, ifr=ifr, counts=counts, licence_tags=sorted(tags), tau=tau, help=help_)


def select(synth_dir: str | Path, tau: float = TAU) -> Selection:
    """Morph's imitation selection over the finished items of ``synth_dir`` (index order).

    Raises SelectionError where the folder is not a synthetic data folder or has no finished item."""
    info = read_synth_info(synth_dir)
    rows = read_index(synth_dir)
    if not rows:
        raise SelectionError(f"{synth_dir} has no finished synthetic item yet; run 'physmotion morph synth'")
    return select_rows(rows, synth_dir, tau, extra_tags=info.get("licence_tags") or ())
