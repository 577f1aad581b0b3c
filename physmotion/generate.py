"""Text in, physically plausible motion out: the product's main job, behind ``physmotion generate``.

This module checks a request, chooses each motion's length, hands the work to the pipeline of
``GenerateConfig.physics`` (:func:`pipeline_for`; the methods live in :mod:`physmotion.pipelines`) and
writes the files. The modes: ``none``, ``none+floor``, ``post[:K]``, ``physdiff[:SCHEDULE]`` (the default,
the last 2 of the default sampler's 10 DPM-Solver++ steps, a motion that flies the last only,
``end:2,space:1,fly:last``) or ``morph``.

P in generation is :meth:`ProjectionConfig.sampling`: where the humanoid falls (its error passes 0.15 m)
it is put back on the motion and the simulation goes on (reset-on-fail), so the output is always the
simulation and never the kinematic input. The output is cross-faded onto the motion over the moments
before each reset (``ProjectionConfig.crossfade``), so nothing jumps; those frames are not simulated and
are marked (``Motion.reset_frames``). Every reset of every call of P is counted (``GenerateResult.resets``,
``generate.json``). ``morph`` uses ``GenerateConfig.morph_projection``
(:class:`ProjectionConfig`'s defaults: no reset, tau 0.5 m) with Morph's imitation selection
(``GenerateResult.imitation_failed``; ``imitation_failure_rate`` in ``generate.json`` and the tables).
"""

from __future__ import annotations

import json
import re
import sys
import time
import unicodedata
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from physmotion.conventions import FPS, MIN_FRAMES
from physmotion.diffusion.model import MotionDiffusion
from physmotion.diffusion.physdiff import projection_settings
from physmotion.diffusion.samplers import SamplerConfig
from physmotion.errors import PhysmotionError
from physmotion.metrics.report import help_words, pooled_help
from physmotion.motion import write_atomic
from physmotion.paths import DEFAULT_MODEL
from physmotion.physics.projection import ProjectionConfig
from physmotion.pipelines.base import Pipeline
from physmotion.pipelines.modes import FLOOR, MORPH, NONE, PHYSDIFF, POST, PhysicsMode
from physmotion.pipelines.result import GenerateResult

GENERATE_LOG = "generate.json"


@dataclass
class GenerateConfig:
    """Options of one generation run; ``physics`` also takes a spelling such as ``"post:4"``."""

    seconds: float | None = 6.0  # None: each prompt's length predicted from its text (physmotion/text/length.py)
    num: int = 1  # samples per text
    physics: PhysicsMode = field(default_factory=PhysicsMode)
    sampler: SamplerConfig = field(default_factory=SamplerConfig)
    seed: int = 0
    in_place: bool = False  # remove the root's horizontal travel (physmotion.io.in_place; generate --in-place)
    projection: ProjectionConfig = field(default_factory=ProjectionConfig.sampling)  # P for physdiff and post
    morph_projection: ProjectionConfig = field(default_factory=ProjectionConfig)  # P with Morph's selection

    def __post_init__(self) -> None:
        self.physics = PhysicsMode.parse(self.physics)

    def at_fine_step(self) -> GenerateConfig:
        """This run with every P (``post``, ``physdiff``, ``morph``) at half the simulation step
        (:meth:`ProjectionConfig.at_fine_step`; ``generate --fine-step``)."""
        return replace(self, projection=self.projection.at_fine_step(),
                       morph_projection=self.morph_projection.at_fine_step())  # fmt: skip

    def with_search_fallback(self, on: bool) -> GenerateConfig:
        """This run with the search as the tracker's fallback in PhysDiff's and post's P, or without it
        (``ProjectionConfig.fallback``; ``generate --search-fallback``)."""
        if on and self.projection.controller == "search":
            raise PhysmotionError("--search-fallback is for the tracker and the policy; --controller search "
                                  "searches every motion already")
        return replace(self, projection=replace(self.projection, fallback=on))

    def with_search_recovery(self, on: bool) -> GenerateConfig:
        """This run with PhysDiff's and post's P handing a fall to the search before resetting the body, or
        resetting it at once (``ProjectionConfig.recover``; ``generate --recover/--no-recover``)."""
        if on and self.projection.controller == "search":
            raise PhysmotionError("--recover is for the tracker and the policy; --controller search has no "
                                  "outside hand to fall from")
        return replace(self, projection=replace(self.projection, recover=on))

    def with_flight_rescue(self, on: bool) -> GenerateConfig:
        """This run with PhysDiff's and post's P handing a take-off whose flight the body kept under 0.8 of
        the motion's to the search, or not (``ProjectionConfig.rescue_flight``;
        ``generate --rescue-flights``)."""
        if on and self.projection.controller == "search":
            raise PhysmotionError("--rescue-flights is for the tracker and the policy; --controller search "
                                  "searches every take-off already")
        if on and not self.projection.recover:
            raise PhysmotionError("--rescue-flights hands take-offs to the search of --recover: it cannot be "
                                  "used with --no-recover")
        return replace(self, projection=replace(self.projection, rescue_flight=0.8 if on else 0.0))

    def with_controller(self, controller: str, policy: str | None = None) -> GenerateConfig:
        """This run with every P driven by ``controller`` ("tracker", "policy" or "search"; ``generate --controller``)."""
        return replace(self, projection=self.projection.with_controller(controller, policy),
                       morph_projection=self.morph_projection.with_controller(controller, policy))  # fmt: skip


