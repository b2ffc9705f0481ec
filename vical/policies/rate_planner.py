"""The information-rate planner: each step, the candidate that sheds the most excess per second of recording.

The information-greedy planner (``vical.policies.greedy``) takes the candidate whose predicted step earns the
information MDP's reward most: 40 per e-fold of excess shed, less 2 per second of motion and 5 per metre at the
shipped runs' prices, so a step twice as long that sheds a little more wins, although the time to the tolerances
is what a user waits. The rate planner predicts the same candidates (the 12 axis moves and the random draws,
``vical.env.lookahead``) and scores each by the e-folds of excess it sheds per second it records (its motion and
the rest after it, as the episode's ``step_timing`` predicts them: the arm's motion and ``settle_time``, a
person's reach and the guide's wait until it sees the sensor still):

    (excess(s) - excess(s'(a))) / (motion_time(a) + rest)

the greedy rule for the least time to a threshold; a candidate that reaches the goal sheds the excess left, so of
those the quickest wins. It plans on the learned run's information state, from the data so far and the sensor's
guess, never the truth, and decides in the greedy planner's time (the same predictions).
"""

from __future__ import annotations

import numpy as np

from vical.env.calibration import CalibrationEnv
from vical.env.lookahead import Prediction
from vical.policies.greedy import DEFAULT_SAMPLES, GreedyInformationPolicy, planner_settings
from vical.policies.learned import DEFAULT_WORKSPACE


class RatePlannerPolicy(GreedyInformationPolicy):
    """The greedy planner's candidates scored by excess shed per second of recording (module doc)."""

    def scores(self, predictions: list[Prediction], env: CalibrationEnv) -> np.ndarray:
        excess, rest = env.state.excess, env.step_timing.rest
        return np.array([(excess - p.excess) / (p.motion_time + rest) for p in predictions])


def rate_planner_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    samples: int = DEFAULT_SAMPLES,
    name: str = "information-rate planner",
    max_steps: int | None = None,
) -> RatePlannerPolicy:
    """The factory ``conf/policy/rate_planner.yaml`` names: the rate planner on the information state of the learned
    run ``run_dir`` (None: the policy shipped for the workspace named ``workspace``), with its step limit
    (``max_steps``; None: the run's)."""
    settings, reward = planner_settings(run_dir, workspace, max_steps)
    return RatePlannerPolicy(settings, reward, samples, name)


class TaskRatePlanners:
    """The rate planner as a teacher on an env that draws its task per episode (``env.task_mix``): each episode
    planned with its task's number of candidates, as ``conf/policy/rate_planner.yaml`` gives them (the intrinsic
    task's predictions carry no IMU, so it affords 4x the candidates in less time)."""

    def __init__(self, samples: int, intrinsic_samples: int) -> None:
        name = "information-rate planner (the env's settings)"
        self.planners = {"intrinsic": RatePlannerPolicy({}, None, intrinsic_samples, name)}
        self.default = RatePlannerPolicy({}, None, samples, name)
        self.current = self.default

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        self.current = self.planners.get(env.task.name, self.default)
        self.current.reset(env, rng)

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        return self.current.act(obs, env)


def rate_planner_demonstrator(samples: int = DEFAULT_SAMPLES, intrinsic_samples: int = 48) -> TaskRatePlanners:
    """The factory a run's ``train.demonstrator`` names: the rate planner on the trained env's own information state,
    at its own settings, with ``samples`` random candidates a step (``intrinsic_samples`` in the intrinsic task): the
    teacher a distilled policy learns from (``conf/experiment/train_distill_rate_planner.yaml``)."""
    return TaskRatePlanners(samples, intrinsic_samples)
