"""Training loop: environment interaction, SAC updates, evaluation, TensorBoard, checkpoints and exact resume.

The env is any gymnasium env with Box observation and action spaces, built from the ``env`` config with
``hydra.utils.instantiate`` (``_target_`` + arguments). Exact resume rests on three choices:
- every random draw comes from the trainer's numpy Generator or the agent's torch Generator, both seeded
  here from ``seed`` and saved in the checkpoint;
- each episode's env is reset with a seed drawn from the trainer's Generator, so no env state needs saving;
- checkpoints are written at episode boundaries only.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import hydra.utils
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from vical.config import ConfigError, from_mapping, require, require_range
from vical.io.atomic import write_text_atomic
from vical.parallel import MAX_WORKERS, ParallelConfig
from vical.rl.buffer import ReplayBuffer, transition_discount
from vical.rl.checkpoint import flatten, load_checkpoint, require_compatible, save_checkpoint
from vical.rl.logger import TrainLogger
from vical.rl.sac import SAC, NonFiniteLossError, SACConfig

log = logging.getLogger(__name__)

CHECKPOINT = "checkpoint.pt"  # latest episode-boundary checkpoint: what resume=<run dir> continues from
LAST_GOOD = "last_good.pt"  # state just before a non-finite loss/observation, for inspection
AGENT = "agent.pt"  # final networks + agent config, for evaluation and deployment
# A policy version is kept per round of lag (a copy of the policy network): beyond this, memory grows for no gain
# (4 rounds already keep 2 workers busy, docs/scaling.md).
MAX_POLICY_LAG = 64
EVAL_SEED_OFFSET = 1_000_000  # evaluation episodes reset with seed + offset + i: the same starts every time


@dataclass
class TrainConfig:
    """Loop settings (steps count env transitions)."""

    total_steps: int = 10_000
    warmup_steps: int = 1_000  # uniform random actions and no updates before this many steps
    updates_per_step: int = 1  # gradient updates per collected transition (num_envs of them per round of steps)
    num_envs: int = 1  # environments, each in a worker process when > 1 (vical.rl.vector)
    policy_lag: int = 4  # with num_envs > 1: rounds between the network that samples an action and the newest
    buffer_size: int = 1_000_000
    eval_every: int = 2_000
    eval_episodes: int = 5
    eval_max_episode_steps: int = 10_000  # ends an evaluation episode of an env without a time limit
    log_every: int = 100
    plot_every_episodes: int = 10
    checkpoint_every: int = 1_000
    progress: bool = True
    info_prefixes: list[str] = field(default_factory=lambda: ["calib/", "coverage/", "reward/", "information/"])

    def __post_init__(self) -> None:
        for name in ("total_steps", "updates_per_step", "buffer_size", "eval_episodes", "eval_max_episode_steps"):
            _require_int(f"train.{name}", getattr(self, name), 1)
        n = self.num_envs
        ok = isinstance(n, int) and not isinstance(n, bool) and 1 <= n <= MAX_WORKERS
        require(ok, "train.num_envs", f"an integer from 1 to {MAX_WORKERS} (env worker processes)", n)
        _require_int("train.policy_lag", self.policy_lag, 1)
        require(
            self.policy_lag <= MAX_POLICY_LAG, "train.policy_lag", f"at most {MAX_POLICY_LAG} rounds", self.policy_lag
        )
        for name in ("warmup_steps", "eval_every", "log_every", "plot_every_episodes", "checkpoint_every"):
            _require_int(f"train.{name}", getattr(self, name), 0)
        self.info_prefixes = list(self.info_prefixes)


def _require_int(key: str, value: Any, low: int) -> None:
    require(isinstance(value, int) and not isinstance(value, bool), key, "an integer", value)
    require_range(key, value, low)


@dataclass
class RunSettings:
    """The validated root config of ``vical-train`` (``env`` stays a mapping for ``instantiate``)."""

    seed: int
    torch_threads: int
    run_dir: Path
    resume: Path | None
    agent: SACConfig
    train: TrainConfig
    env: dict
    parallel: ParallelConfig = field(default_factory=ParallelConfig)

    def effective_config(self) -> dict:
        """Every setting with defaults filled in, as plain containers (the run's config.yaml)."""
        return {
            "seed": self.seed,
            "torch_threads": self.torch_threads,
            "run_dir": str(self.run_dir),
            "resume": None if self.resume is None else str(self.resume),
            "agent": asdict(self.agent),
            "train": asdict(self.train),
            "env": self.env,
            "parallel": asdict(self.parallel),
        }


def parse_settings(cfg: Mapping[str, Any]) -> RunSettings:
    """Validate the root config; out-of-range or unknown settings raise ``ConfigError`` naming the key."""
    _require_int("seed", cfg.get("seed"), 0)
    _require_int("torch_threads", cfg.get("torch_threads"), 1)
    env = cfg.get("env")
    require(isinstance(env, Mapping) and "_target_" in env, "env", "a mapping with a _target_ (env factory)", env)
    resume = cfg.get("resume")
    run_dir = resume if resume else cfg.get("run_dir")
    require(bool(run_dir), "run_dir", "a directory path (or set resume=<run dir>)", run_dir)
    return RunSettings(
        seed=cfg["seed"],
        torch_threads=cfg["torch_threads"],
        run_dir=Path(run_dir),
        resume=Path(resume) if resume else None,
        agent=from_mapping(SACConfig, cfg.get("agent", {}), "agent"),
        train=from_mapping(TrainConfig, cfg.get("train", {}), "train"),
        env=dict(env),
        parallel=ParallelConfig.from_config(cfg.get("parallel")),
    )


class TrainingDivergedError(FloatingPointError):
    """A loss, observation or reward became NaN/inf; the message names the step and the term."""


class BoxActions:
    """Maps policy actions in ``[-1, 1]^d`` affinely onto a gymnasium Box's ``[low, high]``."""

    def __init__(self, space: gym.Space) -> None:
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ConfigError(f"env action space must be a 1-D gymnasium Box, got {space}")
        if not (np.all(np.isfinite(space.low)) and np.all(np.isfinite(space.high))):
            raise ConfigError(f"env action space must have finite bounds for a tanh policy, got {space}")
        self.low = space.low.astype(np.float64)
        self.half_range = 0.5 * (space.high.astype(np.float64) - self.low)
        self.dtype = space.dtype

    def to_env(self, action: np.ndarray) -> np.ndarray:
        return (self.low + (action + 1.0) * self.half_range).astype(self.dtype)


def make_env(env_cfg: Mapping[str, Any]) -> gym.Env:
    """Instantiate the env config (``_target_`` + kwargs) and check its observation space."""
    env = hydra.utils.instantiate(env_cfg)
    space = env.observation_space
    if not isinstance(space, gym.spaces.Box):
        raise ConfigError(f"env observation space must be a gymnasium Box, got {space} from {env_cfg['_target_']}")
    return env


@dataclass
class Episode:
    """The running episode: observations ``(T + 1, obs_dim)`` and actions ``(T, act_dim)`` in policy units."""

    observations: list[np.ndarray]
    actions: list[np.ndarray] = field(default_factory=list)
    total_reward: float = 0.0


@dataclass
class TrainResult:
    run_dir: Path
    agent: SAC
    steps: int
    episodes: int
    updates: int  # gradient updates (each updates every network once)
    last_eval_return: float | None
    resumed_from: int | None  # the checkpoint's step when the run was resumed


class Trainer:
    """Owns the env, agent, buffer, generators and counters of one run; :meth:`run` trains to the end."""

    def __init__(self, cfg: Mapping[str, Any]) -> None:
        raw = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
        s = self.settings = parse_settings(raw)
        self.config = s.effective_config()  # defaults filled in: what config.yaml, checkpoints and resume compare
        torch.set_num_threads(s.torch_threads)
        self.env = make_env(s.env)
        self._eval_env: gym.Env | None = None  # built at the first evaluation
        self.actions = BoxActions(self.env.action_space)
        obs_dim = int(np.prod(self.env.observation_space.shape))
        act_dim = self.act_dim = self.env.action_space.shape[0]
        # Seeding happens here and only here: the trainer's numpy Generator (warm-up actions, replay
        # sampling, episode reset seeds) and the agent's torch Generator (initial weights, policy noise).
        self.rng = np.random.default_rng(s.seed)
        self.agent = SAC(obs_dim, act_dim, s.agent, seed=s.seed)
        self.buffer = ReplayBuffer(s.train.buffer_size, obs_dim, act_dim)
        self.step = self.episode = self.updates = self.last_checkpoint_step = 0
        self.last_eval_return: float | None = None
        self.resumed_from: int | None = None
        self._stats: dict[str, torch.Tensor] = {}
        if s.resume:
            self._restore(load_checkpoint(s.resume / CHECKPOINT))
        self._open_run_dir()

    def _open_run_dir(self) -> None:
        """Create the run directory with its config.yaml and TensorBoard log (the last step before the run)."""
        s = self.settings
        s.run_dir.mkdir(parents=True, exist_ok=True)
        write_text_atomic(s.run_dir / "config.yaml", OmegaConf.to_yaml(self.config))
        # The checkpoint at step S is written after everything logged at step S: keep those events and
        # purge only what the interrupted run logged after its checkpoint (steps > S).
        purge = None if self.resumed_from is None else self.resumed_from + 1
        self.logger = TrainLogger(s.run_dir / "tb", s.train.info_prefixes, purge_step=purge)

    # ---- the loop -------------------------------------------------------------------------------
    def run(self) -> TrainResult:
        t = self.settings.train
        if self.step == 0:
            self.logger.hyperparameters(flatten(self.config))
        self._clock = (time.perf_counter(), self.step, self.updates)
        bar = tqdm(total=t.total_steps, initial=self.step, disable=not t.progress, desc="vical-train", unit="step")
        episode = self._start_episode()
        try:
            while self.step < t.total_steps:
                episode_over = self._env_step(episode)
                self._train_and_evaluate()
                bar.update(1)
                if episode_over:
                    self._end_episode(episode, bar)
                    if self.step < t.total_steps:
                        episode = self._start_episode()
            self._write_agent()
        finally:
            bar.close()
            self.logger.close()
            for env in (self.env, self._eval_env):
                if env is not None:
                    env.close()  # envs may hold renderers or simulator handles
        return TrainResult(
            self.settings.run_dir,
            self.agent,
            self.step,
            self.episode,
            self.updates,
            self.last_eval_return,
            self.resumed_from,
        )

    def _start_episode(self) -> Episode:
        obs, _ = self.env.reset(seed=int(self.rng.integers(2**31 - 1)))
        return Episode([self._checked_obs(obs, "reset observation")])

    def _env_step(self, episode: Episode) -> bool:
        """Act, step the env, store the transition; True when the episode ended (terminated or truncated)."""
        obs = episode.observations[-1]
        if self.step < self.settings.train.warmup_steps:
            action = self.rng.uniform(-1.0, 1.0, self.act_dim).astype(np.float32)
        else:
            action = self.agent.act(obs)
        next_obs, reward, terminated, truncated, info = self.env.step(self.actions.to_env(action))
        next_obs = self._checked_obs(next_obs, "observation")
        if not np.isfinite(reward):
            self._diverged("reward", float(reward), self.step + 1)
        self.buffer.add(obs, action, float(reward), next_obs, bool(terminated), transition_discount(info))
        self.step += 1
        episode.observations.append(next_obs)
        episode.actions.append(action)
        episode.total_reward += float(reward)
        self.logger.env_info(info, self.step)
        return bool(terminated or truncated)

    def _train_and_evaluate(self) -> None:
        t = self.settings.train
        if self.step > t.warmup_steps:  # as stable-baselines3: the first update follows warm-up step + 1
            for _ in range(t.updates_per_step):
                self._update()
        if t.log_every and self.step % t.log_every == 0:
            self._log_progress()
        if t.eval_every and self.step % t.eval_every == 0:
            self._evaluate()

    def _update(self) -> None:
        """One gradient update of every network on a batch sampled with the trainer's generator."""
        try:
            self._stats = self.agent.update(self.buffer.sample(self.agent.config.batch_size, self.rng))
        except NonFiniteLossError as err:
            self._diverged(err.term, err.value, self.step)
        self.updates += 1

    def _end_episode(self, episode: Episode, bar: tqdm) -> None:
        t = self.settings.train
        self._log_episode(episode, bar)
        if t.checkpoint_every and self.step - self.last_checkpoint_step >= t.checkpoint_every:
            self.last_checkpoint_step = self.step
            save_checkpoint(self._state(), self.settings.run_dir / CHECKPOINT)

    def _log_episode(self, episode: Episode, bar: tqdm) -> None:
        t = self.settings.train
        self.episode += 1
        charts = {"charts/episodic_return": episode.total_reward, "charts/episodic_length": len(episode.actions)}
        self.logger.scalars(charts, self.step)
        if t.plot_every_episodes and self.episode % t.plot_every_episodes == 0:
            observations, actions = np.stack(episode.observations), np.stack(episode.actions)
            self.logger.trajectory(self._plot_env(), observations, actions, self.step)
        bar.set_postfix(
            episode=self.episode,
            ret=f"{episode.total_reward:.1f}",
            eval="-" if self.last_eval_return is None else f"{self.last_eval_return:.1f}",
            upd_s=f"{self._rates()[1]:.0f}",
        )

    def _plot_env(self) -> gym.Env:
        """The env whose ``trajectory_figure`` draws the episodes (the training env)."""
        return self.env

    # ---- evaluation and logging -----------------------------------------------------------------
    def _evaluate(self) -> None:
        """Deterministic (mean-action) returns on ``eval_episodes`` fixed-seed episodes of the eval env."""
        t = self.settings.train
        returns = [self._eval_episode(self.settings.seed + EVAL_SEED_OFFSET + i) for i in range(t.eval_episodes)]
        self.last_eval_return = float(np.mean(returns))
        self.logger.scalars(
            {"charts/eval_return_mean": self.last_eval_return, "charts/eval_return_std": float(np.std(returns))},
            self.step,
        )

    def _eval_episode(self, seed: int) -> float:
        if self._eval_env is None:
            self._eval_env = make_env(self.settings.env)
        obs, _ = self._eval_env.reset(seed=seed)
        total = 0.0
        for _ in range(self.settings.train.eval_max_episode_steps):
            action = self.agent.act(np.asarray(obs, np.float32).ravel(), deterministic=True)
            obs, reward, terminated, truncated, _ = self._eval_env.step(self.actions.to_env(action))
            total += float(reward)
            if terminated or truncated:
                break
        return total

    def _rates(self) -> tuple[float, float]:
        """Env steps and gradient updates per second of wall time since this process started training."""
        start, step0, updates0 = self._clock
        elapsed = max(time.perf_counter() - start, 1e-9)
        return (self.step - step0) / elapsed, (self.updates - updates0) / elapsed

    def _log_progress(self) -> None:
        steps_s, updates_s = self._rates()
        values = {"time/steps_per_second": steps_s, "time/updates_per_second": updates_s}
        values.update({k: float(v) for k, v in self._stats.items()})
        self.logger.scalars(values, self.step)

    # ---- checkpoints ----------------------------------------------------------------------------
    def _state(self) -> dict:
        return {
            "config": self.config,
            "agent": self.agent.training_state(),
            "buffer": self.buffer.state_dict(),
            "rng": self.rng.bit_generator.state,
            "counters": {
                "step": self.step,
                "episode": self.episode,
                "updates": self.updates,
                "last_checkpoint_step": self.last_checkpoint_step,
            },
        }

    def _restore(self, state: dict) -> None:
        require_compatible(state["config"], self.config, self.settings.resume / CHECKPOINT)
        _require_reachable(self.settings.train.total_steps, state["counters"]["step"], self.settings.resume)
        self.agent.load_training_state(state["agent"])
        self.buffer.load_state_dict(state["buffer"])
        self.rng.bit_generator.state = state["rng"]
        counters = state["counters"]
        self.step, self.episode = counters["step"], counters["episode"]
        self.updates, self.last_checkpoint_step = counters["updates"], counters["last_checkpoint_step"]
        self.resumed_from = self.step
        log.info("resumed %s from step %d (episode %d)", self.settings.resume, self.step, self.episode)

    def _write_agent(self) -> None:
        state = {"model": self.agent.state_dict(), "agent_config": asdict(self.agent.config), "config": self.config}
        save_checkpoint(state, self.settings.run_dir / AGENT)

    def _checked_obs(self, obs: Any, term: str) -> np.ndarray:
        obs = np.asarray(obs, np.float32).ravel()
        if not np.all(np.isfinite(obs)):
            bad = np.flatnonzero(~np.isfinite(obs)).tolist()
            self._diverged(f"{term} (components {bad})", float(obs[bad[0]]), self.step + 1)
        return obs

    def _diverged(self, term: str, value: float, step: int) -> None:
        """Write the last good state (before the failing update/transition) and stop with a clear message.

        ``step``: the env step (1-based) that produced the value, or after which the failing update ran.
        """
        path = self.settings.run_dir / LAST_GOOD
        save_checkpoint(self._state(), path)
        raise TrainingDivergedError(
            f"training stopped at step {step}: {term} is {value}. The state just before it is in {path}; "
            f"the run resumes from its last episode-boundary checkpoint ({self.settings.run_dir / CHECKPOINT}). "
            "Check the env's observations/rewards for NaN/inf, or lower agent.lr."
        )


def _require_reachable(total_steps: int, step: int, run_dir: Path) -> None:
    """Refuse a ``total_steps`` below the checkpoint's ``step``: resuming would overwrite later work with earlier."""
    if total_steps < step:
        raise ConfigError(
            f"train.total_steps={total_steps} is below step {step} of the checkpoint {run_dir / CHECKPOINT}: the run "
            f"is past it already; resume with train.total_steps >= {step}"
        )


def checkpoint_step(run_dir: str | Path) -> int | None:
    """The step of the run's checkpoint, None when it has none (its tensors are mapped, not read)."""
    path = Path(run_dir) / CHECKPOINT
    return int(load_checkpoint(path, mmap=True)["counters"]["step"]) if path.is_file() else None


def resume_status(run_dir: str | Path, total_steps: int) -> str | None:
    """Whether the run at ``run_dir`` can go on to ``total_steps``: None when it can (from its checkpoint), a
    message when it is complete at that length already (nothing to do).

    A finished run (``agent.pt`` written at the end, no later checkpoint) asked for more steps goes on from
    its last checkpoint: the steps after it are run again, identically, so the result equals a run of
    ``total_steps`` from the start.

    Raises:
        ConfigError: the run would be shortened, or it has no checkpoint to go on from.
    """
    run = Path(run_dir)
    checkpoint = checkpoint_step(run)
    agent = run / AGENT
    finished = int(load_checkpoint(agent, mmap=True)["config"]["train"]["total_steps"]) if agent.is_file() else None
    if finished is not None and (checkpoint is None or checkpoint <= finished):
        if total_steps == finished:
            return f"run {run} is complete: it trained {finished} steps and wrote {agent}; nothing to do"
        if total_steps < finished:
            raise ConfigError(
                f"train.total_steps={total_steps} is below the {finished} steps run {run} finished with: a run cannot "
                f"be shortened (its agent is {agent}); start a new run for a shorter one"
            )
        if checkpoint is None:
            raise ConfigError(
                f"run {run} finished at {finished} steps without a checkpoint to go on from (train.checkpoint_every); "
                f"start a new run with train.total_steps={total_steps}"
            )
        return None
    if checkpoint is None:
        raise ConfigError(
            f"run {run} has no checkpoint yet (it stopped before its first one, at the first episode end after "
            "train.checkpoint_every steps): start it again"
        )
    _require_reachable(total_steps, checkpoint, run)
    return None


def train(cfg: Mapping[str, Any]) -> TrainResult:
    """Train SAC on the configured env (a Hydra ``DictConfig`` or a plain mapping; see ``conf/train.yaml``).

    ``train.num_envs > 1`` collects experience from that many env workers (``vical.rl.vector_trainer``).
    """
    raw = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
    if parse_settings(raw).train.num_envs > 1:
        from vical.rl.vector_trainer import VectorTrainer  # imported here: it subclasses Trainer

        return VectorTrainer(raw).run()
    return Trainer(raw).run()
