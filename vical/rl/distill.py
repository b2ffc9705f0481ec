"""Distillation (DAgger): a teacher labels the states the policy itself visits, and the policy learns its actions.

``train.distill`` runs before SAC's own steps (``train.total_steps`` of them; 0: the distilled policy is the run's
agent). The teacher is ``train.demonstrator`` (a collection policy, e.g. the information-rate planner, built in each
worker beside its env). Each of ``rounds`` rounds rolls out ``episodes`` episodes in which every step's state is
labelled with the teacher's action and the action executed is the teacher's with probability ``beta^round``, else the
policy's mean: round 0 is the teacher's own episodes (behaviour cloning), later rounds visit the states the policy's
own mistakes lead to and learn what the teacher would do there (Ross et al. 2011, DAgger). After each round the
policy's mean is fitted to every label so far (squared error in the policy's ``[-1, 1]`` units: the mean action is
what a deployed policy takes). The rollouts' transitions join the replay buffer, so SAC's critics start from them.

The episodes' seeds come from the trainer's generator and each episode's mixing from its own seed, so a round is a
function of the checkpoint it starts from: an interrupted run resumes at the round it was in.
"""

from __future__ import annotations

import copy
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from vical.config_checks import require, require_range
from vical.rl.buffer import transition_discount
from vical.rl.demonstrations import Demonstrator, demonstrated_action, make_demonstrator, start_demonstration
from vical.rl.envs import BoxActions, make_env
from vical.rl.networks import TanhGaussianPolicy


@dataclass
class DistillConfig:
    """``train.distill``: the rounds of DAgger before SAC (module doc)."""

    rounds: int = 4  # rounds of rollouts, each followed by fitting the policy to every label so far
    episodes: int = 32  # episodes per round
    beta: float = 0.5  # round k executes the teacher's action with probability beta^k (round 0: every step)
    epochs: int = 200  # passes over the labels after each round
    batch_size: int = 256
    lr: float = 1e-3  # Adam's step size for the policy's fit

    def __post_init__(self) -> None:
        for key, low in (("rounds", 1), ("episodes", 1), ("epochs", 1), ("batch_size", 1)):
            value = getattr(self, key)
            require(isinstance(value, int) and not isinstance(value, bool), f"train.distill.{key}", "an integer", value)
            require_range(f"train.distill.{key}", value, low)
        require_range("train.distill.beta", self.beta, 0.0, 1.0)
        require(self.lr > 0, "train.distill.lr", "a step size > 0", self.lr)


@dataclass(frozen=True)
class RolloutJob:
    """One DAgger episode, run in a worker: the env and teacher configs, the policy, the seed and the mixing."""

    env_cfg: dict
    teacher_cfg: dict
    policy: TanhGaussianPolicy
    seed: int
    beta: float


@dataclass
class Rollout:
    """One episode's steps (policy units) with the teacher's label of each state, and how it ended."""

    obs: np.ndarray  # (T, obs_dim)
    labels: np.ndarray  # (T, act_dim) the teacher's actions
    actions: np.ndarray  # (T, act_dim) the actions executed
    rewards: np.ndarray  # (T,)
    next_obs: np.ndarray  # (T, obs_dim)
    terminated: np.ndarray  # (T,) bool
    discounts: np.ndarray  # (T,)

    @property
    def total_reward(self) -> float:
        return float(self.rewards.sum())

    @property
    def reached(self) -> bool:
        """The episode ended by termination (the env's goal), not by its step limit."""
        return bool(self.terminated[-1])


_WORKER_ENVS: dict[str, tuple[Any, Demonstrator, BoxActions]] = {}


def _worker_env(env_cfg: Mapping[str, Any], teacher_cfg: Mapping[str, Any]) -> tuple[Any, Demonstrator, BoxActions]:
    """The worker's env and teacher of these configs, built once per worker process."""
    key = json.dumps([env_cfg, teacher_cfg], sort_keys=True, default=str)
    if key not in _WORKER_ENVS:
        env = make_env(env_cfg)
        _WORKER_ENVS[key] = (env, make_demonstrator(teacher_cfg), BoxActions(env.action_space))
    return _WORKER_ENVS[key]


def rollout(job: RolloutJob) -> Rollout:
    """One episode of the teacher-policy mixture, every state labelled by the teacher (module doc)."""
    torch.set_num_threads(1)  # one worker per core: the policy's forward passes are small
    env, teacher, actions = _worker_env(job.env_cfg, job.teacher_cfg)
    mixing = np.random.default_rng([job.seed, 1])
    obs, _ = env.reset(seed=job.seed)
    start_demonstration(teacher, env, job.seed)
    steps: dict[str, list] = {k: [] for k in ("obs", "labels", "actions", "rewards", "next_obs", "terminated",
                                              "discounts")}  # fmt: skip
    while True:
        obs = np.asarray(obs, np.float32).ravel()
        taught = demonstrated_action(teacher, env, obs)
        label = actions.to_policy(taught)
        if mixing.random() < job.beta:
            action, env_action = label, taught
        else:
            action = mean_action(job.policy, obs)
            env_action = actions.to_env(action)
        next_obs, reward, terminated, truncated, info = env.step(env_action)
        step = {"obs": obs, "labels": label, "actions": action, "rewards": float(reward),
                "next_obs": np.asarray(next_obs, np.float32).ravel(), "terminated": bool(terminated),
                "discounts": transition_discount(info)}  # fmt: skip
        for key, value in step.items():
            steps[key].append(value)
        obs = next_obs
        if terminated or truncated:
            break
    arrays = {k: np.asarray(v, np.float32) for k, v in steps.items() if k != "terminated"}
    return Rollout(terminated=np.asarray(steps["terminated"]), **arrays)


@torch.no_grad()
def mean_action(policy: TanhGaussianPolicy, obs: np.ndarray) -> np.ndarray:
    """The policy's deterministic action (its mean) for one observation, in ``[-1, 1]``."""
    return policy.deterministic(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0))[0].numpy()


def rollout_jobs(
    env_cfg: Mapping[str, Any], teacher_cfg: Mapping[str, Any], policy: TanhGaussianPolicy, seeds: np.ndarray,
    beta: float,
) -> list[RolloutJob]:  # fmt: skip
    """The round's jobs: one per seed, each with a frozen copy of the policy as it is now."""
    frozen = copy.deepcopy(policy).eval()
    return [RolloutJob(dict(env_cfg), dict(teacher_cfg), frozen, int(s), float(beta)) for s in seeds]


def fit_policy(
    policy: TanhGaussianPolicy, obs: np.ndarray, labels: np.ndarray, cfg: DistillConfig, generator: torch.Generator
) -> float:
    """Fit the policy's mean action to the labels (squared error, Adam, ``cfg.epochs`` passes); the last pass's mean
    loss. Only the policy's parameters move."""
    optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.lr)
    obs_t, labels_t = torch.as_tensor(obs), torch.as_tensor(labels)
    n = len(obs_t)
    for _ in range(cfg.epochs):
        order = torch.randperm(n, generator=generator)
        total = 0.0
        for start in range(0, n, cfg.batch_size):
            batch = order[start : start + cfg.batch_size]
            loss = imitation_loss(policy, obs_t[batch], labels_t[batch])
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            optimizer.step()
            total += float(loss.detach()) * len(batch)
    return total / n


def imitation_loss(policy: TanhGaussianPolicy, obs: torch.Tensor, labels: torch.Tensor) -> torch.Tensor:
    """Mean over the batch of the squared distance between the policy's mean action and the label (policy units)."""
    return (policy.deterministic(obs) - labels).square().sum(-1).mean()
