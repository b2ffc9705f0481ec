"""One interface for every way of moving the sensor: learned policies, random policies, fixed trajectories.

A policy drives one ``CalibrationEnv`` episode, one action per step (``vical.env.actions``:
``[rho, theta, phi, alpha, beta, gamma]`` in the env's units). Fixed trajectories are lists of
waypoints (pose offsets from the episode's start pose) that ``WaypointPolicy`` reaches through
actions within the env's bounds, so every policy runs through the same executor, workspace and
sensors, and is scored the same way.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from vical.config_checks import ConfigError
from vical.env.actions import step_to_action
from vical.env.calibration import CalibrationEnv


class Policy(ABC):
    """Chooses the actions of a calibration episode.

    Attributes:
        name: shown in evaluation tables.
        stop_at_coverage: the episode ends when the coverage is complete (the MDP's terminal
            condition); False for fixed trajectories, which run all their steps.
        max_steps: step limit of its episodes (None: the env's ``max_steps``).
        env_settings: MDP settings the policy's episodes run with, over the evaluation env's
            (a learned policy's state and stopping rule: ``state``, ``information``); empty for
            policies that act in any env.
        reads_state: its actions depend on the env's state (a learned policy): it runs only in the state
            it was trained on. The baselines' actions do not, so any state's stopping rule can end their
            episodes (``vical.policies.stopping``).
        action_scale: (6,) the action box its actions were trained in (a learned policy: it acts in no other);
            None: it acts in whatever box its env has (``vical-guide`` gives those a person's step).
    """

    name: str = "policy"
    stop_at_coverage: bool = True
    max_steps: int | None = None
    env_settings: Mapping[str, Any] = MappingProxyType({})
    reads_state: bool = False
    action_scale: np.ndarray | None = None

    def check(self, env: CalibrationEnv) -> None:  # noqa: B027 (optional hook)
        """Raise ``ConfigError`` (one line: what and what to do) when the policy cannot run in ``env``.

        Called once before the first episode, so that a mismatch (a workspace the policy was not
        made for, another action scale) fails in seconds rather than after episodes have run.
        """

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:  # noqa: B027 (optional hook)
        """Called after ``env.reset``, before the episode's first action; ``rng`` seeds any randomness."""

    @property
    def finished(self) -> bool:
        """True when the policy has nothing left to do (a fixed trajectory after its last waypoint)."""
        return False

    @abstractmethod
    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        """The next action (6,) in the env's units, for state ``obs`` (24,)."""


def require_frame(env: CalibrationEnv, frame: str, trajectories: str, instead: str) -> None:
    """Refuse ``env`` unless its workspace's orientations are relative to ``frame`` (``start`` or ``board``).

    ``trajectories`` names what was written for that frame, ``instead`` what to use in the other.
    """
    workspace = env.config.workspace
    if workspace.frame != frame:
        raise ConfigError(
            f"{trajectories} are written for a workspace with frame={frame}; workspace {workspace.name!r} "
            f"has frame={workspace.frame!r}: {instead}"
        )


class WaypointPolicy(Policy):
    """Visits pose offsets ``[x, y, z, roll, pitch, yaw]`` ([m], [rad], from the start pose) in order.

    Each step heads for the current waypoint; a waypoint farther than one action can move is
    approached over several steps. A waypoint counts as reached within ``tolerance`` of the arm's
    executed pose (waypoints are clipped to the workspace), or when a step toward it left the pose
    unchanged (an unreachable pose); then the next one is the goal. After the last waypoint the
    policy holds still.

    Args:
        waypoints: (K, 6) pose offsets.
        name: shown in evaluation tables.
        tolerance: (position [m], angle [rad]) within which a waypoint is reached.

    ``STEPS_PER_WAYPOINT``: a cap on the steps of an episode per waypoint for trajectories whose
    segments may take several steps (the episode normally ends after the last waypoint).
    """

    stop_at_coverage = False
    STEPS_PER_WAYPOINT = 4

    def __init__(self, waypoints: np.ndarray, name: str = "waypoints", tolerance: tuple[float, float] = (2e-3, 2e-3)):
        w = np.asarray(waypoints, dtype=float)
        if w.ndim != 2 or w.shape[1] != 6 or not len(w) or not np.all(np.isfinite(w)):
            raise ValueError(f"waypoints must be a non-empty (K, 6) array of finite pose offsets, got shape {w.shape}")
        self.waypoints = w
        self.name = name
        self.tolerance = tolerance
        self._next = 0
        self._last_offset: np.ndarray | None = None

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self._next = 0
        self._last_offset: np.ndarray | None = None

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        offset = env.pose_offset
        stuck = self._last_offset is not None and self._reached(offset - self._last_offset)
        if stuck and self._next < len(self.waypoints):
            self._next += 1
        self._last_offset = offset
        while self._next < len(self.waypoints) and self._reached(self._goal(env) - offset):
            self._next += 1
        if self._next == len(self.waypoints):
            return np.zeros(6)
        delta = self._goal(env) - offset
        scale = np.asarray(env.config.action_scale, dtype=float)
        # Shrink the whole step uniformly so translation and rotation arrive together.
        distance = np.r_[np.linalg.norm(delta[:3]), np.abs(delta[3:])]
        limits = np.r_[scale[0], scale[3:]] / np.maximum(distance, 1e-12)
        shrink = min(1.0, float(limits.min()))
        return step_to_action(shrink * delta[:3], shrink * delta[3:])

    @property
    def finished(self) -> bool:
        return self._next == len(self.waypoints)

    def _goal(self, env: CalibrationEnv) -> np.ndarray:
        """The current waypoint clipped to the workspace (what the arm can reach)."""
        bound = env.config.workspace.bound
        return np.clip(self.waypoints[self._next], -bound, bound)

    def _reached(self, delta: np.ndarray) -> bool:
        return bool(np.linalg.norm(delta[:3]) <= self.tolerance[0] and np.max(np.abs(delta[3:])) <= self.tolerance[1])
