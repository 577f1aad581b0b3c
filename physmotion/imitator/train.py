"""``physmotion train imitator``: PPO (rsl-rl) on imitation episodes, in resumable chunks.

The PPO algorithm, its actor-critic models, rollout storage and observation normalisation are rsl-rl's
(``rsl-rl-lib``); the loop around them is ours, because it also samples clips toward failures, moves the
residual-cap curriculum, evaluates a fixed clip set and checkpoints at chunk boundaries.

Exact resumption: every ``chunk`` iterations all episodes restart from streams seeded by
``(seed, iteration)`` and torch is reseeded at every iteration, and checkpoints are written only at those
boundaries (network, critic, optimiser, normaliser, clip weights, curriculum, counters). A run stopped and
resumed therefore takes the same steps as one that was not, for the same clips, workers and environments
(resumed on other clips, it fine-tunes: their sampling weights start anew).

A run folder holds ``checkpoint.pt``, ``log.csv`` (one row per iteration), ``eval.csv`` (one row per
evaluation and cap), ``curves.png`` (with matplotlib) and ``policy/``: the exported policy that P loads
(``policy.safetensors`` at most a few MB, ``settings.json``, ``card.json``).

Warm start (``warm_start``): the actor starts as a policy folder's network (e.g. a student behaviour-cloned
on the search's teacher records), so that at iteration 0 its mean action is that policy's; its action scale
and tracker settings are taken; the critic starts fresh. Teacher clips (``clips.teacher_clips``) train with
no outside hand (:func:`no_hand_config`): the cap is 0 in every episode and evaluation.
"""

from __future__ import annotations

import csv
import json
import os
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import ClipSource, licence_tags
from physmotion.imitator.env import EnvConfig
from physmotion.imitator.vec_env import CapCurriculum, EpisodeEnd, VecImitationEnv
from physmotion.physics.policy import OBS_DIM, PolicySettings, settings_dict


@dataclass(frozen=True)
class ImitatorTrainConfig:
    """PPO and sampling settings (rsl-rl's names where they are rsl-rl's)."""

    env: EnvConfig = field(default_factory=EnvConfig)
    num_envs: int = 16
    workers: int = 0  # processes for the environments, 0: one per core
    num_steps_per_env: int = 32
    hidden_dims: tuple[int, ...] = (512, 256)
    init_std: float = 0.3  # of the Gaussian actions, in action units (x action_scale rad)
    learning_rate: float = 3e-4
    num_learning_epochs: int = 5
    num_mini_batches: int = 4
    gamma: float = 0.99
    lam: float = 0.95
    entropy_coef: float = 0.0
    desired_kl: float = 0.01
    chunk: int = 10  # iterations between checkpoints (and episode restarts, for exact resumption)
    eval_every: int = 5  # chunks between evaluations of the fixed clip set
    eval_caps: tuple[float, ...] = (0.25, 0.0)
    cap_zero_share: float = 0.25  # episodes with no root residual at all (CapCurriculum.zero_share); 1: all
    fail_weight: float = 4.0  # a clip's sampling weight is 1 + fail_weight x its recent fall rate
    seed: int = 0


def no_hand_config(base: ImitatorTrainConfig, action_scale: float = 0.5) -> ImitatorTrainConfig:
    """``base`` with no outside hand anywhere: the tracker's root residual, lift and feet balance off
    (:func:`~physmotion.physics.search.no_hand`), the cap 0 in every episode (the curriculum's zero share 1,
    which its level cannot move) and evaluated at cap 0 only; offsets up to ``action_scale`` rad (the
    search's committed offsets reach ~0.8 rad, 95 % under ~0.26 rad in the first teacher records).
    A warm start replaces ``action_scale`` and the tracking with its own."""
    from physmotion.physics.search import no_hand
    from physmotion.physics.tracking import TrackingConfig

    settings = PolicySettings(action_scale=action_scale, cap=0.0, tracking=no_hand(TrackingConfig()))
    return replace(base, env=replace(base.env, settings=settings), eval_caps=(0.0,), cap_zero_share=1.0)


