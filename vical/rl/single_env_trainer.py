"""The training loop with one env in this process: environment interaction, SAC updates, evaluation, TensorBoard,
checkpoints and exact resume (``vical.rl.vector_trainer`` extends it to env workers).

The env is built from the ``env`` config (``vical.rl.envs.make_env``). Exact resume rests on three choices:
- every random draw comes from the trainer's numpy Generator or the agent's torch Generator, both seeded
  here from ``seed`` and saved in the checkpoint;
- each episode's env is reset with a seed drawn from the trainer's Generator, so no env state needs saving;
- checkpoints are written at episode boundaries only.
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from vical.io.atomic import write_text_atomic
from vical.parallel import imap_ordered
from vical.rl.buffer import ReplayBuffer, transition_discount
from vical.rl.checkpoint import (
    AGENT,
    CHECKPOINT,
    LAST_GOOD,
    flatten,
    load_checkpoint,
    require_compatible,
    require_reachable,
    save_checkpoint,
)
from vical.rl.demonstrations import demonstrated_action, make_demonstrator, start_demonstration
from vical.rl.distill import fit_policy, rollout, rollout_jobs
from vical.rl.envs import BoxActions, make_env
from vical.rl.logger import TrainLogger
from vical.rl.run_settings import parse_settings
from vical.rl.sac import SAC, NonFiniteLossError

log = logging.getLogger(__name__)

EVAL_SEED_OFFSET = 1_000_000  # evaluation episodes reset with seed + offset + i: the same starts every time


class TrainingDivergedError(FloatingPointError):
    """A loss, observation or reward became NaN/inf; the message names the step and the term."""


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
        self.demonstrator = make_demonstrator(s.train.demonstrator)  # built here too: a bad one fails at the start
        obs_dim = int(np.prod(self.env.observation_space.shape))
        act_dim = self.act_dim = self.env.action_space.shape[0]
        # Seeding happens here and only here: the trainer's numpy Generator (warm-up actions, replay
        # sampling, episode reset seeds) and the agent's torch Generator (initial weights, policy noise).
        self.rng = np.random.default_rng(s.seed)
        self.agent = SAC(obs_dim, act_dim, s.agent, seed=s.seed)
        self.buffer = ReplayBuffer(s.train.buffer_size, obs_dim, act_dim)
        self.step = self.episode = self.updates = self.last_checkpoint_step = 0
        self.distill_round = 0  # DAgger rounds done (train.distill), and every label they gathered
        self.distill_obs, self.distill_labels = np.zeros((0, obs_dim), np.float32), np.zeros((0, act_dim), np.float32)
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
        self._log_start()
        if self.step == 0:
            self.logger.hyperparameters(flatten(self.config))
        self._distill()
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

    def _distill(self) -> None:
        """The DAgger rounds of ``train.distill`` not yet done (``vical.rl.distill``), a checkpoint after each: their
        transitions join the buffer, the policy is fitted to every label so far. SAC's steps follow."""
        s = self.settings
        d = s.train.distill
        if d is None:
            return
        parallel = dataclasses.replace(s.parallel, workers=s.train.num_envs)
        while self.distill_round < d.rounds:
            beta = d.beta**self.distill_round
            seeds = self.rng.integers(2**31 - 1, size=d.episodes)
            jobs = rollout_jobs(s.env, s.train.demonstrator, self.agent.policy, seeds, beta)
            bar = tqdm(total=len(jobs), disable=not s.train.progress, unit="episode",
                       desc=f"vical-train: distillation round {self.distill_round + 1}/{d.rounds}")  # fmt: skip
            rollouts = []
            for r in imap_ordered(rollout, jobs, parallel):
                rollouts.append(r)
                bar.update(1)
            bar.close()
            for r in rollouts:
                for k in range(len(r.obs)):
                    self.buffer.add(r.obs[k], r.actions[k], float(r.rewards[k]), r.next_obs[k], bool(r.terminated[k]),
                                    float(r.discounts[k]))  # fmt: skip
            self.distill_obs = np.concatenate([self.distill_obs, *(r.obs for r in rollouts)])
            self.distill_labels = np.concatenate([self.distill_labels, *(r.labels for r in rollouts)])
            loss = fit_policy(self.agent.policy, self.distill_obs, self.distill_labels, d, self.agent.generator)
            self.distill_round += 1
            self._log_distillation(rollouts, beta, loss)
            save_checkpoint(self._state(), s.run_dir / CHECKPOINT)

    def _log_distillation(self, rollouts: list, beta: float, loss: float) -> None:
        values = {
            "distill/beta": beta,
            "distill/labels": float(len(self.distill_labels)),
            "distill/fit_loss": loss,
            "distill/episodic_return": float(np.mean([r.total_reward for r in rollouts])),
            "distill/episodic_length": float(np.mean([len(r.obs) for r in rollouts])),
            "distill/terminated": float(np.mean([r.reached for r in rollouts])),
        }
        self.logger.scalars(values, self.distill_round)
        log.info("distillation round %d of %d: %d labels, fit loss %.4f; episodes (teacher's action with probability "
                 "%.3g): return %.1f, %.1f steps, %.0f %% terminated", self.distill_round,
                 self.settings.train.distill.rounds, values["distill/labels"], loss, beta,
                 values["distill/episodic_return"], values["distill/episodic_length"],
                 100 * values["distill/terminated"])  # fmt: skip

    def _start_episode(self) -> Episode:
        seed = int(self.rng.integers(2**31 - 1))
        obs, _ = self.env.reset(seed=seed)
        if self.demonstrator is not None:
            start_demonstration(self.demonstrator, self.env, seed)
        return Episode([self._checked_obs(obs, "reset observation")])

    def _env_step(self, episode: Episode) -> bool:
        """Act, step the env, store the transition; True when the episode ended (terminated or truncated)."""
        obs = episode.observations[-1]
        warm_up = self.step < self.settings.train.warmup_steps
        if warm_up and self.demonstrator is not None:
            env_action = demonstrated_action(self.demonstrator, self.env, obs)
            action = self.actions.to_policy(env_action)
        else:
            action = self.rng.uniform(-1.0, 1.0, self.act_dim).astype(np.float32) if warm_up else self.agent.act(obs)
            env_action = self.actions.to_env(action)
        next_obs, reward, terminated, truncated, info = self.env.step(env_action)
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
            self._clone_demonstrations()
            for _ in range(t.updates_per_step):
                self._update()
        if t.log_every and self.step % t.log_every == 0:
            self._log_progress()
        if t.eval_every and self.step % t.eval_every == 0:
            self._evaluate()

    def _clone_demonstrations(self) -> None:
        """Before the run's first update: ``train.clone_updates`` updates cloning the demonstrations (the buffer
        holds only the warm-up's steps then: the demonstrator's)."""
        clone_updates = self.settings.train.clone_updates
        if self.updates or not clone_updates:
            return
        log.info("step %d: cloning the demonstrator's %d steps (%d updates)", self.step, self.step, clone_updates)
        for _ in range(clone_updates):
            self._update(clone=True)

    def _update(self, clone: bool = False) -> None:
        """One gradient update of every network on a batch sampled with the trainer's generator (``clone``: the
        policy clones the batch's actions, ``SAC.losses``)."""
        try:
            self._stats = self.agent.update(self.buffer.sample(self.agent.config.batch_size, self.rng), clone)
        except NonFiniteLossError as err:
            self._diverged(err.term, err.value, self.step)
        self.updates += 1

    def _end_episode(self, episode: Episode, bar: tqdm) -> None:
        t = self.settings.train
        self._log_episode(episode, bar)
        if t.checkpoint_every and self.step - self.last_checkpoint_step >= t.checkpoint_every:
            self.last_checkpoint_step = self.step
            save_checkpoint(self._state(), self.settings.run_dir / CHECKPOINT)
            self._log_checkpoint()

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
        log.info("step %d: evaluation return %.3f (std %.3f over %d episodes)", self.step, self.last_eval_return,
                 float(np.std(returns)), len(returns))  # fmt: skip
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
            "distill": {
                "round": self.distill_round,
                "obs": torch.from_numpy(self.distill_obs),
                "labels": torch.from_numpy(self.distill_labels),
            },  # tensors: read back with weights_only
            "counters": {
                "step": self.step,
                "episode": self.episode,
                "updates": self.updates,
                "last_checkpoint_step": self.last_checkpoint_step,
            },
        }

    def _restore(self, state: dict) -> None:
        require_compatible(state["config"], self.config, self.settings.resume / CHECKPOINT)
        require_reachable(self.settings.train.total_steps, state["counters"]["step"], self.settings.resume)
        self.agent.load_training_state(state["agent"])
        self.buffer.load_state_dict(state["buffer"])
        self.rng.bit_generator.state = state["rng"]
        if "distill" in state:  # a run's checkpoint since train.distill (none before: no rounds done)
            distill = state["distill"]
            self.distill_round = int(distill["round"])
            self.distill_obs, self.distill_labels = distill["obs"].numpy(), distill["labels"].numpy()
        counters = state["counters"]
        self.step, self.episode = counters["step"], counters["episode"]
        self.updates, self.last_checkpoint_step = counters["updates"], counters["last_checkpoint_step"]
        self.resumed_from = self.step
        log.info("resumed %s from step %d (episode %d)", self.settings.resume, self.step, self.episode)

    def _write_agent(self) -> None:
        state = {"model": self.agent.state_dict(), "agent_config": asdict(self.agent.config), "config": self.config}
        save_checkpoint(state, self.settings.run_dir / AGENT)
        elapsed = time.perf_counter() - self._clock[0]
        log.info("trained %d steps, %d episodes (%.0f s in this process): the agent is %s", self.step, self.episode,
                 elapsed, self.settings.run_dir / AGENT)  # fmt: skip

    # ---- train.log (Hydra writes the vical loggers' records into the run directory) ---------------
    def _log_start(self) -> None:
        s = self.settings
        start = "from scratch" if self.resumed_from is None else f"resumed from step {self.resumed_from}"
        log.info("training %d steps in %s (%s, seed %d, %d env(s))", s.train.total_steps, s.run_dir, start, s.seed,
                 s.train.num_envs)  # fmt: skip

    def _log_checkpoint(self) -> None:
        log.info("step %d: checkpoint written: %s", self.step, self.settings.run_dir / CHECKPOINT)

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
