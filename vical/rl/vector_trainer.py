"""Training with ``train.num_envs`` environments in worker processes (``vical.rl.vector``).

The loop steps every env at once: one action per env (uniform during warm-up, else the policy's
sample for that env's observation, in env order); the envs step in their workers (an episode's
terminal work included) while the learner does ``num_envs * updates_per_step`` gradient updates on
the transitions stored before (once more than ``warmup_steps`` are stored), so ``updates_per_step``
keeps its meaning per collected transition and collecting overlaps with learning; then the
``num_envs`` new transitions go into the buffer in env order. An env whose episode ended is reset before the next step
with a seed drawn from the trainer's generator. Steps count transitions: logging, evaluation and
checkpoints happen when the count crosses a multiple of their interval, and a run may end up to
``num_envs - 1`` transitions past ``total_steps``.

A checkpoint can fall in the middle of episodes: it stores each running episode's reset seed and
actions, and a resumed run replays them in the workers to the same state (the env must be
deterministic given its seed and actions; the replayed observations are checked against the
stored ones). So a run killed and resumed equals the uninterrupted run, bit for bit, for the same
seed and ``num_envs``.
"""

from __future__ import annotations

import contextlib
import logging
import time
from dataclasses import dataclass, field

import numpy as np
import torch
from tqdm import tqdm

from vical.config import ConfigError
from vical.rl.checkpoint import flatten, save_checkpoint
from vical.rl.trainer import CHECKPOINT, Episode, Trainer, TrainResult, make_env
from vical.rl.vector import ERROR_KEY, SEED_KEY, make_vector_env, per_env_infos

log = logging.getLogger(__name__)


class WorkerDiedError(RuntimeError):
    """An environment worker process died; the message says from which checkpoint to resume."""


@dataclass
class RunningEpisode(Episode):
    """An episode in one env: its reset seed and the actions taken so far (to replay it on resume)."""

    seed: int = 0
    env_actions: list[np.ndarray] = field(default_factory=list)