def read_warm_start(folder: str | Path) -> tuple[dict[str, np.ndarray], PolicySettings]:
    """A policy folder's raw weights (``obs_mean``, ``obs_std`` (599,), ``layers.{i}.weight`` (out, in),
    ``layers.{i}.bias`` (out,)) and settings; PhysmotionError naming what is wrong."""
    from safetensors.numpy import load_file

    from physmotion.physics.policy import load_policy

    policy = load_policy(folder)  # checks the files and the shapes
    weights = load_file(str(Path(folder) / "policy.safetensors"))
    if not np.all(weights["obs_std"] > 0):
        raise PhysmotionError(f"cannot warm-start from {folder}: its obs_std has values <= 0")
    return weights, policy.settings


def _warm_config(cfg: ImitatorTrainConfig, weights: dict[str, np.ndarray], settings: PolicySettings
                 ) -> ImitatorTrainConfig:  # fmt: skip
    """``cfg`` with the warm start's hidden widths, action scale and tracking (its cap stays ``cfg``'s)."""
    n = len({k.split(".")[1] for k in weights if k.startswith("layers.")})
    hidden = tuple(int(weights[f"layers.{i}.bias"].shape[0]) for i in range(n - 1))
    env_settings = replace(cfg.env.settings, action_scale=settings.action_scale, tracking=settings.tracking)
    return replace(cfg, hidden_dims=hidden, env=replace(cfg.env, settings=env_settings))


def _load_actor(alg, weights: dict[str, np.ndarray]) -> None:
    """Copy a policy folder's network into rsl-rl's actor: its Linear layers and its observation
    normaliser."""
    import torch

    actor = alg.actor
    linears = [m for m in actor.mlp if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for i, lin in enumerate(linears):
            lin.weight.copy_(torch.from_numpy(weights[f"layers.{i}.weight"]))
            lin.bias.copy_(torch.from_numpy(weights[f"layers.{i}.bias"]))
        norm = actor.obs_normalizer
        # rsl-rl 5.5.1's EmpiricalNormalization normalises by (x - _mean) / (_std + eps) with buffers _mean,
        # _var, _std of shape (1, 599) and a sample ``count``; exported, obs_std is _std + eps.
        norm._mean.copy_(torch.from_numpy(weights["obs_mean"])[None])
        norm._std.copy_(torch.from_numpy(weights["obs_std"])[None])
        norm._var.copy_(norm._std**2)
    _freeze(norm)


def _freeze(norm) -> None:
    """Freeze a warm-started actor's normaliser: eps 0, so that (x - mean) / std is the folder's exactly
    (_std holds its obs_std, eps included), and ``until`` 0, so that update() returns at once (its
    ``count >= until`` guard). Frozen rather than seeded: the warm-started first layer was fitted to these
    statistics, and moving them would move every input it sees. Neither attribute is in the checkpoint's
    state dict, so a resumed run freezes again."""
    norm.eps = 0.0
    norm.until = 0


def make_algorithm(env: VecImitationEnv, cfg: ImitatorTrainConfig, device: str = "cpu",
                   warm: dict[str, np.ndarray] | None = None):  # fmt: skip
    """rsl-rl's PPO for ``env``: the actor at ``warm`` (a policy folder's weights, :func:`read_warm_start`;
    its normaliser frozen) or, without, with a zero last layer, so that a zero action, the tracker, is where
    training starts. The critic starts fresh either way."""
    import torch
    from rsl_rl.algorithms import PPO

    alg = PPO.construct_algorithm(env.get_observations(), env, _rsl_cfg(cfg), device)
    if warm is not None:
        _load_actor(alg, warm)
    else:
        last = [m for m in alg.actor.mlp if isinstance(m, torch.nn.Linear)][-1]
        with torch.no_grad():
            last.weight.zero_()
            last.bias.zero_()
    return alg


def _rsl_cfg(cfg: ImitatorTrainConfig) -> dict:
    mlp = {"class_name": "MLPModel", "hidden_dims": list(cfg.hidden_dims), "activation": "elu",
           "obs_normalization": True}  # fmt: skip
    return {
        "num_steps_per_env": cfg.num_steps_per_env,
        "obs_groups": {"actor": ["policy"], "critic": ["policy"]},
        "actor": {**mlp, "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": cfg.init_std}},
        "critic": mlp,
        "algorithm": {"class_name": "PPO", "num_learning_epochs": cfg.num_learning_epochs,
                      "num_mini_batches": cfg.num_mini_batches, "learning_rate": cfg.learning_rate,
                      "schedule": "adaptive", "desired_kl": cfg.desired_kl, "entropy_coef": cfg.entropy_coef,
                      "gamma": cfg.gamma, "lam": cfg.lam, "clip_param": 0.2, "max_grad_norm": 1.0},
        "multi_gpu": None,
    }  # fmt: skip


