"""A fast controller learned from the search: a policy network (the shipped policy's form,
:class:`~physmotion.physics.policy.PolicyNetwork`) trained on the search's teacher records, with no outside
hand (docs/decisions/projection.md: "learning from the search").

- Behaviour cloning (:func:`fit_student`): observations -> offsets, scaled by ``action_scale`` and clipped
  to [-1, 1]; MSE; inputs standardised.
- Labels (:class:`Labeller`): by default MPPI-style, a deterministic and smooth function of the state (common
  random numbers, candidates averaged by their costs); or the search's best candidate around the student's
  own proposal. The search's committed offsets themselves (:func:`teacher_pairs`) are the naive labels.
- :func:`train_student`: BC on the :class:`Expert`'s (the labeller acting) episodes, then DAgger rounds: the
  student drives the training references (hand off) and the states it visits are labelled.
- :func:`carry`: one episode of any controller with no outside hand, ended by a fall as the search defines
  it (pelvis dropped or tipped against the reference), not by a world-position error.

Training uses torch; acting (``PolicyNetwork``) is numpy, as P's workers require.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from functools import partial
from pathlib import Path

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.physics.humanoid import HumanoidConfig, layout
from physmotion.physics.policy import (
    NUM_ACTIONS,
    OBS_DIM,
    Policy,
    PolicyNetwork,
    PolicySettings,
    settings_dict,
)
from physmotion.physics.search import SearchConfig, SearchController, SearchGoal, no_hand
from physmotion.physics.tracking import ModelBasedTracker, Reference, TrackingConfig


@dataclass(frozen=True)
class StudentConfig:
    """The student network and its supervised training."""

    hidden: tuple[int, ...] = (512, 256)
    action_scale: float = 0.3  # rad per unit action: the search's offsets reach 0.2-0.33 rad (its retries widen)
    steps: int = 3000  # gradient steps per fit
    batch: int = 512
    learning_rate: float = 1e-3
    weight_decay: float = 1e-4
    validation: float = 0.1  # share of the records (whole records, not steps) held out for the validation loss
    # Start from the bare tracker (a zero last layer) and keep the weights of the step with the least
    # validation loss (step 0 included, checked every 25), not the last: small sets overfit until held-out
    # error is above predicting 0 (docs/decisions/projection.md, "learning from the search at scale").
    select_on_validation: bool = False
    seed: int = 0


def teacher_pairs(records: Sequence[dict], action_scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(observations (M, 599) float32, actions (M, 63) float32 in [-1, 1], record index (M,)) of every
    committed control step of ``records`` (:func:`physmotion.imitator.teacher.load_teacher_set`) before its
    fall, the last step (no action) left out."""
    xs, ys, ids = [], [], []
    for i, r in enumerate(records):
        end = len(r["offsets"]) - 1
        if int(r["failed_at"]) >= 0:
            end = min(end, int(r["failed_at"]))
        xs.append(r["observations"][:end])
        ys.append(np.clip(r["offsets"][:end] / action_scale, -1.0, 1.0))
        ids.append(np.full(end, i))
    return (np.concatenate(xs).astype(np.float32), np.concatenate(ys).astype(np.float32),
            np.concatenate(ids))  # fmt: skip


