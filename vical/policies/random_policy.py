"""The paper's random moving policy: uniform random actions in the MDP's action space.

It moves like the learned policy (one "direct transformation" per step, the same bounds and
workspace) and stops when the coverage is complete, so it measures what the learned policy adds
over blind exploration of the same action space.
"""

from __future__ import annotations

import numpy as np

from vical.env.calibration import CalibrationEnv
from vical.policies.base import Policy


class RandomMovingPolicy(Policy):
    """Draws every action uniformly from the env's action box ``[-action_scale, action_scale]``.

    Args:
        name: shown in evaluation tables.
        max_steps: step limit of its episodes (None: the env's ``max_steps``, 20 in the paper).
    """

    stop_at_coverage = True

    def __init__(self, name: str = "random moving policy", max_steps: int | None = None) -> None:
        if max_steps is not None and (not isinstance(max_steps, int) or max_steps < 1):
            raise ValueError(f"max_steps must be a positive integer or None, got {max_steps!r}")
        self.name = name
        self.max_steps = max_steps
        self._rng: np.random.Generator | None = None

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        """Take ``rng`` as the episode's source of actions (the same seed gives the same actions)."""
        self._rng = rng

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        """A uniform sample of the env's action box (6,): [m], [rad] x 5."""
        if self._rng is None:
            raise RuntimeError("RandomMovingPolicy.act called before reset(env, rng)")
        space = env.action_space
        return self._rng.uniform(space.low, space.high).astype(space.dtype)