def _stream(seed: int, *key: int) -> int:
    return int(np.random.SeedSequence([seed, *key]).generate_state(1)[0])


def export_weights(alg) -> dict[str, np.ndarray]:
    """The actor's mean network as the numpy arrays :class:`~physmotion.physics.policy.PolicyNetwork`
    reads: normaliser mean and std (std + rsl-rl's eps, as its forward divides by) and the Linear layers."""
    import torch

    actor = alg.get_policy()
    norm = actor.obs_normalizer
    out = {"obs_mean": norm.mean.cpu().numpy(), "obs_std": (norm.std + norm.eps).cpu().numpy()}
    linears = [m for m in actor.mlp if isinstance(m, torch.nn.Linear)]
    for i, lin in enumerate(linears):
        out[f"layers.{i}.weight"] = lin.weight.detach().cpu().numpy()
        out[f"layers.{i}.bias"] = lin.bias.detach().cpu().numpy()
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in out.items()}


def train_imitator(
    out: str | Path,
    clips: list[ClipSource],
    eval_clips: list[ClipSource],
    *,
    iterations: int | None = None,
    minutes: float | None = None,
    resume: bool = False,
    config: ImitatorTrainConfig | None = None,
    device: str = "cpu",
    sources: list[str] | None = None,
    warm_start: str | Path | None = None,
    log=print,
) -> Path:
    """Train (or resume) an imitation policy in the run folder ``out``; return the exported policy folder.

    Stops after ``iterations`` more iterations or once ``minutes`` have passed, whichever comes first, at a
    chunk boundary. ``sources``: the data folders, for the card. ``warm_start``: a policy folder the actor
    starts from (its hidden widths, action scale and tracking replace ``config``'s; resuming, only those
    settings are read, the weights being the checkpoint's).
    """
    import torch

    try:
        import rsl_rl  # noqa: F401
    except ImportError:
        raise PhysmotionError("training the imitator needs rsl-rl: pip install 'physmotion[train]'") from None

    cfg = config or ImitatorTrainConfig()
    warm = None
    if warm_start is not None:
        warm, warm_settings = read_warm_start(warm_start)
        cfg = _warm_config(cfg, warm, warm_settings)
    if iterations is None and minutes is None:
        raise PhysmotionError("give --iterations or --minutes")
    run = Path(out)
    ckpt_path = run / "checkpoint.pt"
    if run.exists() and any(run.iterdir()) and not resume:
        raise PhysmotionError(f"{run} exists and is not empty: pass --resume to continue it")
    if resume and not ckpt_path.is_file():
        raise PhysmotionError(f"nothing to resume: {ckpt_path} is missing")
    run.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    env = VecImitationEnv(clips, eval_clips, cfg.env, cfg.num_envs, cfg.workers, _stream(cfg.seed, 0),
                          CapCurriculum(zero_share=cfg.cap_zero_share))  # fmt: skip
    try:
        alg = make_algorithm(env, cfg, device, None if resume else warm)
        state = {"iteration": 0, "samples": 0, "wall_s": 0.0, "level": 0.0, "fails": np.zeros(len(clips)),
                 "warm_start": None if warm_start is None else str(warm_start)}  # fmt: skip
        if resume:
            saved = torch.load(ckpt_path, weights_only=False, map_location=device)
            # A checkpoint slimmed for travel may leave the optimiser out: Adam then starts afresh.
            parts = {"actor": True, "critic": True, "optimizer": "optimizer_state_dict" in saved["alg"]}
            alg.load(saved["alg"], parts, strict=True)
            state = saved["state"]
            if saved["clips"] != len(clips):  # fine-tuning on another clip set: its failure record starts anew
                log(f"the run was trained on {saved['clips']} clips, these are {len(clips)}: clip sampling "
                    "weights start anew")  # fmt: skip
                state["fails"] = np.zeros(len(clips))
            if state.get("warm_start"):
                _freeze(alg.actor.obs_normalizer)
        env.curriculum.level = state["level"]
        env.weights = 1.0 + cfg.fail_weight * state["fails"]
        started, stop_it = time.monotonic(), state["iteration"] + (iterations or 10**9)
        hardware = _hardware(device, len(env._procs))
        log(f"training on {len(clips)} clips, {env.num_envs} environments in {len(env._procs)} processes, "
            f"{OBS_DIM} observations; iteration {state['iteration']}")  # fmt: skip
        while state["iteration"] < stop_it:
            elapsed = (time.monotonic() - started) / 60.0
            if state["iteration"] % cfg.chunk == 0:
                if minutes is not None and elapsed >= minutes and state["iteration"] > 0:
                    break
                obs = env.reset(_stream(cfg.seed, 1, state["iteration"]))
                obs = env.get_observations()
            row = _iteration(alg, env, cfg, state, obs, torch)
            obs = env.get_observations()
            state["wall_s"] += row.pop("_seconds")
            _append_csv(run / "log.csv", row)
            if state["iteration"] % cfg.chunk == 0:
                if state["iteration"] % (cfg.chunk * cfg.eval_every) == 0:
                    _evaluate(env, alg, cfg, state, run, log)
                    _export(run, alg, cfg, state, clips, sources or [], hardware)  # a killed run keeps one
                _save(ckpt_path, alg, state, len(clips))
                log(f"iteration {state['iteration']}: {state['samples']:,} samples, reward {row['reward']:.3f}, "
                    f"episode {row['episode_steps']:.1f} steps, survival {row['survival']:.2f}, "
                    f"cap level {row['cap_level']:.2f}, {state['wall_s'] / 60:.1f} min")  # fmt: skip
        if state["iteration"] % cfg.chunk:
            log("stopped between chunk boundaries: the checkpoint is the last boundary's")
        _evaluate(env, alg, cfg, state, run, log)
        policy_dir = _export(run, alg, cfg, state, clips, sources or [], hardware)
        _plot(run)
        return policy_dir
    finally:
        env.close()


