"""Many imitation episodes at once, in worker processes, behind rsl-rl's ``VecEnv`` interface.

The simulation and the tracker are Python over MuJoCo and hold the GIL, so environments are spread over
processes (one per core by default), each stepping its own few environments in turn; the policy's batch
crosses a pipe once per control step. Clips are split between the workers (clip i lives in worker
i mod W), so each is prepared once: building its humanoid and reference takes about a second.

Sampling: a finished episode restarts on a clip drawn with probability proportional to its weight (the
trainer raises the weight of clips it fails on), at a random frame (reference state initialisation),
with a root-residual cap drawn from the curriculum (:class:`CapCurriculum`).
"""

from __future__ import annotations

import multiprocessing as mp
import os
from dataclasses import dataclass

import numpy as np

from physmotion.errors import PhysmotionError
from physmotion.imitator.clips import ClipSource
from physmotion.imitator.env import Clip, EnvConfig, ImitationEnv
from physmotion.physics.policy import NUM_ACTIONS, OBS_DIM


@dataclass
class CapCurriculum:
    """The root residual cap of each episode, as a multiple of the tracker's bounds.

    A share ``zero_share`` of episodes run with no residual at all; the rest draw the cap uniformly from
    [0, 1 - 0.75 level]. ``level`` climbs by ``rate`` after an iteration whose episodes mostly survive
    (``raise_above``) and falls back after one whose do not (``lower_below``): at level 1 every cap is at
    most 0.25 (0.05 W). Sampling a cap per episode instead of annealing one cap keeps what was learnt at
    higher caps (docs/decisions/projection.md: "a learned residual policy over the tracker").
    """

    level: float = 0.0
    zero_share: float = 0.25
    rate: float = 0.05
    raise_above: float = 0.7
    lower_below: float = 0.4

    def sample(self, rng: np.random.Generator) -> float:
        if rng.random() < self.zero_share:
            return 0.0
        return float(rng.uniform(0.0, 1.0 - 0.75 * self.level))

    def update(self, survival: float) -> None:
        """Move the level after an iteration whose finished episodes survived at rate ``survival``."""
        if survival > self.raise_above:
            self.level = min(1.0, self.level + self.rate)
        elif survival < self.lower_below:
            self.level = max(0.0, self.level - self.rate)


@dataclass
class EpisodeEnd:
    """What the trainer learns from a finished episode."""

    clip: int
    steps: int
    fell: bool
    mpjpe: float  # mean over the episode, m
    force: float  # mean residual force, fractions of W


# Set before the workers fork, read by them: the clips cross into the children by copy-on-write, not pickle.
_SHARED: dict[str, object] = {}