class VectorTrainer(Trainer):
    """``Trainer`` with ``num_envs`` env workers (the env config is built in each worker)."""

    def __init__(self, cfg) -> None:
        self._restored_episodes: list[dict] | None = None
        self._worker_died = False
        super().__init__(cfg)  # restores a checkpoint's counters, buffer and generators
        self.env.close()  # the main process keeps its env only for the spaces: the workers step theirs
        self.num_envs = self.settings.train.num_envs
        self.vec = make_vector_env(make_env, self.settings.env, self.num_envs, self.settings.parallel)

    # ---- the loop -------------------------------------------------------------------------------
    def run(self) -> TrainResult:
        t = self.settings.train
        if self.step == 0:
            self.logger.hyperparameters(flatten(self.config))
        self._clock = (time.perf_counter(), self.step, self.updates)
        bar = tqdm(total=t.total_steps, initial=self.step, disable=not t.progress, desc="vical-train", unit="step")
        try:
            episodes = self._resume_episodes() if self._restored_episodes else self._start(range(self.num_envs), None)
            while self.step < t.total_steps:
                before = self.step
                done = self._vector_step(episodes)
                self._periodic(before)
                bar.update(self.num_envs)
                for i in np.flatnonzero(done):
                    self._log_episode(episodes[i], bar)
                if done.any() and self.step < t.total_steps:
                    episodes = self._start(np.flatnonzero(done), episodes)
                if t.checkpoint_every and self.step // t.checkpoint_every > before // t.checkpoint_every:
                    self._checkpoint(episodes)
            self._write_agent()
        finally:
            bar.close()
            self.logger.close()
            self._close_workers()
            if self._eval_env is not None:
                self._eval_env.close()
        return TrainResult(
            self.settings.run_dir, self.agent, self.step, self.episode, self.updates, self.last_eval_return,
            self.resumed_from,
        )  # fmt: skip

    def _start(self, envs, episodes: list[RunningEpisode] | None) -> list[RunningEpisode]:
        """Reset the envs ``envs`` (indices, in order) with seeds drawn from the trainer's generator."""
        episodes = list(episodes) if episodes is not None else [None] * self.num_envs
        seeds = [0] * self.num_envs
        mask = np.zeros(self.num_envs, dtype=bool)
        for i in envs:
            seeds[i], mask[i] = int(self.rng.integers(2**31 - 1)), True
        obs, _ = self._guarded(lambda: self.vec.reset(seed=seeds, options={"reset_mask": mask}))
        for i in envs:
            episodes[i] = RunningEpisode([self._checked_obs(obs[i], "reset observation")], seed=seeds[i])
        return episodes

    def _vector_step(self, episodes: list[RunningEpisode]) -> np.ndarray:
        """Act in every env, learn while they step, store their transitions in env order; which envs ended.

        The gradient updates of this vector step run while the envs step in their workers (on the
        transitions collected before it), so learning and collecting overlap.
        """
        warmup = self.step < self.settings.train.warmup_steps
        actions = [
            self.rng.uniform(-1.0, 1.0, self.act_dim).astype(np.float32)
            if warmup
            else self.agent.act(e.observations[-1])
            for e in episodes
        ]
        env_actions = np.stack([self.actions.to_env(a) for a in actions])
        self._guarded(lambda: self.vec.step_async(env_actions))
        self._updates()
        next_obs, rewards, terminated, truncated, infos = self._guarded(self.vec.step_wait)
        for i, (episode, info) in enumerate(zip(episodes, per_env_infos(infos, self.num_envs), strict=True)):
            obs = self._checked_obs(next_obs[i], "observation")
            if not np.isfinite(rewards[i]):
                self._diverged("reward", float(rewards[i]), self.step + 1)
            self.buffer.add(episode.observations[-1], actions[i], float(rewards[i]), obs, bool(terminated[i]))
            self.step += 1
            episode.observations.append(obs)
            episode.actions.append(actions[i])
            episode.env_actions.append(env_actions[i])
            episode.total_reward += float(rewards[i])
            if ERROR_KEY in info:
                log.warning(
                    "env %d, episode seed %s: %s; the episode was cut short", i, info[SEED_KEY], info[ERROR_KEY]
                )
            self.logger.env_info(info, self.step)
        return np.asarray(terminated) | np.asarray(truncated)

    def _updates(self) -> None:
        """``num_envs * updates_per_step`` updates once more than ``warmup_steps`` transitions are stored."""
        t = self.settings.train
        if self.step > t.warmup_steps:
            for _ in range(t.updates_per_step * self.num_envs):
                self._update()

    def _periodic(self, before: int) -> None:
        """Logging and evaluation when the step count crossed a multiple of their interval."""
        t = self.settings.train
        if t.log_every and self.step // t.log_every > before // t.log_every:
            self._log_progress()
        if t.eval_every and self.step // t.eval_every > before // t.eval_every:
            self._evaluate()

    def _close_workers(self) -> None:
        """Stop the env workers; after one died, the others are terminated (closing politely would wait on it)."""
        if not self._worker_died:
            self.vec.close()
            return
        for process in getattr(self.vec, "processes", []):  # AsyncVectorEnv's; Ray actors are killed by close
            process.terminate()
        with contextlib.suppress(EOFError, BrokenPipeError, ConnectionResetError, OSError):
            self.vec.close(terminate=True)
        self.vec.closed = True

    def _plot_env(self):
        if self._eval_env is None:
            self._eval_env = make_env(self.settings.env)
        return self._eval_env

    def _guarded(self, call):
        """A vector-env call; a worker process that died becomes ``WorkerDiedError`` (never a hang)."""
        try:
            return call()
        except (EOFError, BrokenPipeError, ConnectionResetError) as err:
            self._worker_died = True
            raise WorkerDiedError(self._died_message()) from err
        except Exception as err:
            if type(err).__name__ in ("WorkerCrashedError", "RayActorError", "ActorDiedError"):
                self._worker_died = True
                raise WorkerDiedError(self._died_message()) from err
            raise

    def _died_message(self) -> str:
        if not self.last_checkpoint_step:
            at = "there is no checkpoint yet: start the run again"
        else:
            resume = f"vical-train resume={self.settings.run_dir}"
            at = f"resume from its checkpoint at step {self.last_checkpoint_step}: {resume}"
        return f"an environment worker process died (killed, or out of memory) at step {self.step}; {at}"

    # ---- checkpoints ----------------------------------------------------------------------------
    def _checkpoint(self, episodes: list[RunningEpisode]) -> None:
        self.last_checkpoint_step = self.step
        state = self._state()
        state["episodes"] = [
            {
                "seed": e.seed,
                "total_reward": e.total_reward,
                "observations": _tensor(e.observations),
                "actions": _tensor(e.actions),
                "env_actions": _tensor(e.env_actions),
            }
            for e in episodes
        ]
        save_checkpoint(state, self.settings.run_dir / CHECKPOINT)

    def _restore(self, state: dict) -> None:
        super()._restore(state)
        if "episodes" not in state:
            raise ConfigError(f"{self.settings.resume / CHECKPOINT} holds no env workers' episodes (train.num_envs=1?)")
        self._restored_episodes = state["episodes"]

    def _resume_episodes(self) -> list[RunningEpisode]:
        """Replay every env's running episode in its worker; check that it reaches the stored observation."""
        saved = [
            {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in s.items()} for s in self._restored_episodes
        ]
        self._guarded(lambda: self.vec.set_attr("replay_script", [(s["seed"], list(s["env_actions"])) for s in saved]))
        reached = self._guarded(lambda: self.vec.call("replay"))
        episodes = []
        for i, s in enumerate(saved):
            if not np.array_equal(np.asarray(reached[i], np.float32).ravel(), s["observations"][-1]):
                raise ConfigError(
                    f"env {i} did not replay to its checkpointed state (its episode of seed {s['seed']}): the env is "
                    "not deterministic given its seed and actions, so this run cannot resume exactly"
                )
            episode = RunningEpisode(list(s["observations"]), list(s["actions"]), s["total_reward"], seed=s["seed"])
            episode.env_actions = list(s["env_actions"])
            episodes.append(episode)
        return episodes


def _tensor(rows: list[np.ndarray]) -> torch.Tensor:
    """Rows (T, d) as a tensor (checkpoints hold tensors only); (0, 0) for none."""
    return torch.from_numpy(np.stack(rows)) if rows else torch.zeros((0, 0))
