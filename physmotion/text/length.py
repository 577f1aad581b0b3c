"""Length from the text: how long a motion a caption asks for, predicted as MoMask does (from the text).

MoMask (Guo et al. 2024) estimates a motion's length from the caption's text embedding with a small
classifier over length bins; MDM's users give a length. ``physmotion generate`` without ``--seconds``
asks :class:`LengthPredictor`: ridge regression from the frozen MiniLM sentence vector (the project's own
text encoder, :mod:`physmotion.text.encoder`) to seconds, clipped to the model's range (2 to 9.8 s).
A ridge beat MoMask's bin classifier on our data (docs/decisions/sampling.md "the length of a motion
from its text"): the classifier put "a person jumps" with HDM05's 2 s hops, the ridge with the jumps.

Training examples (:func:`length_examples`) come from a built dataset (``physmotion data build``): one per
caption of each clip, its length the whole clip's captured length (its windows joined, frames held by
``pad_short`` left out), because the build cuts a long clip into windows of at most 196 frames while
the caption describes the whole clip; lengths are capped to the model's range.

The model is a 384-vector, a centre and a bias in ``physmotion/weights/length/model.safetensors`` (3 KB),
with its card (``README.md``, ``card.json``): ``physmotion train length`` makes it. Closed form, so the
same data give the same weights.
"""

from __future__ import annotations

import csv
import json
import re
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS, MAX_FRAMES, MIN_FRAMES
from physmotion.errors import PhysmotionError
from physmotion.paths import WEIGHTS_DIR

LENGTH_MODEL_DIR = WEIGHTS_DIR / "length"
LO_SECONDS, HI_SECONDS = MIN_FRAMES / FPS, MAX_FRAMES / FPS  # the models' range: 2 to 9.8 s
ALPHAS = (0.01, 0.03, 0.05, 0.1, 0.3, 1.0, 3.0)  # ridge strengths tried; the best on val is kept
# prompts the card reports, with the captions of the data whose lengths they are compared with
EXAMPLE_PROMPTS = {"a person jumps": r"\bjump", "a person walks forward": r"\bwalks? forward",
                   "a person squats": r"\bsquat"}
MODEL_FILE, CARD_FILE = "model.safetensors", "card.json"


@dataclass(frozen=True)
class LengthExample:
    """One caption of one clip and how long the clip is."""

    text: str
    seconds: float  # captured length, capped to LO_SECONDS..HI_SECONDS
    raw_seconds: float  # captured length of the whole clip, uncapped
    split: str
    clip: str
    licence_tag: str
    window_seconds: tuple[float, ...] = ()  # the build's windows of the clip (each at most 9.8 s)


def length_examples(root: str | Path) -> list[LengthExample]:
    """The (caption, length) examples of a built dataset: one per distinct caption of each clip (mirrored
    copies left out: same length, 'left' and 'right' swapped), in index.csv's order."""
    root = Path(root)
    index = root / "index.csv"
    if not index.is_file():
        raise PhysmotionError(f"{root}: no index.csv; give a folder built by `physmotion data build`")
    windows: dict[str, list[dict[str, str]]] = {}
    with open(index, newline="", encoding="utf-8") as f:
        for row in csv.DictReader(f):
            if row["mirrored"] == "0":
                windows.setdefault(row["clip"], []).append(row)
    examples = []
    for clip, rows in windows.items():
        padded = int(rows[0].get("padded") or 0)
        start, end = min(int(r["start"]) for r in rows), max(int(r["end"]) for r in rows)
        raw = (end - start - 1 - padded) / FPS  # joint frames -> feature frames, as the build counts
        parts = tuple((int(r["end"]) - int(r["start"]) - 1) / FPS for r in rows)
        texts = (root / "texts" / f"{rows[0]['id']}.txt").read_text(encoding="utf-8").splitlines()
        for text in dict.fromkeys(t.strip() for t in texts if t.strip()):
            examples.append(LengthExample(text, float(np.clip(raw, LO_SECONDS, HI_SECONDS)), raw, rows[0]["split"],
                                          clip, rows[0]["licence_tag"], parts))  # fmt: skip
    if not examples:
        raise PhysmotionError(f"{root}: no captioned clip in index.csv")
    return examples


def captions_matching(examples: Sequence[LengthExample], pattern: str) -> list[LengthExample]:
    """Examples whose caption matches the regular expression ``pattern`` (case ignored): ``r"\bjump"``
    finds jumps, jumping and jump."""
    found = re.compile(pattern, re.IGNORECASE)
    return [e for e in examples if found.search(e.text)]


