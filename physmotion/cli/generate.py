"""``physmotion refine`` and ``generate``: the diffusion model's commands (physmotion.generate,
physmotion.pipelines.refine), with generate's checks that run before torch loads."""

from __future__ import annotations

from pathlib import Path

import typer

from physmotion.cli._common import (
    BVH_FPS_HELP,
    BVH_MAPPING_HELP,
    BVH_RIG_HELP,
    CFG_HELP,
    CONTROLLER_HELP,
    ETA_HELP,
    MODEL_HELP,
    OVERWRITE_HELP,
    POLICY_HELP,
    PREVIEW_HELP,
    RECOVER_HELP,
    SAMPLER_HELP,
    SAMPLER_OPTIONS,
    RESCUE_HELP,
    SEARCH_FALLBACK_HELP,
    _as_options,
    _check_out,
    _check_preview,
    _check_sampler_options,
    _model_dir,
    _opt_str,
    _step_bar,
    _warn,
    _with,
    app,
    console,
)
from physmotion.conventions import FPS, MAX_FRAMES, MAX_TEXT_TOKENS, MIN_FRAMES
from physmotion.errors import PhysmotionError
from physmotion.paths import DEFAULT_MODEL, MOTION_SUFFIXES, WEIGHTS_DIR

@app.command("refine")
def refine_cmd(
    path: Path = typer.Argument(..., help="A motion .npz or .bvh (e.g. a pose estimator's output)."),
    out: Path = typer.Option(..., "-o", "--out", help="Output motion .npz or .bvh (20 fps), with a GIF "
                             "preview of input and output side by side beside it (<stem>.gif)."),
    strength: float = typer.Option(0.3, help="Share of the diffusion steps to invert, in [0, 1] (0 returns "
                                   "the input on the dataset's skeleton)."),
    text: str = typer.Option("", help="Caption to condition on (default: none)."),
    model_dir: Path | None = typer.Option(None, "--model", help=MODEL_HELP),
    steps: int = typer.Option(50, help="DDIM steps of the full schedule."),
    phys_scale: float | None = typer.Option(None, help="BioMoDiffuse models only: physics guidance weight "
                                            "(default: 1)."),
    smooth_hz: float = typer.Option(4.0, help="Low-pass the input at this cut-off (Hz) before inversion and "
                                    "fuse the result with it; 0: the paper's plain inversion."),
    anchor_hz: float = typer.Option(1.0, help="Plain inversion only: heading and root path slower than this "
                                    "(Hz) follow the input; 0: one yaw + shift for the whole clip."),
    rig: str | None = typer.Option(None, help=BVH_RIG_HELP),
    fps: float | None = typer.Option(None, help=BVH_FPS_HELP),
    mapping: Path | None = typer.Option(None, help=BVH_MAPPING_HELP),
    preview: bool = typer.Option(True, help=PREVIEW_HELP),
    overwrite: bool = typer.Option(False, "--overwrite", help=OVERWRITE_HELP),
) -> None:
    """Refine a motion by DDIM inversion and denoising (BioMoDiffuse Sec. 3.5; physics guidance with a
    BioMoDiffuse model)."""
    from physmotion.diffusion.model import MotionDiffusion
    from physmotion.diffusion.refine import RefineConfig
    from physmotion.motion import Motion
    from physmotion.pipelines.refine import RefinePipeline

    config = RefineConfig(strength=strength, steps=steps, text=text, phys_scale=phys_scale,
                          smooth_hz=smooth_hz or None, anchor_hz=anchor_hz or None)
    with _as_options(strength="--strength", steps="--steps", phys_scale="--phys-scale", smooth_hz="--smooth-hz",
                     anchor_hz="--anchor-hz"):  # fmt: skip
        config.check()
    if not path.is_file():
        raise PhysmotionError(f"{path}: no such file")
    if path.suffix.lower() not in (".npz", ".bvh"):
        raise PhysmotionError(f"{path}: refine reads .npz or .bvh")
    _check_out(out, overwrite, MOTION_SUFFIXES)
    _check_preview(out, overwrite)
    if path.suffix.lower() == ".bvh":
        from physmotion.io.importer import import_clip

        motion = import_clip(path, rig=rig, fps=fps, mapping=mapping)
    else:
        motion = Motion.load(path)
    pipeline = RefinePipeline(MotionDiffusion.load(_model_dir(model_dir)), config)
    pipeline.check(motion)  # length and NaN before the work
    refined = pipeline(motion).motion
    from physmotion.render import save_with_preview

    files = save_with_preview(refined, out, preview, before=motion, title=text)
    console.print(f"wrote {' and '.join(map(str, files))}: {len(refined.joints)} frames, strength {strength:g}",
                  highlight=False)  # fmt: skip