class VecImitationEnv:
    """``num_envs`` episodes over ``clips`` in ``workers`` processes (rsl-rl's VecEnv protocol)."""

    def __init__(self, clips: list[ClipSource], eval_clips: list[ClipSource], config: EnvConfig,
                 num_envs: int, workers: int = 0, seed: int = 0,
                 curriculum: CapCurriculum | None = None) -> None:  # fmt: skip
        import torch

        if not clips:
            raise PhysmotionError("no clips to train on")
        self.cfg = config
        self.num_envs = num_envs
        self.num_actions = NUM_ACTIONS
        self.max_episode_length = config.max_steps
        self.device = "cpu"
        self.episode_length_buf = torch.zeros(num_envs, dtype=torch.long)
        self.num_clips = len(clips)
        self.num_eval = len(eval_clips)
        self.curriculum = curriculum or CapCurriculum()
        self.weights = np.ones(len(clips))
        n = max(1, min(workers or os.cpu_count() or 1, num_envs, len(clips)))
        self._split = np.array_split(np.arange(num_envs), n)
        _SHARED.update(clips=clips, eval_clips=eval_clips, config=config)
        ctx = mp.get_context("fork")
        self._pipes, self._procs = [], []
        for w in range(n):
            parent, child = ctx.Pipe()
            proc = ctx.Process(target=_worker, args=(child, w, n, len(self._split[w])), daemon=True)
            proc.start()
            child.close()
            self._pipes.append(parent)
            self._procs.append(proc)
        _SHARED.clear()
        self._obs = self.reset(seed)

    # --- rsl-rl's VecEnv -------------------------------------------------------------------------------
    def get_observations(self):
        from tensordict import TensorDict

        return TensorDict({"policy": self._obs}, batch_size=[self.num_envs])

    def step(self, actions):
        import torch

        acts = actions.detach().cpu().numpy().astype(np.float64)
        for pipe, idx in zip(self._pipes, self._split):
            pipe.send(("step", (acts[idx], self.weights, self.curriculum)))
        obs, rew, term, trunc, ends = [], [], [], [], []
        for pipe in self._pipes:
            o, r, te, tr, e = _recv(pipe)
            obs.append(o), rew.append(r), term.append(te), trunc.append(tr), ends.extend(e)
        self._obs = torch.from_numpy(np.concatenate(obs))
        dones = np.concatenate(term) | np.concatenate(trunc)
        self.episode_length_buf += 1
        self.episode_length_buf[torch.from_numpy(dones)] = 0
        # episode_ends: ours, the episodes that ended at this step (rsl-rl reads only time_outs and log)
        extras = {"time_outs": torch.from_numpy(np.concatenate(trunc)).float(), "log": {}, "episode_ends": ends}
        return self.get_observations(), torch.from_numpy(np.concatenate(rew)).float(), \
            torch.from_numpy(dones).long(), extras  # fmt: skip

    # --- ours ------------------------------------------------------------------------------------------
    def reset(self, seed: int):
        """Restart every episode, drawing from the streams of ``seed`` (a resumed run passes its
        iteration, so it draws what an uninterrupted run would after that point)."""
        import torch

        for pipe in self._pipes:
            pipe.send(("reset", (seed, self.weights, self.curriculum)))
        self._obs = torch.from_numpy(np.concatenate([_recv(p) for p in self._pipes]))
        self.episode_length_buf.zero_()
        return self._obs

    def evaluate(self, weights: dict[str, np.ndarray], settings, cap: float) -> list[dict]:
        """Run the policy (numpy ``weights``) deterministically over every evaluation clip from its first
        frame at residual cap ``cap``; one record per clip, in the order given."""
        for pipe in self._pipes:
            pipe.send(("eval", (weights, settings, cap)))
        rows = [row for p in self._pipes for row in _recv(p)]
        return sorted(rows, key=lambda r: r["index"])

    def close(self) -> None:
        for pipe in self._pipes:
            try:
                pipe.send(("close", None))
            except (BrokenPipeError, OSError):
                pass
        for proc in self._procs:
            proc.join(timeout=5)
            if proc.is_alive():
                proc.kill()


def _recv(pipe):
    try:
        kind, payload = pipe.recv()
    except EOFError:
        raise PhysmotionError("an imitation worker process died (out of memory, or killed)") from None
    if kind == "error":
        raise PhysmotionError(f"an imitation worker failed: {payload}")
    return payload


def _worker(pipe, w: int, n: int, num_envs: int) -> None:
    """One worker: the clips i with i mod n == w, ``num_envs`` environments over them."""
    try:
        _serve(pipe, w, n, num_envs)
    except KeyboardInterrupt:
        pass
    except Exception as e:  # noqa: BLE001 - the trainer reports it as one line
        pipe.send(("error", f"{type(e).__name__}: {e}"))


