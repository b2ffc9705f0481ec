"""The information-greedy planner: each step, the candidate action whose predicted step earns the most.

It plans on the information state the learned policy was trained on (the same tolerances, confidence, goal
groups and step limit, read from the learned run as ``stop=information`` reads them) and looks one step ahead:

- **candidates** (``candidate_actions``): the 12 moves along one workspace axis at the action box's full scale
  (+-x, +-y, +-z by the translation scale; +-roll, +-pitch, +-yaw by theirs) and ``samples`` actions drawn
  uniformly from the box with the episode's generator (12 by default: 24 candidates); a candidate the workspace
  clips to no motion is left out;
- **prediction** (``vical.env.lookahead``): the views each would give (the board's corners projected with the
  current estimate where the detector reports them) and its IMU excitation, added to a fork of the information
  state; the data so far and the sensor's guess, never the truth;
- **score**: the information MDP's step reward of the prediction (``vical.env.rewards.information_reward_terms``):
  ``information_weight`` per e-fold of excess shed, less ``path_weight`` per metre and ``time_weight`` per second
  of motion, plus the terminal bonus when it reaches the goal: the information state's excess reduction per
  second of motion and per metre, at the prices the learned policy was trained with (the learned run's
  ``env.reward`` and ``env.information``, whatever the env it drives is given).

Before any frame has posed the board it searches along the line of sight to the board (where the alignment put
it): to the workspace's nearest point first (tags too small to detect from the start), then to its farthest (a
board too large for the image), back and forth, looking at the board centre. ``decision_times`` keeps each
step's planning time [s] (``experiments/bench_greedy.py``).

``greedy_demonstrator`` is the planner as ``vical-train``'s demonstrator (``train.demonstrator``): in the env being
trained, on that env's own information state and at its own prices (its ``env.reward``), with no learned run.
"""

from __future__ import annotations

import time

import numpy as np

from vical.config_checks import ConfigError, require
from vical.env.actions import step_to_action
from vical.env.calibration import CalibrationEnv
from vical.env.lookahead import Lookahead, Prediction
from vical.env.rewards import information_reward_terms
from vical.env.settings import RewardWeights
from vical.policies.base import Policy
from vical.policies.learned import DEFAULT_WORKSPACE, carried_settings, trained_reward
from vical.policies.stopping import information_run

DEFAULT_SAMPLES = 12
SEARCH_TOLERANCE = 0.01  # [m] the arm's reach of a workspace end (IK tolerance, clipping)


def axis_actions(scale: np.ndarray) -> np.ndarray:
    """(12, 6) the moves along one workspace axis, both ways, at the action ``scale`` (6,)."""
    moves = []
    for axis in range(6):
        for sign in (1.0, -1.0):
            step = np.zeros(6)
            step[axis] = sign * (scale[0] if axis < 3 else scale[axis])
            moves.append(step_to_action(step[:3], step[3:]))
    return np.array(moves)


def candidate_actions(scale: np.ndarray, samples: int, rng: np.random.Generator) -> np.ndarray:
    """(12 + samples, 6) the planner's candidates: the axis moves, then ``samples`` uniform draws from the box; all
    within the box, as the env clips them (a horizontal move's polar angle of pi/2 to an angle scale of 1.57)."""
    scale = np.asarray(scale, dtype=float)
    return np.clip(np.vstack([axis_actions(scale), rng.uniform(-scale, scale, (samples, 6))]), -scale, scale)


def predicted_moves(lookahead: Lookahead, actions: np.ndarray) -> tuple[list[np.ndarray], list[Prediction]]:
    """The ``actions`` that move (one the workspace's edge clips to no motion is left out) and their predictions."""
    moving, predictions = [], []
    for action in actions:
        prediction = lookahead.predict(action)
        if not np.allclose(prediction.goal, lookahead.offset, atol=1e-9):
            moving.append(action)
            predictions.append(prediction)
    return moving, predictions