def fit_student(x: np.ndarray, y: np.ndarray, groups: np.ndarray, config: StudentConfig) -> tuple[dict, dict]:
    """Fit the student on observations x (M, 599) -> actions y (M, 63); groups (M,) names each pair's
    record, and whole records are held out for validation. Returns the network's weights (PolicyNetwork's
    arrays) and {"train_mse", "val_mse", and of predicting 0 (the bare tracker) "train_mse_zero",
    "val_mse_zero"; "pairs"; "steps_kept", the step whose weights were kept}."""
    import torch

    if len(x) != len(y) or x.shape[1:] != (OBS_DIM,) or y.shape[1:] != (NUM_ACTIONS,):
        raise PhysmotionError(f"student data must be (M, {OBS_DIM}) and (M, {NUM_ACTIONS}), got {x.shape}, {y.shape}")
    rng = np.random.default_rng(config.seed)
    names = np.unique(groups)
    held = set(rng.choice(names, size=max(1, int(round(config.validation * len(names)))), replace=False).tolist())
    val = np.isin(groups, list(held)) if len(names) > 1 else np.zeros(len(x), dtype=bool)
    mean = x[~val].mean(axis=0)
    std = x[~val].std(axis=0) + 1e-2  # a floor: some inputs are constant over a data set (the cap)
    torch.manual_seed(config.seed)
    dims = [OBS_DIM, *config.hidden, NUM_ACTIONS]
    layers: list = []
    for i in range(len(dims) - 1):
        layers.append(torch.nn.Linear(dims[i], dims[i + 1]))
        if i < len(dims) - 2:
            layers.append(torch.nn.ELU())
    net = torch.nn.Sequential(*layers)
    select = config.select_on_validation and val.any()
    if select:  # step 0 is the bare tracker: a fit kept on validation is never worse than it on held-out data
        torch.nn.init.zeros_(layers[-1].weight)
        torch.nn.init.zeros_(layers[-1].bias)
    opt = torch.optim.AdamW(net.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    xt = torch.from_numpy((x - mean) / std)
    yt = torch.from_numpy(y)
    train_idx = np.flatnonzero(~val)
    gen = torch.Generator().manual_seed(config.seed)
    val_idx = torch.from_numpy(np.flatnonzero(val))
    best, best_step = (float("inf"), None), 0
    for step in range(config.steps + 1):
        if step:
            b = torch.from_numpy(train_idx)[torch.randint(len(train_idx), (config.batch,), generator=gen)]
            loss = torch.mean((net(xt[b]) - yt[b]) ** 2)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
        if select and (step % 25 == 0 or step == config.steps):
            with torch.no_grad():
                v = float(torch.mean((net(xt[val_idx]) - yt[val_idx]) ** 2))
            if v < best[0]:
                best, best_step = (v, {k: t.clone() for k, t in net.state_dict().items()}), step
    if select:
        net.load_state_dict(best[1])
    with torch.no_grad():
        pred = net(xt)
        err = ((pred - yt) ** 2).mean(dim=1).numpy()
    stats = {"pairs": len(x), "train_mse": float(err[~val].mean()), "train_mse_zero": float((y[~val] ** 2).mean()),
             "val_mse": float(err[val].mean()) if val.any() else float("nan"),
             "val_mse_zero": float((y[val] ** 2).mean()) if val.any() else float("nan"),
             "steps_kept": best_step if select else config.steps}  # fmt: skip
    linears = [m for m in net if isinstance(m, torch.nn.Linear)]
    weights = {"obs_mean": mean, "obs_std": std}
    for i, lin in enumerate(linears):
        weights[f"layers.{i}.weight"] = lin.weight.detach().numpy()
        weights[f"layers.{i}.bias"] = lin.bias.detach().numpy()
    return {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in weights.items()}, stats


def student_settings(config: StudentConfig, tracking: TrackingConfig | None = None) -> PolicySettings:
    """How a student acts: the search's nominal control (the tracker with every outside help off) plus
    ``action_scale`` x its action, at cap 0."""
    return PolicySettings(action_scale=config.action_scale, cap=0.0, tracking=no_hand(tracking or TrackingConfig()))


def save_student(folder: str | Path, weights: dict, settings: PolicySettings, card: dict) -> Path:
    """Write a policy folder P loads (``--controller policy --policy FOLDER``): policy.safetensors,
    settings.json, card.json (what it was trained on, its licence tags and figures), each atomically."""
    from safetensors.numpy import save

    from physmotion.motion import write_atomic

    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    write_atomic(root / "policy.safetensors", lambda f: f.write(save(weights)))
    write_atomic(root / "settings.json", lambda f: f.write(json.dumps(settings_dict(settings), indent=1).encode()))
    write_atomic(root / "card.json", lambda f: f.write(json.dumps(card, indent=1).encode()))
    return root


def student_policy(weights: dict, settings: PolicySettings) -> Policy:
    """The trained weights as a :class:`Policy` (no card)."""
    return Policy(PolicyNetwork(weights), settings, {})


@dataclass
class Carried:
    """One episode with no outside hand: ``survived`` control steps before the fall (all of them when
    ``completed``), of ``steps``; world and pelvis-relative MPJPE (m) over the survived steps; the
    visited full-physics states (steps, nstate) up to the fall."""

    steps: int
    survived: int
    completed: bool
    mpjpe: float
    mpjpe_rel: float
    states: np.ndarray


def carry(model, ref: Reference, controller, humanoid: HumanoidConfig | None = None,
          push: np.ndarray | None = None, fall: SearchConfig | None = None) -> Carried:  # fmt: skip
    """Run ``controller`` (a :class:`~physmotion.physics.tracking.Controller`, whatever outside help it
    gives) along ``ref`` from its first frame (its root velocity plus ``push`` (6,)) until the end or a fall
    (``fall``'s drop and tilt: the search's definition)."""
    import mujoco

    from physmotion.physics.sim import _quiet_mujoco_warnings, control_step, reset_state
    from physmotion.physics.tracking import STANDARD_GRAVITY

    _quiet_mujoco_warnings()
    hum = humanoid or HumanoidConfig()
    goal = SearchGoal(ref, fall or SearchConfig())
    data = mujoco.MjData(model)
    reset_state(model, data, ref)
    if push is not None:
        data.qvel[:6] += push
        mujoco.mj_forward(model, data)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    states = [_state(model, data, spec)]
    weight = float(model.body_subtreemass[0]) * STANDARD_GRAVITY
    ids = layout(model).body_ids
    err, rel = [], []
    n = len(ref.qpos)
    survived = n - 1
    for k in range(n - 1):
        control_step(model, data, ref, controller, k, hum, weight)
        if not np.all(np.isfinite(data.qpos)) or goal.fallen(data.qpos, k + 1):
            survived = k
            break
        bodies, target = data.xpos[ids], ref.joints_mj[k + 1]
        err.append(np.linalg.norm(bodies - target, axis=-1).mean())
        rel.append(np.linalg.norm((bodies - bodies[0]) - (target - target[0]), axis=-1).mean())
        states.append(_state(model, data, spec))
    return Carried(n - 1, survived, survived == n - 1, float(np.mean(err)) if err else float("nan"),
                   float(np.mean(rel)) if rel else float("nan"), np.stack(states))  # fmt: skip


def _state(model, data, spec) -> np.ndarray:
    import mujoco

    s = np.empty(mujoco.mj_stateSize(model, spec))
    mujoco.mj_getState(model, data, s, spec)
    return s


def dagger_steps(carried: Carried, near: int = 45, every_near: int = 3, every_far: int = 9) -> list[int]:
    """Which visited states to label: every ``every_near``-th of the ``near`` control steps before the
    student's fall (where it goes wrong), every ``every_far``-th before them (and everywhere when it did not
    fall): a fixed labelling budget spent where the student needs it."""
    end = carried.survived
    start = end - near if not carried.completed else end + 1
    far = [k for k in range(0, max(start, 0), every_far)]
    return far + [k for k in range(max(start, 0), end + 1, every_near)]


@dataclass(frozen=True)
class Labeller:
    """Who labels a state with the offsets to apply (63,) rad: one window of the search at ``effort``.

    temperature set (the default): MPPI-style, the candidates drawn around 0 with the same ``seed`` for every
    state (common random numbers) and averaged with weights exp(-(cost - least) / (temperature x (median -
    least))): a deterministic, smooth function of the state, which a network can learn
    (:meth:`SearchController.window`). None: the best candidate of a search centred on the student's own
    proposal, seeded per state (its local improvement; measured no better in the decision entry)."""

    effort: SearchConfig = SearchConfig(candidates=32, rounds=1, elites=2, horizon=15, retries=0, rollback=0)
    temperature: float | None = 0.1
    seed: int = 0


def dagger_labels(model, ref: Reference, policy: Policy | None, states: np.ndarray, steps: Sequence[int],
                  labeller: Labeller, humanoid: HumanoidConfig | None = None,
                  action_scale: float = 0.3) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """Observations (M, 599) and action labels (M, 63, offsets / ``action_scale`` clipped to [-1, 1]) of the
    visited ``states`` (S, nstate; state k at control step k) at control ``steps``, by ``labeller``
    (``policy``: the student whose proposal centres a search without temperature)."""
    import mujoco

    from physmotion.physics.policy import observe

    tracking = policy.settings.tracking if policy is not None else no_hand(TrackingConfig())
    search = SearchController(model, replace(labeller.effort, threads=1), humanoid, tracking)
    data = mujoco.MjData(model)
    spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
    xs, ys = [], []
    for k in steps:
        if k >= min(len(states), len(ref.qpos) - 1):
            continue
        mujoco.mj_setState(model, data, states[k], spec)
        mujoco.mj_forward(model, data)
        obs = observe(model, data, ref, k, 0.0)
        if labeller.temperature is not None:
            offset = search.window(ref, states[k], k, np.zeros(model.nu), labeller.seed, labeller.temperature)
        else:
            scale = policy.settings.action_scale
            proposal = scale * np.clip(policy.network(obs), -1.0, 1.0)
            offset = search.window(ref, states[k], k, proposal, labeller.seed * 100_003 + k)
        xs.append(obs)
        ys.append(np.clip(offset / action_scale, -1.0, 1.0))
    if not xs:
        return np.zeros((0, OBS_DIM), np.float32), np.zeros((0, NUM_ACTIONS), np.float32)
    return np.stack(xs).astype(np.float32), np.stack(ys).astype(np.float32)


class Expert:
    """The labeller as a controller (:class:`~physmotion.physics.tracking.Controller`): every ``window``
    control steps it labels the current state and holds that offset over the window, on the tracker with
    every outside help off. What its labels are worth when acted on; its visited states and labels are a
    student's first data."""

    def __init__(self, model, labeller: Labeller, humanoid: HumanoidConfig | None = None,
                 tracking: TrackingConfig | None = None) -> None:  # fmt: skip
        import mujoco

        self.model, self.labeller = model, labeller
        self.tracker = ModelBasedTracker(model, no_hand(tracking or TrackingConfig()))
        self.search = SearchController(model, replace(labeller.effort, threads=1), humanoid, tracking)
        self.offset = np.zeros(model.nu)
        self._spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._state = np.empty(mujoco.mj_stateSize(model, self._spec))
        self.labels: dict[int, np.ndarray] = {}  # control step -> the offset labelled there

    def act(self, data, ref: Reference, k: int) -> tuple[np.ndarray, np.ndarray]:
        import mujoco

        if k % self.labeller.effort.window == 0:
            mujoco.mj_getState(self.model, data, self._state, self._spec)
            mean = np.zeros(self.model.nu)
            self.offset = self.search.window(ref, self._state, k, mean, self.labeller.seed, self.labeller.temperature)
            self.labels[k] = self.offset
        ctrl, qfrc = self.tracker.act(data, ref, k)
        return ctrl + self.offset, qfrc

    def residual(self, data, ref: Reference, step: int, substeps: int) -> np.ndarray:
        return self.tracker.residual(data, ref, step, substeps)

    def caps(self) -> tuple[float, float, float]:
        return self.tracker.caps()


def prepared(joints: np.ndarray, fps: float) -> tuple:
    """(model, reference, P's configuration) of a motion (T, 22, 3) at ``fps`` as the teacher data searched it
    (:meth:`physmotion.imitator.teacher.TeacherConfig.projection`)."""
    from physmotion.imitator.teacher import TeacherConfig
    from physmotion.physics.projection import prepare_motion
    from physmotion.physics.tracking import prepare_reference

    pconf = TeacherConfig().projection()
    prep = prepare_motion(joints.astype(np.float64), fps, pconf)
    return prep.model, prepare_reference(prep.model, prep.target, pconf.humanoid.control_dt, pconf.tracking), pconf


def train_student(records: Sequence[dict], out: str | Path, config: StudentConfig | None = None,
                  dagger_rounds: int = 2, labeller: Labeller | None = None, workers: int = 0,
                  log=print) -> dict[str, str]:  # fmt: skip
    """A student from ``records``' references: behaviour cloning, then ``dagger_rounds`` rounds of DAgger
    (the student drives every record's reference from its start, pushed as the record was; its visited states
    at :func:`dagger_steps` are labelled by ``labeller``; refit on all pairs). With a temperature, the first
    data are the :class:`Expert`'s own episodes; without, the search's committed offsets in the records.
    Each student is written as a policy folder, ``out/bc`` and ``out/dagger<r>``. Returns {name: folder};
    each card holds the fit and, for DAgger, the share of control steps the previous student survived."""
    from physmotion.physics.workers import map_in_workers

    cfg, lab = config or StudentConfig(), labeller or Labeller()
    root = Path(out)
    if lab.temperature is not None:
        got = map_in_workers(partial(expert_episode, labeller=lab, action_scale=cfg.action_scale), list(records),
                             workers)  # fmt: skip
        x, y = np.concatenate([a for a, _, _, _ in got]), np.concatenate([b for _, b, _, _ in got])
        g = np.concatenate([np.full(len(a), i) for i, (a, _, _, _) in enumerate(got)])
        done = sum(s == n for _, _, s, n in got)
        log(f"expert: {done} of {len(got)} records to the end, {len(x)} labelled states")
    else:
        x, y, g = teacher_pairs(records, cfg.action_scale)
    weights, stats = fit_student(x, y, g, cfg)
    folders = {"BC": str(save_student(root / "bc", weights, student_settings(cfg), card(cfg, "BC", records, stats)))}
    log(f"BC: {len(x)} pairs, validation MSE {stats['val_mse']:.3f} (0 predicted: {stats['val_mse_zero']:.3f})")
    for r in range(1, dagger_rounds + 1):
        step = partial(dagger_episode, labeller=replace(lab, seed=lab.seed if lab.temperature is not None else
                                                     cfg.seed * 1000 + r), action_scale=cfg.action_scale)  # fmt: skip
        x, y, g, survived = dagger_round(step, records, range(len(records)), folders[list(folders)[-1]],
                                         (x, y, g), workers)  # fmt: skip
        weights, stats = fit_student(x, y, g, cfg)
        stats["survived_before"] = round(float(survived), 3)
        name = f"DAgger {r}"
        folders[name] = str(save_student(root / f"dagger{r}", weights, student_settings(cfg),
                                         card(cfg, name, records, stats)))  # fmt: skip
        log(f"{name}: the student before it survived {survived:.2f} of the training steps; {len(x)} pairs, "
            f"validation MSE {stats['val_mse']:.3f}")  # fmt: skip
    return folders


def dagger_round(step, records: Sequence[dict], groups: Sequence[int], folder: str,
                 pairs: tuple[np.ndarray, np.ndarray, np.ndarray],
                 workers: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:  # fmt: skip
    """One DAgger round: the student in ``folder`` drives each of ``records`` through ``step`` (a partial of
    :func:`dagger_episode`), and the labelled pairs are appended to ``pairs`` (observations, labels, group),
    record i's under ``groups[i]``. Returns the grown pairs and the share of control steps it survived."""
    from physmotion.physics.workers import map_in_workers

    got = map_in_workers(step, [(rec, folder) for rec in records], workers)
    x = np.concatenate([pairs[0]] + [a for a, _, _, _ in got])
    y = np.concatenate([pairs[1]] + [b for _, b, _, _ in got])
    g = np.concatenate([pairs[2]] + [np.full(len(a), i) for i, (a, _, _, _) in zip(groups, got)])
    survived = sum(s for _, _, s, _ in got) / max(sum(n for _, _, _, n in got), 1)
    return x, y, g, float(survived)


def expert_episode(record: dict, labeller: Labeller, action_scale: float) -> tuple[np.ndarray, np.ndarray, int, int]:
    """A reference driven by the :class:`Expert` (``record``: "joints" (T, 22, 3) metres Y-up, "fps", "push"
    (6,), as a teacher record has them): observations (M, 599) and labels (M, 63) in [-1, 1] of its labelled
    states, control steps survived, control steps."""
    import mujoco

    from physmotion.physics.policy import observe

    model, ref, pconf = prepared(record["joints"], float(record["fps"]))
    expert = Expert(model, labeller, pconf.humanoid, pconf.tracking)
    c = carry(model, ref, expert, pconf.humanoid, push=record["push"])
    data, spec = mujoco.MjData(model), mujoco.mjtState.mjSTATE_FULLPHYSICS
    xs, ys = [], []
    for k, offset in sorted(expert.labels.items()):
        if k >= len(c.states):
            break
        mujoco.mj_setState(model, data, c.states[k], spec)
        mujoco.mj_forward(model, data)
        xs.append(observe(model, data, ref, k, 0.0))
        ys.append(np.clip(offset / action_scale, -1.0, 1.0))
    x = np.stack(xs).astype(np.float32) if xs else np.zeros((0, OBS_DIM), np.float32)
    y = np.stack(ys).astype(np.float32) if ys else np.zeros((0, NUM_ACTIONS), np.float32)
    return x, y, c.survived, c.steps


def dagger_episode(job: tuple[dict, str], labeller: Labeller, action_scale: float) -> tuple[np.ndarray, np.ndarray, int, int]:
    """A training record (:func:`expert_episode`'s keys) driven by the student in a policy folder (``job``:
    (record, folder)): its labelled pairs, control steps survived, control steps."""
    from physmotion.physics.policy import load_policy

    record, folder = job
    model, ref, pconf = prepared(record["joints"], float(record["fps"]))
    pol = load_policy(folder)
    c = carry(model, ref, pol.controller(model), pconf.humanoid, push=record["push"])
    steps = dagger_steps(c) if labeller.temperature is None else dagger_steps(c, every_far=3)
    x, y = dagger_labels(model, ref, pol, c.states, steps, labeller, pconf.humanoid, action_scale)
    return x, y, c.survived, c.steps


def card(config: StudentConfig, method: str, records: Sequence[dict], stats: dict) -> dict:
    """A student's card: how it was made, what data it saw (sources and licence tags) and its fit."""
    tags = sorted({str(r["licence_tag"]) for r in records if str(r["licence_tag"])})
    origins = sorted({str(r["origin"]) for r in records})
    return {"method": method, "config": asdict(config), "records": len(records), "origins": origins,
            "licence_tags": tags, "fit": stats, "outside_help": "none (cap 0, no feet balance)",
            # P runs a policy on its preset's humanoid and shaping; these are the ones it was trained on.
            "humanoid_and_shaping": "the plain preset's (TeacherConfig.projection(): the default HumanoidConfig, "
                                    "pyramidal cone, and ShapingConfig)"}  # fmt: skip