def _serve(pipe, w: int, n: int, num_envs: int) -> None:
    from physmotion.physics.projection import ProjectionConfig, prepare_motion

    sources: list[ClipSource] = _SHARED["clips"]  # type: ignore[assignment]
    eval_sources: list[ClipSource] = _SHARED["eval_clips"]  # type: ignore[assignment]
    config: EnvConfig = _SHARED["config"]  # type: ignore[assignment]
    mine = np.arange(w, len(sources), n)
    proj = ProjectionConfig(humanoid=config.humanoid)
    cache: dict[int, Clip] = {}

    def clip(i: int) -> Clip:
        if i not in cache:
            s = sources[i]
            # the teacher's humanoid and shaping are P's plain ones, as ``proj``'s (TeacherConfig.projection)
            cache[i] = Clip(prepare_motion(s.joints.astype(np.float64), s.fps, proj), config, s.tracked)
        return cache[i]

    envs = [ImitationEnv(config) for _ in range(num_envs)]
    current = np.zeros(num_envs, dtype=int)
    stats = [[0, 0.0, 0.0] for _ in range(num_envs)]  # steps, summed mpjpe, summed force
    rng = np.random.default_rng([0, w])

    def restart(e: int, weights: np.ndarray, curriculum: CapCurriculum) -> np.ndarray:
        p = weights[mine] / weights[mine].sum()
        i = int(mine[rng.choice(len(mine), p=p)])
        c = clip(i)
        frame = int(rng.integers(0, max(1, c.steps - 2)))
        current[e] = i
        stats[e] = [0, 0.0, 0.0]
        return envs[e].reset(c, frame, curriculum.sample(rng))

    while True:
        cmd, payload = pipe.recv()
        if cmd == "close":
            return
        if cmd == "reset":
            seed, weights, curriculum = payload
            rng = np.random.default_rng([seed, w])
            pipe.send(("ok", np.stack([restart(e, weights, curriculum) for e in range(num_envs)])))
        elif cmd == "step":
            actions, weights, curriculum = payload
            obs = np.zeros((num_envs, OBS_DIM), dtype=np.float32)
            rew = np.zeros(num_envs, dtype=np.float32)
            term = np.zeros(num_envs, dtype=bool)
            trunc = np.zeros(num_envs, dtype=bool)
            ends = []
            for e, env in enumerate(envs):
                o, r, te, tr, info = env.step(actions[e])
                st = stats[e]
                st[0] += 1
                st[1] += info["mpjpe"]
                st[2] += info["force"]
                rew[e], term[e], trunc[e] = r, te, tr
                if te or tr:
                    ends.append(EpisodeEnd(int(current[e]), st[0], te, st[1] / st[0], st[2] / st[0]))
                    o = restart(e, weights, curriculum)
                obs[e] = o
            pipe.send(("ok", (obs, rew, term, trunc, ends)))
        elif cmd == "eval":
            weights, settings, cap = payload
            pipe.send(("ok", [_evaluate_one(j, eval_sources[j], weights, settings, cap, config, proj)
                              for j in range(w, len(eval_sources), n)]))  # fmt: skip


def _evaluate_one(j: int, source: ClipSource, weights, settings, cap: float, config: EnvConfig, proj) -> dict:
    """One evaluation clip simulated whole from its first frame (P's plain simulation, no reset)."""
    from physmotion.physics.policy import Policy, PolicyNetwork
    from physmotion.physics.projection import prepare_motion
    from physmotion.physics.sim import simulate
    from physmotion.physics.tracking import prepare_reference

    prep = prepare_motion(source.joints.astype(np.float64), source.fps, proj)
    ref = prepare_reference(prep.model, prep.target, config.humanoid.control_dt, settings.tracking)
    controller = Policy(PolicyNetwork(weights), settings, {}).controller(prep.model, cap)
    roll = simulate(prep.model, ref, controller, config.humanoid, fail_mpjpe=0.5)
    end = len(ref.qpos) if roll.failed_at is None else roll.failed_at
    return {
        "index": j,
        "name": source.name,
        "origin": source.origin,
        "success": roll.failed_at is None,
        "survived": end / len(ref.qpos),
        "mpjpe_mm": 1000.0 * float(roll.mpjpe[:end].mean()),
        "residual_force": float(roll.residual_force[:end].mean()),
    }