def _iteration(alg, env: VecImitationEnv, cfg: ImitatorTrainConfig, state: dict, obs, torch) -> dict:
    """One PPO iteration: a rollout of ``num_steps_per_env`` steps in every environment, then the update."""
    t0 = time.monotonic()
    torch.manual_seed(_stream(cfg.seed, 2, state["iteration"]))
    ends: list[EpisodeEnd] = []
    rewards = 0.0
    with torch.inference_mode():
        obs = obs.to(alg.device)
        for _ in range(cfg.num_steps_per_env):
            actions = alg.act(obs)
            obs, rew, dones, extras = env.step(actions)
            obs, rew, dones = obs.to(alg.device), rew.to(alg.device), dones.to(alg.device)
            alg.process_env_step(obs, rew, dones, extras)
            rewards += float(rew.mean())
            ends.extend(extras["episode_ends"])
        alg.compute_returns(obs)
    losses = alg.update()
    fails = state["fails"]
    for e in ends:  # recent fall rate per clip: the sampler leans toward the clips it fails on
        fails[e.clip] = 0.8 * fails[e.clip] + 0.2 * float(e.fell)
    env.weights = 1.0 + cfg.fail_weight * fails
    survival = float(np.mean([not e.fell for e in ends])) if ends else 1.0
    env.curriculum.update(survival)
    state["level"] = env.curriculum.level
    state["iteration"] += 1
    state["samples"] += cfg.num_steps_per_env * env.num_envs
    return {
        "iteration": state["iteration"],
        "samples": state["samples"],
        "wall_s": round(state["wall_s"] + time.monotonic() - t0, 2),
        "reward": rewards / cfg.num_steps_per_env,
        "episode_steps": float(np.mean([e.steps for e in ends])) if ends else float("nan"),
        "survival": survival,
        "episode_mpjpe_mm": 1000.0 * float(np.mean([e.mpjpe for e in ends])) if ends else float("nan"),
        "episode_residual": float(np.mean([e.force for e in ends])) if ends else float("nan"),
        "cap_level": env.curriculum.level,
        "value_loss": float(losses.get("value", losses.get("value_function", float("nan")))),
        "_seconds": time.monotonic() - t0,
    }


def _evaluate(env: VecImitationEnv, alg, cfg: ImitatorTrainConfig, state: dict, run: Path, log) -> None:
    if env.num_eval == 0:
        return
    weights = export_weights(alg)
    for cap in cfg.eval_caps:
        rows = env.evaluate(weights, cfg.env.settings, cap)
        summary = {
            "iteration": state["iteration"],
            "samples": state["samples"],
            "cap": cap,
            "success": float(np.mean([r["success"] for r in rows])),
            "survived": float(np.mean([r["survived"] for r in rows])),
            "mpjpe_mm": float(np.mean([r["mpjpe_mm"] for r in rows])),
            "residual_force": float(np.mean([r["residual_force"] for r in rows])),
        }
        _append_csv(run / "eval.csv", summary)
        log(f"  eval at cap {cap:g}: success {summary['success']:.2f}, survived {summary['survived']:.2f}, "
            f"MPJPE {summary['mpjpe_mm']:.1f} mm, residual {summary['residual_force']:.3f} W")  # fmt: skip