class GreedyInformationPolicy(Policy):
    """The information-greedy planner (module doc).

    Args:
        settings: the learned run's ``state``, ``information`` and ``max_steps`` (its MDP).
        reward: the learned run's reward weights (the prices of path and the goal's bonus); None: the env's own.
        samples: random candidates per step beside the 12 axis moves.
        name: shown in evaluation tables.
    """

    stop_at_coverage = True

    def __init__(
        self,
        settings: dict,
        reward: RewardWeights | None,
        samples: int = DEFAULT_SAMPLES,
        name: str = "greedy information planner",
    ) -> None:
        ok = isinstance(samples, int) and not isinstance(samples, bool) and samples >= 0
        require(ok, "policy.samples", "an integer >= 0 (random candidates beside the 12 axis moves)", samples)
        self.env_settings = {k: v for k, v in settings.items() if k != "max_steps"}
        self.reward = reward
        self.max_steps = settings.get("max_steps")
        self.samples = samples
        self.name = name
        self.decision_times: list[float] = []
        self._rng = np.random.default_rng(0)

    def check(self, env: CalibrationEnv) -> None:
        if env.config.state != "information":
            raise ConfigError(
                f"the greedy planner plans on the information state, but the env has env.state={env.config.state}; "
                "vical-evaluate and vical-collect bring it with the planner's settings"
            )

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self.check(env)
        self._rng = rng

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        start = time.perf_counter()
        try:
            lookahead = Lookahead(env.state, env.frame, env.pose_offset, env.config, env.step_timing)
        except ValueError:  # no frame has posed the board yet
            action = self._search(env)
        else:
            action = self._best(lookahead, env)
        self.decision_times.append(time.perf_counter() - start)
        return action

    def _best(self, lookahead: Lookahead, env: CalibrationEnv) -> np.ndarray:
        actions, predictions = predicted_moves(
            lookahead, candidate_actions(env.action_space.high, self.samples, self._rng)
        )
        if not actions:
            return self._toward_start(env)
        return actions[self.choice(lookahead, predictions, env)]

    def choice(self, lookahead: Lookahead, predictions: list[Prediction], env: CalibrationEnv) -> int:
        """The index of the prediction taken: the best score (the first of equals, in candidate order)."""
        return int(np.argmax(self.scores(predictions, env)))

    def scores(self, predictions: list[Prediction], env: CalibrationEnv) -> np.ndarray:
        """Each predicted step's score: the information MDP's reward of the step (``score``)."""
        excess = env.state.excess
        return np.array([self.score(prediction, excess, env) for prediction in predictions])

    def score(self, prediction: Prediction, excess: float, env: CalibrationEnv) -> float:
        """The information MDP's reward of the predicted step from the current ``excess``, at the learned run's
        prices (the env carries its information settings)."""
        reward = env.config.reward if self.reward is None else self.reward
        terms = information_reward_terms(
            excess, prediction.excess, prediction.path_length, prediction.motion_time, prediction.goal_reached,
            env.config.information, reward,
        )  # fmt: skip
        return float(sum(terms.values()))

    @classmethod
    def _search(cls, env: CalibrationEnv) -> np.ndarray:
        """Toward the workspace's nearest point on the line of sight (+x: the start pose looks along it), or from
        there toward its farthest, with the start's orientation."""
        reach = env.config.workspace.bound[0]
        at_near_end = env.pose_offset[0] >= reach - SEARCH_TOLERANCE
        goal = np.zeros(6)
        goal[0] = -reach if at_near_end else reach
        return cls._toward(env, goal)

    @classmethod
    def _toward_start(cls, env: CalibrationEnv) -> np.ndarray:
        """The action toward the start pose (offset 0), within the action box."""
        return cls._toward(env, np.zeros(6))

    @staticmethod
    def _toward(env: CalibrationEnv, goal: np.ndarray) -> np.ndarray:
        """The action toward the workspace offset ``goal`` (6,), within the action box."""
        scale = env.action_space.high
        back = np.asarray(goal, dtype=float) - np.asarray(env.pose_offset, dtype=float)
        distance = np.linalg.norm(back[:3])
        if distance > scale[0]:
            back[:3] *= scale[0] / distance
        return step_to_action(back[:3], np.clip(back[3:], -scale[3:], scale[3:]))


def greedy_information_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    samples: int = DEFAULT_SAMPLES,
    name: str = "greedy information planner",
    max_steps: int | None = None,
) -> GreedyInformationPolicy:
    """The factory ``conf/policy/greedy_information.yaml`` names: the planner on the information state of the
    learned run ``run_dir`` (None: the policy shipped for the workspace named ``workspace``), with its step limit
    (``max_steps``; None: the learned run's)."""
    settings, reward = planner_settings(run_dir, workspace, max_steps)
    return GreedyInformationPolicy(settings, reward, samples, name)


def greedy_demonstrator(samples: int = DEFAULT_SAMPLES) -> GreedyInformationPolicy:
    """The factory a run's ``train.demonstrator`` names: the planner on the trained env's own information state,
    at its own prices (``conf/experiment/train_practitioner_from_planner.yaml``)."""
    return GreedyInformationPolicy({}, None, samples, name="greedy information planner (the env's prices)")


def planner_settings(run_dir: str | None, workspace: str, max_steps: int | None) -> tuple[dict, RewardWeights]:
    """The learned run's MDP settings (its step limit replaced by ``max_steps`` unless None) and reward weights,
    that a planner on its information state plans with (``run_dir`` None: the policy shipped for ``workspace``)."""
    path, env = information_run(run_dir, workspace, key="policy.run_dir")
    settings = carried_settings(env)
    if max_steps is not None:
        ok = isinstance(max_steps, int) and not isinstance(max_steps, bool) and max_steps >= 1
        require(ok, "policy.max_steps", "null or an integer >= 1", max_steps)
        settings = {**settings, "max_steps": max_steps}
    return settings, trained_reward(path, env)