@app.command("generate")
def generate_cmd(
    texts: list[str] | None = typer.Argument(
        None, show_default=False, help="One or more captions, e.g. \"a person walks forward\" (or --prompts FILE). "
        "The text encoder reads the first "
        f"{MAX_TEXT_TOKENS} tokens of each (special tokens included): a longer caption is cut there, with "
        "a warning. Words the model never saw in its training captions get a warning too (only for a "
        "model folder with a vocabulary.txt, as the shipped model has)."),
    out: Path = typer.Option(Path("out"), "-o", "--out", help="Output folder: each motion becomes "
                             "<caption>_s<seed>_<k>.npz, .bvh and .gif (k: sample of that caption), and "
                             "the run is appended to generate.json there. A new folder named like a file (foo.npz, foo.gif) is "
                             "refused."),
    prompts: Path | None = typer.Option(
        None, "--prompts", help="A UTF-8 file of prompts, one a line, generated in one batch by one process: "
        "'a person jumps | 3.5' (or a tab before the number) gives that motion's seconds; blank lines and "
        "lines starting with # are skipped. A line without seconds takes --seconds, or its length is "
        "predicted from its text; --seconds, when given, applies to every line."),
    seconds: float | None = typer.Option(
        None, help=f"Length of each motion in seconds, {MIN_FRAMES / FPS:g} to {MAX_FRAMES / FPS:g} (the "
        "model's range: another model may allow less); left out, each prompt's length is predicted from its "
        "text by the length model (physmotion/weights/length), printed and recorded in generate.json "
        "(default: predicted from the text)."),
    physics: str | None = typer.Option(
        None, help="none, none+floor (plain sampling, shifted onto the floor as well as a constant "
        "shift can), post[:K] (K projections after sampling), physdiff[:SCHEDULE] (projection "
        "inside sampling; SCHEDULE uniform:N, start:M,end:N or end:N,space:S, and ,fly:last to project a "
        "motion that flies at the last of those steps only) or morph (one projection after sampling that "
        "keeps the sampled motion where the humanoid fails to imitate it, Morph's inference) "
        "(default: physdiff:end:2,space:1,fly:last)."),
    num: int | None = typer.Option(None, help="Samples per caption (default: 1)."),
    seed: int | None = typer.Option(None, help="Random seed; the same seed gives the same motions (default: 0)."),
    sampler: str | None = typer.Option(None, help=SAMPLER_HELP),
    steps: int | None = typer.Option(None, help="Sampling steps (default: 10)."),
    eta: float | None = typer.Option(None, help=ETA_HELP),
    cfg_scale: float | None = typer.Option(None, help=CFG_HELP),
    phys_scale: float | None = typer.Option(None, help="BioMoDiffuse models only: physics guidance weight, "
                                            "0 = without the physical network (default: 1)."),
    speed: float | None = typer.Option(None, help="BioMoDiffuse models only: speed control signal, scales "
                                       "the physical network's accelerations (default: 1)."),
    model: Path | None = typer.Option(None, help=MODEL_HELP),
    fine_step: bool = typer.Option(False, "--fine-step", help="Simulate the projection at 1/720 s instead "
                                   "of 1/360 s: PhysDiff on unseen prompts 12.5 -> 11.2 mm Phys-Err, for "
                                   "1.3-1.4x PhysDiff's time (experiments/generate_speed.py)."),
    controller: str = typer.Option("tracker", help=CONTROLLER_HELP),
    policy: Path | None = typer.Option(None, help=POLICY_HELP),
    search_fallback: bool = typer.Option(False, "--search-fallback", help=SEARCH_FALLBACK_HELP),
    recover: bool | None = typer.Option(None, "--recover/--no-recover", help=RECOVER_HELP),
    rescue_flights: bool = typer.Option(False, "--rescue-flights", help=RESCUE_HELP),
    preview: bool = typer.Option(True, help="Write a GIF preview per motion."),
    in_place: bool = typer.Option(False, "--in-place", help="Remove the root's horizontal travel (heading "
                                  "and height kept), for game loops."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace files of the same names instead of "
                                   "refusing (with --no-preview, an old GIF of the same name is removed)."),
) -> None:
    """Generate motions from text: .npz, .bvh and a GIF preview per sample.

    Unset options take GenerateConfig's and the model's sampler defaults (the values the help quotes)."""
    prompt_file = None
    if prompts is not None:
        if texts:
            raise PhysmotionError("give prompts as arguments or in --prompts FILE, not both")
        from physmotion.text.prompts import read_prompts

        prompt_file = read_prompts(prompts)
        texts = [p.text for p in prompt_file]
    elif not texts:
        raise PhysmotionError("give a prompt, e.g. physmotion generate \"a person walks forward\", or --prompts FILE")
    model = _model_dir(model)
    _check_generate_early(texts, model, prompt_file, prompts, seconds=seconds, num=num, physics=physics,
                          sampler=sampler, steps=steps, eta=eta, cfg_scale=cfg_scale, phys_scale=phys_scale,
                          speed=speed)  # fmt: skip
    from physmotion.diffusion.model import DEFAULT_MODEL_DIR, MotionDiffusion
    from physmotion.diffusion.samplers import default_sampler
    from physmotion.generate import (
        GenerateConfig,
        check_outputs,
        check_request,
        chosen_lengths,
        generate,
        long_prompts,
        physics_summary,  # fmt: skip
        unknown_prompt_words,
        write_outputs,
    )

    cfg = _with(GenerateConfig(), num=num, physics=physics, seed=seed)
    cfg.in_place = in_place
    cfg.seconds = seconds  # None: each prompt's length predicted from its text
    cfg = cfg.at_fine_step() if fine_step else cfg
    cfg = cfg.with_controller(controller, _opt_str(policy))
    if search_fallback:
        cfg = cfg.with_search_fallback(True)
    if recover is not None:
        cfg = cfg.with_search_recovery(recover)
    if rescue_flights:
        cfg = cfg.with_flight_rescue(True)
    check_outputs(texts, out, cfg, overwrite)
    net = MotionDiffusion.load(model)
    cfg.sampler = _with(default_sampler(net), sampler=sampler, steps=steps, eta=eta, cfg_scale=cfg_scale,
                        phys_scale=phys_scale, speed=speed)  # fmt: skip
    cfg.sampler.check_model(net)
    with _as_options(**SAMPLER_OPTIONS):
        check_request(texts, cfg, net)
    for text, tokens in long_prompts(texts, net).items():
        _warn(f"{_quote(text)} is {tokens} tokens long; the text encoder reads only the first "
              f"{MAX_TEXT_TOKENS}, the rest is ignored")  # fmt: skip
    unknown = unknown_prompt_words(texts, model or DEFAULT_MODEL_DIR)
    for text, words in unknown.items():
        where = f" (in {_quote(text)})" if len(texts) > 1 else ""
        _warn(f"the model never saw {', '.join(repr(w) for w in words)} in training{where}; "
              "expect a generic motion")  # fmt: skip
    lengths = sources = None
    own = [p for p in prompt_file or () if p.seconds is not None]
    if own and seconds is not None:
        _warn(f"--seconds {seconds:g} applies to every prompt, also to the {len(own)} line(s) of {prompts} that "
              "give their own seconds")  # fmt: skip
    elif own:  # each line's own seconds; the others predicted from their text
        rest = [p.text for p in prompt_file if p.seconds is None]
        predicted = iter(chosen_lengths(rest, cfg, net)) if rest else iter(())
        chosen = [(round(p.seconds * FPS), "given") if p.seconds is not None else next(predicted) for p in prompt_file]
        lengths, sources = [n for n, _ in chosen], [s for _, s in chosen]
    if seconds is None:
        chosen = zip(lengths, sources) if lengths is not None else chosen_lengths(texts, cfg, net)
        for text, (frames, source) in dict(zip(texts, chosen)).items():
            if source == "predicted":
                console.print(f"length: {frames / FPS:.2f} s for {_quote(text)} (predicted from the text; "
                              "--seconds sets it)", highlight=False)  # fmt: skip
    with _step_bar("generating") as tick:
        result = generate(texts, cfg, net, on_step=tick, lengths=lengths, length_source=sources)
    paths = write_outputs(result, out, cfg, preview=preview, overwrite=overwrite, model=model,
                          unknown=unknown)
    console.print(f"wrote {len(result.motions)} motion(s) to {out} ({len(paths)} files, run logged in "
                  f"generate.json)", highlight=False)  # fmt: skip
    phys = physics_summary(result)
    if phys:
        console.print(f"physics: {phys}", highlight=False)