def _save(path: Path, alg, state: dict, clips: int) -> None:
    import torch

    tmp = path.with_suffix(".tmp")
    torch.save({"alg": alg.save(), "state": state, "clips": clips}, tmp)
    os.replace(tmp, path)


def _append_csv(path: Path, row: dict) -> None:
    new = not path.is_file()
    with path.open("a", newline="") as f:
        w = csv.DictWriter(f, fieldnames=list(row))
        if new:
            w.writeheader()
        w.writerow({k: (round(v, 5) if isinstance(v, float) else v) for k, v in row.items()})


def _hardware(device: str, processes: int) -> str:
    from physmotion.provenance import cpu_model

    text = f"{os.cpu_count()} x {cpu_model()}, {processes} environment processes"
    if device.startswith("cuda"):
        import torch

        text += f", network on {torch.cuda.get_device_name(0)}"
    return text


def _export(run: Path, alg, cfg: ImitatorTrainConfig, state: dict, clips: list[ClipSource],
            sources: list[str], hardware: str) -> Path:  # fmt: skip
    """Write ``run/policy`` atomically: weights, settings, card."""
    import shutil

    from safetensors.numpy import save_file

    final = run / "policy"
    tmp = run / "policy.tmp"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir()
    save_file(export_weights(alg), str(tmp / "policy.safetensors"))
    (tmp / "settings.json").write_text(json.dumps(settings_dict(cfg.env.settings), indent=2) + "\n")
    evals = []
    if (run / "eval.csv").is_file():
        with (run / "eval.csv").open(newline="") as f:
            evals = list(csv.DictReader(f))
    card = {
        "what": "physmotion imitation policy: offsets to the model-based tracker's PD targets (physics/policy.py)",
        "data": {
            "sources": sources,
            "captured_clips": sum(c.origin == "captured" for c in clips),
            "generated_clips": sum(c.origin == "generated" for c in clips),
            "licence_tags": licence_tags(clips),
        },
        "warm_start": state.get("warm_start"),
        "iterations": state["iteration"],
        "samples": state["samples"],
        "wall_minutes": round(state["wall_s"] / 60.0, 1),
        "hardware": hardware,
        "train_config": {k: v for k, v in asdict(cfg).items() if k != "env"},
        "reward": asdict(cfg.env.reward),
        "last_evaluation": evals[-len(cfg.eval_caps):] if evals else [],
    }
    (tmp / "card.json").write_text(json.dumps(card, indent=2) + "\n")
    shutil.rmtree(final, ignore_errors=True)
    os.replace(tmp, final)
    return final


def _plot(run: Path) -> None:
    """``curves.png``: training reward and episode length, and evaluation success, if matplotlib is there."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    with (run / "log.csv").open(newline="") as f:
        rows = list(csv.DictReader(f))
    if not rows:
        return
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.2))
    x = [int(r["samples"]) / 1e6 for r in rows]
    axes[0].plot(x, [float(r["reward"]) for r in rows])
    axes[0].set_title("reward per step")
    axes[1].plot(x, [float(r["episode_steps"]) for r in rows])
    axes[1].set_title("episode length (control steps)")
    if (run / "eval.csv").is_file():
        with (run / "eval.csv").open(newline="") as f:
            ev = list(csv.DictReader(f))
        for cap in sorted({r["cap"] for r in ev}):
            sel = [r for r in ev if r["cap"] == cap]
            axes[2].plot([int(r["samples"]) / 1e6 for r in sel], [float(r["success"]) for r in sel],
                         marker="o", label=f"cap {cap}")  # fmt: skip
        axes[2].legend()
    axes[2].set_title("evaluation success")
    for a in axes:
        a.set_xlabel("million samples")
    fig.tight_layout()
    tmp = run / "curves.tmp.png"
    fig.savefig(tmp, dpi=90)
    plt.close(fig)
    os.replace(tmp, run / "curves.png")
