"""Demonstrations: a policy that acts in a run's warm-up instead of uniform random actions, and whose actions the
agent may clone before SAC's own updates (``train.demonstrator``, ``train.clone_updates``; docs/rl.md).

A demonstrator is built from its config (``_target_`` + arguments) wherever its env is (the trainer's process, or
each env worker) and drives the env as a collection policy does: ``reset(env, rng)`` after every ``env.reset``,
then ``act(obs, env)``, an action in the env's units (``env`` is the unwrapped env). The trainer stores its
actions in the policy's units (``BoxActions.to_policy``). Its generator is seeded by the episode's reset seed, so
an episode it drives is a function of that seed: a resumed run replays it exactly.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import gymnasium as gym
import hydra.utils
import numpy as np

from vical.config_checks import ConfigError


class Demonstrator(Protocol):
    def reset(self, env: Any, rng: np.random.Generator) -> None: ...

    def act(self, obs: np.ndarray, env: Any) -> np.ndarray: ...


def make_demonstrator(cfg: Mapping[str, Any] | None) -> Demonstrator | None:
    """The demonstrator of ``train.demonstrator`` (None without one); a factory that fails is one line by key."""
    if cfg is None:
        return None
    try:
        demonstrator = hydra.utils.instantiate(dict(cfg))
    except ConfigError:
        raise
    except Exception as err:
        cause = err.__cause__ or err
        raise ConfigError(f"train.demonstrator: {cfg['_target_']} could not be built ({cause})") from err
    if not (callable(getattr(demonstrator, "reset", None)) and callable(getattr(demonstrator, "act", None))):
        raise ConfigError(
            f"train.demonstrator: {cfg['_target_']} built a {type(demonstrator).__name__}, which has no reset(env, "
            "rng) and act(obs, env): name a collection policy's factory"
        )
    return demonstrator


def start_demonstration(demonstrator: Demonstrator, env: gym.Env, seed: int) -> None:
    """Ready ``demonstrator`` for the episode ``env`` was just reset to with ``seed``."""
    demonstrator.reset(env.unwrapped, np.random.default_rng(seed))


def demonstrated_action(demonstrator: Demonstrator, env: gym.Env, obs: np.ndarray) -> np.ndarray:
    """The demonstrator's action (the env's units) on the observation ``obs`` of ``env``."""
    return np.asarray(demonstrator.act(obs, env.unwrapped))