def check_request(texts: Sequence[str], config: GenerateConfig, model: MotionDiffusion) -> int | None:
    """Validate the request before any work; returns the number of frames (None: predicted per text)."""
    if not texts:
        raise PhysmotionError("no text given")
    for t in texts:
        if not isinstance(t, str) or not t.strip():
            raise PhysmotionError("text is empty: describe a motion, e.g. 'a person walks forward'")
    # A prompt longer than the text encoder's token limit is not refused: the encoder reads its first
    # max_tokens tokens (see long_prompts, which the CLI warns with).
    lo, hi = MIN_FRAMES / FPS, model.denoiser.max_frames / FPS
    if config.seconds is not None and (not np.isfinite(config.seconds) or not lo <= config.seconds <= hi):
        raise PhysmotionError(f"--seconds must be between {lo:g} and {hi:g} (the model's range), got {config.seconds:g}")
    if not 1 <= config.num <= 256:
        raise PhysmotionError(f"--num must be between 1 and 256, got {config.num}")
    config.sampler.check()
    config.physics.hook_steps(config.sampler.steps)
    return None if config.seconds is None else round(config.seconds * FPS)


def chosen_lengths(texts: Sequence[str], config: GenerateConfig, model: MotionDiffusion) -> list[tuple[int, str]]:
    """Per text, (frames, "given") from ``config.seconds``, or where that is None (frames, "predicted") from
    the length model (physmotion/weights/length, as MoMask predicts a length from the text), within the
    model's range."""
    if config.seconds is not None:
        return [(round(config.seconds * FPS), "given")] * len(texts)
    from physmotion.text.length import predict_seconds

    seconds = predict_seconds([t.strip() for t in texts])
    return [(int(np.clip(round(s * FPS), MIN_FRAMES, model.denoiser.max_frames)), "predicted") for s in seconds]


