"""Training with ``train.num_envs`` environments in worker processes (``vical.rl.vector``).

The envs step independently: a worker gets its next action as soon as it answers, so a fast env never
waits for a slow one, while the run stays a function of its seed and ``num_envs``. Transitions are
numbered by *round*: round ``r`` holds every env's ``r``-th step. The learner takes rounds in order:
it stores round ``r``'s transitions in env order, then does ``num_envs * updates_per_step`` gradient
updates (once more than ``warmup_steps`` transitions are stored; so ``updates_per_step`` keeps its
meaning per collected transition), and the network after them is *version* ``r``. An env's action of
round ``r`` is sampled from version ``r - policy_lag`` (uniform during warm-up, or the demonstrator's, which acts
in the worker: ``vical.rl.demonstrations``), with noise drawn from a
generator keyed by (seed, env, round), and an env's episode ``e`` is reset with a seed keyed by (seed,
env, e): which env answers first never changes a number. An env may thus run up to ``policy_lag - 1``
rounds ahead of the slowest one. Logging, evaluation and checkpoints happen after a round's updates,
when the step count (transitions stored) crossed a multiple of their interval; a run may end up to
``num_envs - 1`` transitions past ``total_steps``.

A checkpoint (after round ``r``) can fall in the middle of episodes: it stores each env's running
episode (reset seed and actions) and the network versions that the next rounds act with; a resumed
run replays the episodes in the workers to the same state (the env must be deterministic given its
seed and actions; the replayed observations are checked against the stored ones). So a run killed
and resumed equals the uninterrupted run, bit for bit, for the same seed and ``num_envs``.
"""

from __future__ import annotations

import copy
import logging
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from tqdm import tqdm

from vical.config_checks import ConfigError
from vical.rl.buffer import transition_discount
from vical.rl.checkpoint import CHECKPOINT, flatten, save_checkpoint
from vical.rl.envs import make_env
from vical.rl.single_env_trainer import Episode, Trainer, TrainResult
from vical.rl.vector import ERROR_KEY, SEED_KEY, WorkerDied, WorkerError, make_workers

log = logging.getLogger(__name__)

# Streams of the keyed generators (the first word of the key after the seed).
_ACTION_NOISE, _WARMUP_ACTION, _RESET_SEED = 1, 2, 3
_INITIAL_VERSION = -1  # the network before any round (version r: after round r's updates)


class WorkerDiedError(RuntimeError):
    """An environment worker process died; the message says from which checkpoint to resume."""


class EnvWorkerError(RuntimeError):
    """An env raised outside a step (its reset, a replay on resume); the message names its seed and the checkpoint."""


@dataclass
class RunningEpisode(Episode):
    """An episode in one env as stored so far: its reset seed and the actions taken (to replay it on resume)."""

    seed: int = 0
    index: int = 0  # the env's episode count before it (its reset seed is keyed by it)
    env_actions: list[np.ndarray] = field(default_factory=list)


@dataclass
class Step:
    """One env's answer to a step (and, when its episode ended and the run goes on, the next reset)."""

    action: np.ndarray
    env_action: np.ndarray
    obs: np.ndarray
    reward: float
    terminated: bool
    truncated: bool
    info: dict[str, Any]
    reset: RunningEpisode | None = None  # the env's next episode, as reset

    @property
    def ended(self) -> bool:
        return self.terminated or self.truncated


@dataclass
class Worker:
    """What one env's worker is doing: the round of its next step and the observation to act on."""

    round: int
    obs: np.ndarray | None  # None while a step or a reset is in flight
    episodes_started: int
    # (policy units, env units) of the step in flight; None while the demonstrator's step is (it answers its action)
    action: tuple[np.ndarray, np.ndarray] | None = None
    reset: tuple[int, int] | None = None  # (seed, episode index) of the reset in flight


class PolicyVersions:
    """The policy network after each recent round, for sampling actions ``policy_lag`` rounds behind."""

    def __init__(self, policy: torch.nn.Module) -> None:
        self._acting = copy.deepcopy(policy)
        self._loaded: int | None = None
        self.states: dict[int, dict[str, torch.Tensor]] = {}

    def keep(self, version: int, policy: torch.nn.Module) -> None:
        self.states[version] = {k: v.detach().clone() for k, v in policy.state_dict().items()}

    def forget_before(self, version: int) -> None:
        for old in [v for v in self.states if v < version]:
            del self.states[old]

    @torch.no_grad()
    def sample(self, version: int, obs: np.ndarray, generator: torch.Generator) -> np.ndarray:
        if self._loaded != version:
            self._acting.load_state_dict(self.states[version])
            self._loaded = version
        action, _ = self._acting.sample(torch.tensor(obs, dtype=torch.float32).unsqueeze(0), generator)
        return action[0].numpy()


