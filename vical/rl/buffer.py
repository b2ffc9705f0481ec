"""Preallocated circular replay buffer of transitions ``(s, a, r, s', terminated, discount)``.

Only *termination* (the MDP ended: no bootstrap from ``s'``) is stored. A time-limit *truncation* is not a
terminal state: the transition is stored with ``terminated = 0`` and its true ``s'`` (gymnasium returns the
final observation from ``step`` before the caller resets), so the critic bootstraps through it.

``discount`` is the transition's own factor on the agent's ``gamma`` (1 for an ordinary step): an env whose
steps last unequal amounts of what the task counts (a semi-MDP) reports it as ``info["discount"]``; 0 says
nothing after the step is valued, though ``s'`` is not terminal (a time limit that is part of the task).
"""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch
from torch import Tensor

from vical.io.atomic import atomic_file

_ARRAYS = ("obs", "actions", "rewards", "next_obs", "terminated", "discounts")
DISCOUNT_KEY = "discount"  # info key of a transition's own discount factor, in [0, 1]


def transition_discount(info: dict) -> float:
    """The discount an env's step reports in ``info["discount"]``; 1 when it reports none."""
    return float(info.get(DISCOUNT_KEY, 1.0))


class Batch(NamedTuple):
    """A minibatch of ``B`` transitions as float32 tensors.

    obs, next_obs: ``(B, obs_dim)``; actions: ``(B, act_dim)`` in the policy's ``[-1, 1]`` units;
    rewards: ``(B,)``; terminated: ``(B,)`` with 1.0 where ``s'`` is terminal; discounts: ``(B,)``, the
    transitions' factors on ``gamma``.
    """

    obs: Tensor
    actions: Tensor
    rewards: Tensor
    next_obs: Tensor
    terminated: Tensor
    discounts: Tensor


class ReplayBuffer:
    """Holds the last ``capacity`` transitions in float32 arrays allocated once; oldest overwritten first."""

    def __init__(self, capacity: int, obs_dim: int, act_dim: int) -> None:
        if capacity < 1:
            raise ValueError(f"replay buffer capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_dim), np.float32)
        self.actions = np.zeros((capacity, act_dim), np.float32)
        self.rewards = np.zeros(capacity, np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), np.float32)
        self.terminated = np.zeros(capacity, np.float32)
        self.discounts = np.ones(capacity, np.float32)
        self.position = 0  # next slot to write
        self.size = 0

    def __len__(self) -> int:
        return self.size

    def add(
        self,
        obs: np.ndarray,
        action: np.ndarray,
        reward: float,
        next_obs: np.ndarray,
        terminated: bool,
        discount: float = 1.0,
    ) -> None:
        """Store one transition: obs/next_obs ``(obs_dim,)``, action ``(act_dim,)``, discount in [0, 1]."""
        if not 0.0 <= discount <= 1.0:
            raise ValueError(
                f"a transition's discount must be in [0, 1], got {discount}: check the env's info['discount']"
            )
        i = self.position
        self.obs[i] = obs
        self.actions[i] = action
        self.rewards[i] = reward
        self.next_obs[i] = next_obs
        self.terminated[i] = float(terminated)
        self.discounts[i] = discount
        self.position = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def sample(self, batch_size: int, rng: np.random.Generator) -> Batch:
        """``batch_size`` transitions drawn uniformly with replacement from the stored ones."""
        if self.size == 0:
            raise ValueError("cannot sample from an empty replay buffer: add transitions first")
        idx = rng.integers(0, self.size, size=batch_size)
        return Batch(*(torch.from_numpy(getattr(self, name)[idx]) for name in _ARRAYS))

    def state_dict(self) -> dict:
        """The stored transitions (filled slots only) as tensors plus the write position."""
        state = {name: torch.from_numpy(getattr(self, name)[: self.size].copy()) for name in _ARRAYS}
        state.update(position=self.position, size=self.size, capacity=self.capacity)
        return state

    def load_state_dict(self, state: dict) -> None:
        """Restore from :meth:`state_dict`; the capacity and dimensions must match this buffer's."""
        if state["capacity"] != self.capacity:
            raise ValueError(f"replay buffer capacity {self.capacity} differs from the saved {state['capacity']}")
        size = int(state["size"])
        state = {"discounts": np.ones(size, np.float32), **state}  # checkpoints from before per-step discounts
        for name in _ARRAYS:
            saved = np.asarray(state[name])
            target = getattr(self, name)
            if saved.shape[1:] != target.shape[1:]:
                raise ValueError(f"replay buffer '{name}' has shape {target.shape[1:]}, saved {saved.shape[1:]}")
            target[:size] = saved
        self.size = size
        self.position = int(state["position"])

    def save(self, path: str | Path) -> None:
        """Write the buffer to an ``.npz`` file atomically (temp file + ``os.replace``)."""
        path = Path(path)
        state = self.state_dict()
        arrays = {k: (v.numpy() if isinstance(v, Tensor) else np.asarray(v)) for k, v in state.items()}
        with atomic_file(path) as tmp, open(tmp, "wb") as f:  # a file object: np.savez would append .npz to a path
            np.savez(f, **arrays)

    def load(self, path: str | Path) -> None:
        """Restore from a file written by :meth:`save`."""
        with np.load(path) as data:
            state = {k: (data[k] if data[k].ndim else data[k].item()) for k in data.files}
        self.load_state_dict(state)