def generate(
    texts: Sequence[str],
    config: GenerateConfig | None = None,
    model: MotionDiffusion | None = None,
    on_step: Callable[[int, int], None] | None = None,
    lengths: Sequence[int] | None = None,
    length_source: Sequence[str] | None = None,
) -> GenerateResult:
    """Generate ``config.num`` motions per text. Deterministic under ``config.seed``.

    lengths: frames per text (evaluation matches the test motions' lengths); default ``config.seconds``,
    or where that is None each text's length predicted from it (:func:`chosen_lengths`).
    length_source: with ``lengths``, per text "given" or "predicted" as recorded (default all "given").
    """
    cfg = config or GenerateConfig()
    model = model or MotionDiffusion.load()
    check_request(texts, cfg, model)
    sources = list(length_source) if length_source is not None and lengths is not None else ["given"] * len(texts)
    if lengths is None:
        lengths, sources = (list(z) for z in zip(*chosen_lengths(texts, cfg, model)))
    elif len(lengths) != len(texts) or not all(MIN_FRAMES // 2 <= n <= model.denoiser.max_frames for n in lengths):
        raise PhysmotionError(f"give one length per text, each {MIN_FRAMES // 2}..{model.denoiser.max_frames} frames")
    prompts = [t.strip() for t in texts for _ in range(cfg.num)]
    lengths = [int(n) for n in lengths for _ in range(cfg.num)]
    sources = [s for s in sources for _ in range(cfg.num)]
    result = pipeline_for(cfg, model)(prompts, lengths, seed=cfg.seed, on_step=on_step)
    result.length_source = sources
    if cfg.in_place:
        from physmotion.io.in_place import in_place

        result.motions = [in_place(m) for m in result.motions]
    return result


def pipeline_for(config: GenerateConfig, model: MotionDiffusion) -> Pipeline:
    """The pipeline of ``config.physics``, with the run's sampler and P's settings."""
    from physmotion.pipelines.morph import MorphPipeline
    from physmotion.pipelines.physdiff import PhysDiffPipeline, PostProjectionPipeline
    from physmotion.pipelines.plain import FloorPipeline, PlainPipeline

    mode, sampler = config.physics, config.sampler
    if mode.kind == PHYSDIFF:
        return PhysDiffPipeline(model, sampler, config.projection, schedule=mode.schedule)
    if mode.kind == POST:
        return PostProjectionPipeline(model, sampler, config.projection, projections=mode.projections)
    if mode.kind == MORPH:
        return MorphPipeline(model, sampler, config.morph_projection)
    return {NONE: PlainPipeline, FLOOR: FloorPipeline}[mode.kind](model, sampler)


def slug(text: str, limit: int = 40) -> str:
    """A file-name stem from a caption: lower case, runs of anything but letters and digits become '_'.

    Letters of any script are kept ("una persona camina" -> "una_persona_camina", "人が歩く" stays);
    only where the file-system encoding cannot spell them does the stem fall back to ASCII.
    """
    stem = _squash("".join(c if c.isalnum() else "_" for c in text.lower()), limit)
    try:
        stem.encode(sys.getfilesystemencoding())
    except UnicodeEncodeError:
        ascii_text = unicodedata.normalize("NFKD", text).encode("ascii", "ignore").decode()
        stem = _squash(re.sub(r"[^a-z0-9]", "_", ascii_text.lower()), limit)
    return stem or "motion"


def _squash(stem: str, limit: int) -> str:
    """Runs of '_' made one, and cut to ``limit`` characters at a word end where the cut is not too short."""
    stem = re.sub(r"_+", "_", stem).strip("_")
    if len(stem) > limit:
        cut = stem[: limit + 1].rfind("_")
        stem = stem[:cut] if cut >= limit // 2 else stem[:limit]
    return stem.rstrip("_")


OUTPUT_SUFFIXES = (".npz", ".bvh", ".gif")


def output_stems(texts: Sequence[str], config: GenerateConfig) -> list[str]:
    """File stems of a run, one per motion in ``generate``'s order: ``<slug>_s<seed>_<k>``.

    k counts the samples of a caption (0..num-1; a caption given twice goes on counting), so runs with
    another seed, caption or count never share a name.
    """
    counts: dict[str, int] = {}
    stems = []
    for text in texts:
        base = f"{slug(text.strip())}_s{config.seed}"
        for _ in range(config.num):
            k = counts[base] = counts.get(base, -1) + 1
            stems.append(f"{base}_{k}")
    return stems


def check_outputs(
    texts: Sequence[str], out: str | Path, config: GenerateConfig, overwrite: bool = False
) -> None:
    """Raise PhysmotionError before any work where the run could not write ``out`` or would replace a file.

    Every file the run may write (.npz, .bvh and .gif of each motion: an old GIF of the same stem is
    checked too, so none is left claiming to show a new motion) must be new unless ``overwrite``;
    ``out/generate.json`` must be absent or a run log this run can append to.
    """
    from physmotion.paths import check_output

    out = Path(out)
    check_output(out, "folder", overwrite=True)
    hint = "pass --overwrite to replace it, or use another --seed or -o"
    for stem in output_stems(texts, config):
        for suffix in OUTPUT_SUFFIXES:
            check_output(out / f"{stem}{suffix}", "file", overwrite=overwrite, hint=hint)
    _read_log(out / GENERATE_LOG)


def _read_log(path: Path) -> list[dict]:
    """The run records of an existing generate.json (a single-run file from older versions included)."""
    if not path.exists():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise PhysmotionError(f"{path}: not a generate.json run log ({exc}); move it away") from None
    if isinstance(data, dict) and isinstance(data.get("runs"), list):
        return data["runs"]
    if isinstance(data, dict):
        return [data]
    raise PhysmotionError(f"{path}: not a generate.json run log; move it away")


def long_prompts(texts: Sequence[str], model: MotionDiffusion) -> dict[str, int]:
    """Prompts longer than the text encoder reads, with their token counts: the encoder keeps the first
    ``max_tokens`` tokens of each and ignores the rest."""
    from physmotion.text.encoder import load_text_encoder

    encoder = load_text_encoder(model.text_encoder)
    counts = {t.strip(): encoder.count_tokens(t.strip()) for t in texts}
    return {t: n for t, n in counts.items() if n > encoder.max_tokens}


def unknown_prompt_words(texts: Sequence[str], model_dir: str | Path) -> dict[str, list[str]]:
    """prompt -> its words that the model's training captions never had (only prompts with some).

    Empty where the model folder has no vocabulary file: nothing is known about what it saw."""
    from physmotion.text.vocabulary import load_vocabulary, unknown_words

    vocabulary = load_vocabulary(model_dir)
    if vocabulary is None:
        return {}
    found = {t.strip(): unknown_words(t, vocabulary) for t in texts}
    return {t: w for t, w in found.items() if w}


def physics_summary(result: GenerateResult) -> str:
    """The projections' falls and resets, and the outside help P gave (the root residual, the share of
    frames at its cap, joints over their torque limit), in plain words for the end of a run ('' without
    projections)."""
    log = result.projections
    if not log.tracked:
        return ""
    pooled = pooled_help(result.motions)
    helped = f"; {help_words(*pooled)}" if pooled else ""
    searched = sum(bool(m.searched) for m in result.motions)
    if searched:  # --controller search, or the tracker's fallback where it fell or flattened a flight
        helped += (f"; the search (no outside hand) made {searched} of {len(result.motions)} motions (per motion "
                   "in generate.json: 'searched')")
    recovered = [int(m.recovered or 0) for m in result.motions]
    if any(recovered):  # ProjectionConfig.recover: the search carried the body where it would have been reset
        helped += (f"; the search (no outside hand) carried the body {sum(recovered)} time(s) where it would "
                   f"have been put back on the motion, in {sum(r > 0 for r in recovered)} of "
                   f"{len(result.motions)} motions (per motion in generate.json: 'recovered')")
    if result.imitation_failed:  # morph: a failed imitation keeps the sampled motion, nothing is reset
        n, failed = len(result.imitation_failed), int(sum(result.imitation_failed))
        return (f"the simulated humanoid imitated {n - failed} of {n} motions; "
                + (f"the other {failed} kept the sampled motion (Morph's imitation selection; imitation "
                   f"failure rate {failed / n:.2f})" if failed else "none was kept as sampled") + helped)
    falls, resets = len(log.tracked) - sum(log.tracked), sum(result.resets)
    if not falls:
        return f"the simulated humanoid followed the motion without falling in all {len(log.tracked)} " \
            f"projections{helped}"
    with_reset = sum(r > 0 for r in result.resets)
    return (f"the simulated humanoid fell in {falls} of {len(log.tracked)} projections and was put back onto "
            f"the motion {resets} time(s) in all, in {with_reset} of {len(result.motions)} motions; the output "
            "is cross-faded onto the motion over the moments before each reset, frames that are not "
            f"simulated (per motion in generate.json: 'resets', 'reset_frames'){helped}")


def _frame_list(frames: np.ndarray | None) -> list[int] | None:
    """The indices of the marked frames of a (T,) bool record, None where there is no record."""
    return None if frames is None else np.flatnonzero(frames).tolist()


def write_outputs(
    result: GenerateResult,
    out: str | Path,
    config: GenerateConfig,
    preview: bool = True,
    overwrite: bool = False,
    model: str | Path | None = None,
    unknown: dict[str, list[str]] | None = None,
) -> list[Path]:
    """Write .npz, .bvh and (optionally) a .gif preview per motion as ``<slug>_s<seed>_<k>.*``, and append
    a run record to ``generate.json``; returns the motion files written.

    Refuses (PhysmotionError) to replace any file unless ``overwrite``; without a preview, an old GIF of
    the same stem is removed. model: the model folder, recorded; unknown: prompt -> words the model
    never saw, recorded. Every file is written atomically, so an interrupted run leaves only whole files.
    """
    from physmotion.io.export import save_bvh
    from physmotion.render import save_gif

    out = Path(out)
    texts = [m.texts[0] for m in result.motions[:: config.num]]  # motions are text-major, num per text
    check_outputs(texts, out, config, overwrite)
    stems = output_stems(texts, config)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    motions = []
    for i, (motion, stem) in enumerate(zip(result.motions, stems)):
        base = out / stem
        motion.save(base.with_suffix(".npz"))
        save_bvh(motion, base.with_suffix(".bvh"))
        files = [base.with_suffix(".npz"), base.with_suffix(".bvh")]
        if preview:
            save_gif(base.with_suffix(".gif"), motion.joints, motion.fps, title=motion.texts[0],
                     not_simulated=motion.reset_frames)  # fmt: skip
            files.append(base.with_suffix(".gif"))
        else:
            base.with_suffix(".gif").unlink(missing_ok=True)  # a stale preview of another motion
        written += files
        motions.append({"prompt": motion.texts[0], "sample": int(stem.rsplit("_", 1)[1]),
                        "files": [p.name for p in files], "resets": result.resets[i] if result.projections.calls else None,
                        "reset_frames": _frame_list(motion.reset_frames),
                        "searched": motion.searched, "recovered": motion.recovered})  # fmt: skip
        if result.lengths:  # the length asked for, and whether the user gave it or the text's was predicted
            motions[-1]["seconds"] = round(result.lengths[i] / FPS, 2)
            motions[-1]["length_source"] = result.length_source[i]
        if result.imitation_failed:
            motions[-1]["imitation_failed"] = result.imitation_failed[i]
    log = result.projections
    settings = asdict(config)
    settings["physics"] = str(config.physics)
    settings["projection"] = projection_settings(config.projection)
    settings["morph_projection"] = projection_settings(config.morph_projection)
    record = {
        "time": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "prompts": texts,
        "seed": config.seed,
        "model": str(model) if model is not None else f"default (physmotion/weights/{DEFAULT_MODEL})",
        "pipeline": result.settings.get("pipeline"),  # the class that made the motions (physmotion/pipelines)
        "settings": settings,
        "preview": preview,
        "unknown_words": {t: w for t, w in (unknown or {}).items() if w},
        "licence_tag": result.motions[0].licence_tag if result.motions else "",
        "projections": {"calls": log.calls, "projected": len(log.selected), "without_fall": int(sum(log.tracked)),
                        "resets_total": int(sum(log.resets))},
        "motions": motions,
        "files": [p.name for p in written],
    }
    if result.imitation_failed:  # morph: Morph's IFR, the share of motions whose sampled input was kept
        record["projections"]["imitation_failures"] = int(sum(result.imitation_failed))
        record["projections"]["imitation_failure_rate"] = float(np.mean(result.imitation_failed))
    runs = _read_log(out / GENERATE_LOG) + [record]
    data = json.dumps({"runs": runs}, indent=2, ensure_ascii=False).encode("utf-8")
    write_atomic(out / GENERATE_LOG, lambda f: f.write(data))
    return written