class VectorTrainer(Trainer):
    """``Trainer`` with ``num_envs`` env workers (the env config is built in each worker)."""

    def __init__(self, cfg) -> None:
        self._restored: dict | None = None
        self._worker_died = False
        super().__init__(cfg)  # restores a checkpoint's counters, buffer and generators; starts the workers
        self.env.close()  # the main process keeps its env only for the spaces: the workers step theirs
        t = self.settings.train
        self.num_envs, self.lag = t.num_envs, t.policy_lag
        self.total_rounds = -(-t.total_steps // self.num_envs)
        self.versions = PolicyVersions(self.agent.policy)

    def _open_run_dir(self) -> None:
        """The workers first: workers that cannot start (an unreachable or too small Ray cluster, an env that fails
        to build in them) stop the run before its directory holds anything."""
        self.workers = self._start_workers()
        try:
            super()._open_run_dir()
        except BaseException:
            self.workers.close(kill=True)
            raise

    def _start_workers(self):
        """The env workers, each with its env built; a worker that dies or raises meanwhile is one line."""
        s = self.settings
        try:
            return make_workers(make_env, s.env, s.train.num_envs, s.parallel, s.train.demonstrator)
        except WorkerDied as err:
            message = f"an environment worker process died while it started ({err}): run the command again"
            raise WorkerDiedError(message) from err
        except WorkerError as err:
            raise EnvWorkerError(str(err)) from err

    # ---- the loop -------------------------------------------------------------------------------
    def run(self) -> TrainResult:
        t = self.settings.train
        self._log_start()
        if self.step == 0:
            self.logger.hyperparameters(flatten(self.config))
        self._distill()
        self._clock = (time.perf_counter(), self.step, self.updates)
        self.bar = tqdm(total=t.total_steps, initial=self.step, disable=not t.progress, desc="vical-train", unit="step")
        try:
            self._guarded(self._start)
            while self.next_round < self.total_rounds:
                self._guarded(self._advance)
            self._write_agent()
        finally:
            self.bar.close()
            self.logger.close()
            self.workers.close(kill=self._worker_died)
            if self._eval_env is not None:
                self._eval_env.close()
        return TrainResult(
            self.settings.run_dir, self.agent, self.step, self.episode, self.updates, self.last_eval_return,
            self.resumed_from,
        )  # fmt: skip

    def _start(self) -> None:
        """Every env at the start of the round after the last one stored: reset, or replayed from a checkpoint."""
        self.next_round = self.step // self.num_envs  # every round before it is stored and learnt from
        self.results: dict[int, dict[int, Step]] = {}
        self.pending_updates = 0
        if self._restored is None:
            self.versions.keep(_INITIAL_VERSION, self.agent.policy)
            self.episodes = [RunningEpisode([]) for _ in range(self.num_envs)]
            self.live = [Worker(0, None, 0) for _ in range(self.num_envs)]
            for i in range(self.num_envs):
                self._reset(i)
        else:
            self._resume()

    def _advance(self) -> None:
        """One unit of work: dispatch the envs that can step, then an update, a stored round or an answer."""
        self._dispatch()
        if self.pending_updates:
            self._take(self.workers.receive(timeout=0))  # answers that arrived keep their envs busy
            self._update()
            self.pending_updates -= 1
            if not self.pending_updates:
                self._finish_round()
        elif len(self.results.get(self.next_round, {})) == self.num_envs:
            self._store_round()
        else:
            self._take(self.workers.receive())

    # ---- the workers ----------------------------------------------------------------------------
    def _dispatch(self) -> None:
        """Send its next action to every idle env whose round's policy version exists (and is in the run)."""
        for i, w in enumerate(self.live):
            if w.obs is None or w.round >= self.total_rounds or w.round - self.lag >= self.next_round:
                continue
            if self._demonstrated(w.round):
                w.action, w.reset, w.obs = None, None, None
                self.workers.send(i, "demonstrate")
                continue
            action = self._action(i, w.round, w.obs)
            w.action, w.reset, w.obs = (action, self.actions.to_env(action)), None, None
            self.workers.send(i, "step", w.action[1])

    def _demonstrated(self, round_: int) -> bool:
        """The round's actions are the demonstrator's (it has one, and the round is in the warm-up)."""
        return self.demonstrator is not None and round_ * self.num_envs < self.settings.train.warmup_steps

    def _action(self, i: int, round_: int, obs: np.ndarray) -> np.ndarray:
        seed = self.settings.seed
        if round_ * self.num_envs < self.settings.train.warmup_steps:
            rng = np.random.default_rng([seed, _WARMUP_ACTION, i, round_])
            return rng.uniform(-1.0, 1.0, self.act_dim).astype(np.float32)
        key = int(np.random.SeedSequence([seed, _ACTION_NOISE, i, round_]).generate_state(1, np.uint64)[0] >> 1)
        version = max(round_ - self.lag, _INITIAL_VERSION)
        return self.versions.sample(version, obs, torch.Generator().manual_seed(key))

    def _reset(self, i: int) -> None:
        w = self.live[i]
        key = np.random.SeedSequence([self.settings.seed, _RESET_SEED, i, w.episodes_started])
        w.reset, w.action = (int(key.generate_state(1)[0] % (2**31 - 1)), w.episodes_started), None
        w.episodes_started += 1
        self.workers.send(i, "reset", w.reset[0])

    def _take(self, answers: list[tuple[int, Any]]) -> None:
        """Record each answer: a reset gives the env its first observation, a step its round's transition."""
        for i, answer in answers:
            w = self.live[i]
            if w.reset is not None:
                (seed, index), obs = w.reset, self._checked_obs(answer[0], "reset observation")
                episode = RunningEpisode([obs], seed=seed, index=index)
                if w.round == 0:  # the run's first episode
                    self.episodes[i] = episode
                else:  # after the episode that ended in the env's last step
                    self.results[w.round - 1][i].reset = episode
                w.obs = obs
                continue
            if w.action is None:  # the demonstrator's step: its action first
                env_action, *answer = answer
                w.action = (self.actions.to_policy(env_action), np.asarray(env_action))
            obs, reward, terminated, truncated, info = answer
            step = Step(*w.action, self._checked_obs(obs, "observation"), float(reward), bool(terminated),
                        bool(truncated), dict(info))  # fmt: skip
            self.results.setdefault(w.round, {})[i] = step
            w.round += 1
            if step.ended and w.round < self.total_rounds:
                self._reset(i)
            else:
                w.obs = step.obs

    # ---- the learner ----------------------------------------------------------------------------
    def _store_round(self) -> None:
        """Store the next round's transitions in env order and schedule its updates."""
        round_ = self.results.get(self.next_round)
        if any(s.ended and s.reset is None and self.next_round + 1 < self.total_rounds for s in round_.values()):
            self._take(self.workers.receive())  # an env's next reset is still in flight
            return
        self.results.pop(self.next_round)
        self._round_before = self.step
        for i in range(self.num_envs):
            step, episode = round_[i], self.episodes[i]
            if not np.isfinite(step.reward):
                self._diverged("reward", step.reward, self.step + 1)
            discount = transition_discount(step.info)
            self.buffer.add(episode.observations[-1], step.action, step.reward, step.obs, step.terminated, discount)
            self.step += 1
            episode.observations.append(step.obs)
            episode.actions.append(step.action)
            episode.env_actions.append(step.env_action)
            episode.total_reward += step.reward
            if ERROR_KEY in step.info:
                log.warning(
                    "env %d, episode seed %s: %s; the episode was cut short", i, step.info[SEED_KEY],
                    step.info[ERROR_KEY],
                )  # fmt: skip
            self.logger.env_info(step.info, self.step)
        self._stored = round_
        t = self.settings.train
        if self.step > t.warmup_steps:
            self._clone_demonstrations()
        self.pending_updates = t.updates_per_step * self.num_envs if self.step > t.warmup_steps else 0
        if not self.pending_updates:
            self._finish_round()

    def _finish_round(self) -> None:
        """After a round's updates: its network version, logging, evaluation, episode ends, checkpoint."""
        t, before, version = self.settings.train, self._round_before, self.next_round
        self.next_round += 1
        self.versions.keep(version, self.agent.policy)
        self.versions.forget_before(version + 1 - self.lag)
        if t.log_every and self.step // t.log_every > before // t.log_every:
            self._log_progress()
        if t.eval_every and self.step // t.eval_every > before // t.eval_every:
            self._evaluate()
        self.bar.update(self.num_envs)
        for i, step in sorted(self._stored.items()):
            if step.ended:
                self._log_episode(self.episodes[i], self.bar)
                if step.reset is not None:
                    self.episodes[i] = step.reset
        if t.checkpoint_every and self.step // t.checkpoint_every > before // t.checkpoint_every:
            self._checkpoint()

    def _plot_env(self):
        if self._eval_env is None:
            self._eval_env = make_env(self.settings.env)
        return self._eval_env

    def _guarded(self, call):
        """A step of the loop; a worker process that died becomes ``WorkerDiedError``, an env that raised outside a
        step ``EnvWorkerError``: one line each, saying where the run can go on from (never a hang)."""
        try:
            return call()
        except WorkerDied as err:
            self._worker_died = True
            raise WorkerDiedError(
                f"an environment worker process died (killed, or out of memory; {err}) at step {self.step}; "
                f"{self._where_to_go_on()}"
            ) from err
        except WorkerError as err:
            raise EnvWorkerError(f"{err} at step {self.step}; {self._where_to_go_on()}") from err

    def _where_to_go_on(self) -> str:
        if not self.last_checkpoint_step:
            return "there is no checkpoint yet: start the run again"
        resume = f"vical-train resume={self.settings.run_dir}"
        return f"resume from its checkpoint at step {self.last_checkpoint_step}: {resume}"

    # ---- checkpoints ----------------------------------------------------------------------------
    def _checkpoint(self) -> None:
        """The state after the last stored round (envs that ran ahead are replayed to it on resume)."""
        self.last_checkpoint_step = self.step
        state = self._state()
        state["episodes"] = [
            {
                "seed": e.seed,
                "index": e.index,
                "total_reward": e.total_reward,
                "observations": _tensor(e.observations),
                "actions": _tensor(e.actions),
                "env_actions": _tensor(e.env_actions),
            }
            for e in self.episodes
        ]
        state["policy_versions"] = dict(self.versions.states)
        save_checkpoint(state, self.settings.run_dir / CHECKPOINT)
        self._log_checkpoint()

    def _restore(self, state: dict) -> None:
        super()._restore(state)
        if "episodes" not in state or "policy_versions" not in state:
            raise ConfigError(
                f"{self.settings.resume / CHECKPOINT} holds no env workers' episodes and policy versions (a run with "
                "train.num_envs=1, or written by an older vical): resume it with its own num_envs, or start again"
            )
        self._restored = state

    def _resume(self) -> None:
        """Replay every env's running episode in its worker; check that it reaches the stored observation."""
        self.versions.states = {int(v): s for v, s in self._restored["policy_versions"].items()}
        saved = [
            {k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in s.items()}
            for s in self._restored["episodes"]
        ]
        self.episodes, self.live = [], []
        for i, s in enumerate(saved):
            taken = len(s["env_actions"])  # in the rounds next_round - taken .. next_round - 1
            demonstrated = sum(self._demonstrated(r) for r in range(self.next_round - taken, self.next_round))
            self.workers.send(i, "replay", int(s["seed"]), list(s["env_actions"]), demonstrated)
            self.episodes.append(RunningEpisode(
                list(s["observations"]), list(s["actions"]), s["total_reward"], seed=int(s["seed"]),
                index=int(s["index"]), env_actions=list(s["env_actions"]),
            ))  # fmt: skip
            self.live.append(Worker(self.next_round, None, int(s["index"]) + 1))
        reached: dict[int, Any] = {}
        while len(reached) < self.num_envs:
            reached.update(self.workers.receive())
        for i, s in enumerate(saved):
            if not np.array_equal(np.asarray(reached[i], np.float32).ravel(), s["observations"][-1]):
                raise ConfigError(
                    f"env {i} did not replay to its checkpointed state (its episode of seed {s['seed']}): the env is "
                    "not deterministic given its seed and actions, so this run cannot resume exactly"
                )
            self.live[i].obs = s["observations"][-1]
        self._restored = None


def _tensor(rows: list[np.ndarray]) -> torch.Tensor:
    """Rows (T, d) as a tensor (checkpoints hold tensors only); (0, 0) for none."""
    return torch.from_numpy(np.stack(rows)) if rows else torch.zeros((0, 0))