def _range(values) -> list[float] | None:
    values = list(values)
    return [round(min(values), 2), round(max(values), 2)] if values else None


def _encode(texts: Sequence[str], encoder: str) -> np.ndarray:
    from physmotion.text.encoder import load_text_encoder

    return load_text_encoder(encoder).encode(list(texts)).pooled.numpy().astype(np.float64)


@dataclass
class LengthPredictor:
    """seconds = clip(bias + (v - centre) . weights, 2, 9.8) for the caption's sentence vector v."""

    weights: np.ndarray  # (D,)
    centre: np.ndarray  # (D,) mean sentence vector of the training captions
    bias: float  # mean length of the training captions, s
    encoder: str = "minilm"
    lo: float = LO_SECONDS
    hi: float = HI_SECONDS

    def predict_vectors(self, vectors: np.ndarray) -> np.ndarray:
        return np.clip(self.bias + (vectors - self.centre) @ self.weights, self.lo, self.hi)

    def predict(self, texts: Sequence[str]) -> np.ndarray:
        """Seconds per caption (float64), within ``lo``..``hi``. An empty caption is an error."""
        return self.predict_vectors(_encode([t.strip() for t in texts], self.encoder))

    def save(self, folder: str | Path) -> None:
        from safetensors.numpy import save_file

        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        tensors = {"weights": self.weights.astype(np.float32), "centre": self.centre.astype(np.float32),
                   "bias": np.array([self.bias], np.float32)}  # fmt: skip
        save_file(tensors, str(folder / MODEL_FILE),
                  metadata={"encoder": self.encoder, "lo": f"{self.lo:g}", "hi": f"{self.hi:g}"})

    @classmethod
    def load(cls, folder: str | Path | None = None) -> LengthPredictor:
        """The length model in ``folder`` (default: the shipped ``physmotion/weights/length``)."""
        from safetensors import safe_open

        path = Path(folder or LENGTH_MODEL_DIR) / MODEL_FILE
        if not path.is_file():
            raise PhysmotionError(f"{path}: no length model; give --seconds, or train one with "
                                  "`physmotion train length`")  # fmt: skip
        with safe_open(str(path), framework="numpy") as f:
            meta = f.metadata() or {}
            t = {k: f.get_tensor(k).astype(np.float64) for k in f.keys()}  # noqa: SIM118 - not a dict
        return cls(t["weights"], t["centre"], float(t["bias"][0]), meta.get("encoder", "minilm"),
                   float(meta.get("lo", LO_SECONDS)), float(meta.get("hi", HI_SECONDS)))  # fmt: skip


_LOADED: dict[str, LengthPredictor] = {}


def predict_seconds(texts: Sequence[str], folder: str | Path | None = None) -> list[float]:
    """Seconds per caption from the shipped (or ``folder``'s) length model, loaded once per process."""
    key = str(folder or LENGTH_MODEL_DIR)
    if key not in _LOADED:
        _LOADED[key] = LengthPredictor.load(folder)
    return [float(s) for s in _LOADED[key].predict(texts)]


def fit_ridge(vectors: np.ndarray, seconds: np.ndarray, alpha: float, encoder: str = "minilm") -> LengthPredictor:
    """Ridge regression of seconds on centred sentence vectors (closed form: deterministic)."""
    centre, bias = vectors.mean(0), float(seconds.mean())
    x = vectors - centre
    weights = np.linalg.solve(x.T @ x + alpha * np.eye(x.shape[1]), x.T @ (seconds - bias))
    return LengthPredictor(weights, centre, bias, encoder)


def _mae(pred: np.ndarray | float, y: np.ndarray) -> float:
    return round(float(np.mean(np.abs(pred - y))), 3) if len(y) else float("nan")


@dataclass
class LengthReport:
    """What training found: val MAE per ridge strength, the strength kept, test MAE of the shipped model
    and of the two constant baselines (6 s, the old default; the train captions' mean), in seconds; and
    the same on a split by caption (``caption_split``, :class:`CaptionSplitReport`)."""

    examples: dict[str, int]
    alpha: float
    val_mae: dict[str, float]  # alpha -> MAE on val (fit on train)
    test_mae: float
    test_mae_const6: float
    test_mae_mean: float
    val_mae_const6: float
    val_mae_mean: float
    train_mean: float
    test_captions_seen: int = 0  # test examples whose caption train or val has too
    prompts: dict[str, dict] = field(default_factory=dict)  # example prompt -> seconds and the data's range
    caption_split: dict = field(default_factory=dict)  # CaptionSplitReport's fields


