"""The env a run trains on: built from its config (``_target_`` + arguments), and its action box.

The env is any gymnasium env with Box observation and action spaces; the policy acts in ``[-1, 1]^d``
and ``BoxActions`` maps its actions onto the env's box, in training and wherever a trained agent acts.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import hydra.utils
import numpy as np
from hydra.errors import InstantiationException

from vical.config_checks import ConfigError


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

    def to_policy(self, action: np.ndarray) -> np.ndarray:
        """The inverse of ``to_env``: an env action (a demonstrator's) in ``[-1, 1]^d``, float32, clipped into it."""
        policy = (np.asarray(action, np.float64) - self.low) / self.half_range - 1.0
        return np.clip(policy, -1.0, 1.0).astype(np.float32)


def make_env(env_cfg: Mapping[str, Any]) -> gym.Env:
    """Instantiate the env config (``_target_`` + kwargs) and check its observation space; a setting the env refuses
    is its own ``ConfigError`` line (naming the key), not Hydra's wrapper of it."""
    try:
        env = hydra.utils.instantiate(env_cfg)
    except InstantiationException as err:
        if isinstance(err.__cause__, ConfigError):
            raise err.__cause__ from None
        raise
    space = env.observation_space
    if not isinstance(space, gym.spaces.Box):
        raise ConfigError(f"env observation space must be a gymnasium Box, got {space} from {env_cfg['_target_']}")
    return env