def _check_generate_early(texts, model, prompt_file, prompts, *, seconds, num, physics, sampler, steps, eta,
                          cfg_scale, phys_scale, speed) -> None:
    """generate's argument checks that need neither torch nor the model's weights (its config.json only),
    so that a mistake is told in a fraction of a second. The same checks run again, with the loaded
    model, in check_request and SamplerConfig.check: this only finds errors sooner, with the same words."""
    import json
    import math

    from physmotion.pipelines.modes import PhysicsMode

    if any(not t.strip() for t in texts):
        raise PhysmotionError("text is empty: describe a motion, e.g. 'a person walks forward'")
    mode = PhysicsMode.parse(physics) if physics is not None else None
    if sampler is not None:
        from physmotion.diffusion.schedule import SAMPLERS

        if sampler not in SAMPLERS:
            raise PhysmotionError(f"unknown sampler {sampler!r}: choose one of {', '.join(SAMPLERS)}")
    _check_sampler_options(steps=steps, eta=eta, cfg_scale=cfg_scale)
    if steps is not None and mode is not None:
        mode.hook_steps(steps)
    if phys_scale is not None and not (math.isfinite(phys_scale) and phys_scale >= 0):
        raise PhysmotionError(f"--phys-scale must be a number >= 0, got {phys_scale}")
    if speed is not None and not (math.isfinite(speed) and 0.0 < speed <= 4.0):
        raise PhysmotionError(f"--speed must be in (0, 4], got {speed}")
    if num is not None and not 1 <= num <= 256:
        raise PhysmotionError(f"--num must be between 1 and 256, got {num}")
    try:
        config = json.loads(((model or WEIGHTS_DIR / DEFAULT_MODEL) / "config.json").read_text(encoding="utf-8"))
        den = config["denoiser"]
        max_frames, arch = int(den.get("max_frames", MAX_FRAMES)), den.get("arch", "transformer")
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return  # loading the model names what is wrong with it
    lo, hi = MIN_FRAMES / FPS, max_frames / FPS
    if seconds is not None and (not math.isfinite(seconds) or not lo <= seconds <= hi):
        raise PhysmotionError(f"--seconds must be between {lo:g} and {hi:g} (the model's range), got {seconds:g}")
    if prompt_file is not None and seconds is None:
        from physmotion.text.prompts import check_seconds

        check_seconds(prompt_file, lo, hi, str(prompts))
    if arch != "biomo" and (phys_scale is not None or (speed is not None and speed != 1.0)):
        raise PhysmotionError(f"--phys-scale and --speed need a BioMoDiffuse model (arch biomo); this one is a {arch}")


def _quote(text: str, limit: int = 40) -> str:
    """A prompt for a one-line message: quoted, cut to ``limit`` characters."""
    return repr(text if len(text) <= limit else text[: limit - 3] + "...")