SPLITS = ("train", "val", "test")
CAPTION_SPLIT_SHARES = (0.8, 0.1, 0.1)  # the build's own split ratios (BuildConfig.split_ratios)
CAPTION_SPLIT_SEED = 0


def caption_groups(examples: Sequence[LengthExample]) -> list[int]:
    """A group number per example (0, 1, ... in order of first appearance): examples that share a caption
    or a clip are in one group, transitively (the connected parts of the caption-clip graph). HDM05 gives
    one caption to every clip of a class, and every clip has two captions, so a split by caption alone
    would still put a clip's other caption on the other side."""
    parent: dict[tuple[str, str], tuple[str, str]] = {}

    def root(node: tuple[str, str]) -> tuple[str, str]:
        parent.setdefault(node, node)
        while parent[node] != node:
            parent[node] = parent[parent[node]]
            node = parent[node]
        return node

    for e in examples:
        parent[root(("caption", e.text))] = root(("clip", e.clip))
    numbers: dict[tuple[str, str], int] = {}
    return [numbers.setdefault(root(("caption", e.text)), len(numbers)) for e in examples]


def caption_split(examples: Sequence[LengthExample], shares: Sequence[float] = CAPTION_SPLIT_SHARES,
                  seed: int = CAPTION_SPLIT_SEED) -> list[str]:  # fmt: skip
    """A split name ("train", "val", "test") per example such that no caption and no clip is on two sides
    (whole :func:`caption_groups` move together). The groups are taken in a seeded random order, each to
    the split furthest below its share of the examples (ties: train, val, test), so the sides come close
    to ``shares`` however large a group is."""
    groups = caption_groups(examples)
    sizes = np.bincount(groups, minlength=max(groups, default=-1) + 1)
    counts = dict.fromkeys(SPLITS, 0)
    side: dict[int, str] = {}
    for g in np.random.default_rng(seed).permutation(len(sizes)):
        chosen = min(SPLITS, key=lambda s: counts[s] / shares[SPLITS.index(s)])
        side[int(g)] = chosen
        counts[chosen] += int(sizes[g])
    return [side[g] for g in groups]


def _xy(examples: Sequence[LengthExample], splits: Sequence[str], vec: dict[str, np.ndarray],
        wanted: tuple[str, ...]) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Sentence vectors (N, D) and seconds (N,) of the examples whose split (``splits``, one per example)
    is in ``wanted``."""
    chosen = [e for e, s in zip(examples, splits) if s in wanted]
    dim = len(next(iter(vec.values())))
    x = np.stack([vec[e.text] for e in chosen]) if chosen else np.zeros((0, dim))
    return x, np.array([e.seconds for e in chosen])


def _select_and_fit(examples: Sequence[LengthExample], splits: Sequence[str], vec: dict[str, np.ndarray],
                    alphas: Sequence[float], encoder: str) -> tuple[LengthPredictor, float, dict[str, float]]:
    """The ridge strength with the lowest val MAE when fit on train, and the model fit on train + val with
    it; with the val MAE per strength. No val: the first strength."""
    (xt, yt), (xv, yv) = _xy(examples, splits, vec, ("train",)), _xy(examples, splits, vec, ("val",))
    val = {f"{a:g}": _mae(fit_ridge(xt, yt, a, encoder).predict_vectors(xv), yv) for a in alphas}
    alpha = float(min(alphas, key=lambda a: val[f"{a:g}"])) if len(yv) else float(alphas[0])
    return fit_ridge(*_xy(examples, splits, vec, ("train", "val")), alpha, encoder), alpha, val


@dataclass
class CaptionSplitReport:
    """The length model on a split by caption (:func:`caption_split`): no test caption or clip is in
    train or val. ``refit_*``: the same training (strength on val, fit on train + val) on that split's
    sides; ``model_test_mae``: the model given (the shipped one, fit on the build's train + val) on its
    test side, of whose captions it was fit on ``test_captions_seen`` (of ``examples["test"]``). Seconds."""

    seed: int
    examples: dict[str, int]
    groups: dict[str, int]
    refit_alpha: float
    refit_val_mae: dict[str, float]
    refit_test_mae: float
    test_mae_const6: float
    test_mae_mean: float  # the constant: mean length of this split's train examples
    model_test_mae: float
    test_captions_seen: int  # test examples whose caption the model was fit on (the build's train + val)


def caption_split_report(examples: Sequence[LengthExample], vec: dict[str, np.ndarray],
                         model: LengthPredictor, alphas: Sequence[float] = ALPHAS,
                         seed: int = CAPTION_SPLIT_SEED,
                         encoder: str = "minilm") -> CaptionSplitReport:  # fmt: skip
    """Measure the length model on the caption split of ``examples`` (``vec``: caption -> sentence vector):
    a model refit on its train + val, and ``model`` as it is. Raises where the split has no train side."""
    splits = caption_split(examples, seed=seed)
    if "train" not in splits:
        raise PhysmotionError("no captioned clip in the caption split's train side")
    refit, alpha, val = _select_and_fit(examples, splits, vec, alphas, encoder)
    (_, yt), (xs, ys) = _xy(examples, splits, vec, ("train",)), _xy(examples, splits, vec, ("test",))
    fit_on = {e.text for e in examples if e.split in ("train", "val")}
    groups = caption_groups(examples)
    return CaptionSplitReport(
        seed=seed, examples={s: splits.count(s) for s in SPLITS},
        groups={s: len({g for g, t in zip(groups, splits) if t == s}) for s in SPLITS},
        refit_alpha=alpha, refit_val_mae=val, refit_test_mae=_mae(refit.predict_vectors(xs), ys),
        test_mae_const6=_mae(6.0, ys), test_mae_mean=_mae(float(yt.mean()), ys),
        model_test_mae=_mae(model.predict_vectors(xs), ys),
        test_captions_seen=sum(e.text in fit_on for e, s in zip(examples, splits) if s == "test"),
    )  # fmt: skip


def encode_examples(examples: Sequence[LengthExample], encoder: str = "minilm") -> dict[str, np.ndarray]:
    """caption -> its sentence vector (D,), each distinct caption encoded once."""
    texts = sorted({e.text for e in examples})
    return dict(zip(texts, _encode(texts, encoder)))


def train_length(data: str | Path, out: str | Path, alphas: Sequence[float] = ALPHAS,
                 encoder: str = "minilm") -> LengthReport:  # fmt: skip
    """Fit the length model on ``data``'s captions and write it with its card to ``out``.

    The ridge strength is the one with the lowest MAE on val (fit on train); the model written is fit on
    train + val with it, and measured on test, which nothing else saw. The build's splits keep a clip on
    one side but not a caption (HDM05 gives a class one caption), so the card also gives the figures of a
    split by caption (:func:`caption_split_report`)."""
    data = Path(data)
    examples = length_examples(data)
    vec = encode_examples(examples, encoder)
    splits = [e.split for e in examples]
    (_, yt), (_, yv), (xs, ys) = (_xy(examples, splits, vec, (s,)) for s in SPLITS)
    if not len(yt):
        raise PhysmotionError(f"{data}: no captioned clip in the train split")
    model, alpha, val = _select_and_fit(examples, splits, vec, alphas, encoder)
    prompts = {}
    for prompt, pattern in EXAMPLE_PROMPTS.items():
        match = captions_matching(examples, pattern)
        prompts[prompt] = {"seconds": round(float(model.predict([prompt])[0]), 2), "captions": pattern,
                           "clips": len({e.clip for e in match}), "range_capped": _range(e.seconds for e in match),
                           "range_raw": _range(e.raw_seconds for e in match),
                           "range_windows": _range(w for e in match for w in e.window_seconds)}  # fmt: skip
    report = LengthReport(
        examples={s: int(sum(e.split == s for e in examples)) for s in SPLITS},
        alpha=alpha, val_mae=val, test_mae=_mae(model.predict_vectors(xs), ys),
        test_mae_const6=_mae(6.0, ys), test_mae_mean=_mae(float(yt.mean()), ys),
        val_mae_const6=_mae(6.0, yv), val_mae_mean=_mae(float(yt.mean()), yv),
        train_mean=round(float(yt.mean()), 3), prompts=prompts,
        test_captions_seen=sum(e.text in {t.text for t in examples if t.split != "test"}
                               for e in examples if e.split == "test"),
        caption_split=asdict(caption_split_report(examples, vec, model, alphas, encoder=encoder)),
    )  # fmt: skip
    out = Path(out)
    model.save(out)
    _write_card(out, data, examples, report)
    return report


def _write_card(out: Path, data: Path, examples: list[LengthExample], report: LengthReport) -> None:
    info_file = data / "build_info.json"
    info = json.loads(info_file.read_text()) if info_file.is_file() else {}
    sources = info.get("source", str(data))
    tags = sorted({t for e in examples for t in e.licence_tag.split(",") if t and t != "open"})
    card = {
        "what": "physmotion length model: seconds of motion a caption asks for (ridge regression on the "
                "MiniLM sentence vector, clipped to 2-9.8 s); used by `generate` without --seconds",
        "data": {"sources": sources if isinstance(sources, list) else [sources],
                 "examples": report.examples, "clips": len({e.clip for e in examples}),
                 "length": "whole clip's captured length (windows joined, padding left out), capped to 2-9.8 s"},
        "licence_tags": tags,
        "encoder": "minilm",
        "report": asdict(report),
    }  # fmt: skip
    (out / CARD_FILE).write_text(json.dumps(card, indent=2) + "\n", encoding="utf-8")
    rows = "\n".join(f"| {p} | {v['seconds']:.2f} | `{v['captions']}` ({v['clips']} clips) | {_span(v['range_raw'])} | "
                     f"{_span(v['range_capped'])} | {_span(v['range_windows'])} |" for p, v in report.prompts.items())
    terms = []
    if "NC" in tags:
        terms.append("**non-commercial use** (`NC`: Bandai Namco's motions, CC BY-NC 4.0)")
    if "SA" in tags:
        terms.append("HDM05's **share-alike** terms (`SA`: CC BY-SA 3.0)")
    build = " ".join(f"--source {s}" for s in card["data"]["sources"])
    cs = report.caption_split
    n = cs["examples"]
    lines = [
        "# The length model (`physmotion/weights/length`)",
        "",
        "What `physmotion generate` asks for each prompt's length when `--seconds` is not given (as MoMask",
        "predicts a length from the text): ridge regression from the frozen MiniLM sentence vector (384-d, the",
        "project's text encoder) to seconds, clipped to the models' range of 2 to 9.8 s. `model.safetensors`",
        "holds the weight vector, the training captions' mean vector and their mean length; `card.json` has the",
        "figures below. Made by `physmotion/text/length.py`, closed form (the same build gives the same weights):",
        "",
        f"    physmotion data build {build} -o BUILD",
        "    physmotion train length --data BUILD -o physmotion/weights/length --overwrite",
        "",
        (f"- **Data**: the captions of {card['data']['clips']} clips of that build: {report.examples['train']} "
         f"train, {report.examples['val']} val and {report.examples['test']} test examples, one per distinct "
         "caption of a clip (mirrored copies left out). A clip's length is its whole captured length (the "
         "build's windows of at most 9.8 s joined, frames held at the ends of a short clip left out), capped "
         "to 2-9.8 s."),
        (f"- **Licence**: it saw data tagged {', '.join(f'`{t}`' for t in tags) or 'with no restriction'}, so "
         f"it carries {' and '.join(terms) or 'no restriction'}."),
        (f"- **Training**: ridge strength {report.alpha:g}, the lowest MAE on val when fit on train (tried "
         f"{', '.join(report.val_mae)}), then fit on train + val; test is measured only."),
        (f"- **Unseen captions**: the build's splits keep a clip on one side, not a caption (HDM05 gives "
         f"every clip of a class one caption): {report.test_captions_seen} of the {report.examples['test']} "
         "test examples have a caption that train or val has. The second table splits by caption instead "
         f"(seed {cs['seed']}; examples sharing a caption or a clip stay on one side: {n['train']} train, "
         f"{n['val']} val, {n['test']} test examples): a model refit the same way on its train + val, and "
         f"this model, which saw {cs['test_captions_seen']} of those {n['test']} test captions. On captions "
         f"it has not seen the refit errs by {cs['refit_test_mae']:.2f} s (the constant mean: "
         f"{cs['test_mae_mean']:.2f} s), so the first table overstates the model on new wordings."),
        "",
        "| test split (caption examples) | MAE, s |",
        "|---|---|",
        f"| this model | {report.test_mae:.2f} |",
        f"| constant 6 s (the old default) | {report.test_mae_const6:.2f} |",
        f"| constant: train captions' mean ({report.train_mean:.2f} s) | {report.test_mae_mean:.2f} |",
        "",
        "| split by caption: test | MAE, s |",
        "|---|---|",
        f"| refit on its train + val (ridge {cs['refit_alpha']:g}) | {cs['refit_test_mae']:.2f} |",
        f"| this model (saw {cs['test_captions_seen']} of the {cs['examples']['test']} captions) | "
        f"{cs['model_test_mae']:.2f} |",
        f"| constant 6 s | {cs['test_mae_const6']:.2f} |",
        f"| constant: its train captions' mean | {cs['test_mae_mean']:.2f} |",
        "",
        "| prompt | predicted, s | captions matching | their clips, s | capped to 2-9.8 s | their windows, s |",
        "|---|---|---|---|---|---|",
        rows,
        "",
    ]
    (out / "README.md").write_text("\n".join(lines), encoding="utf-8")


def _span(pair: list[float] | None) -> str:
    return "-" if pair is None else f"{pair[0]:.2f}-{pair[1]:.2f}"
