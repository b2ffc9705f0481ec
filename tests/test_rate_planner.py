"""The information-rate planner: its score is excess shed per second recorded; its episodes against the greedy
planner's on the same sensors."""

from types import SimpleNamespace

import numpy as np
import pytest
from configs import env_config

from vical.env.lookahead import ArmTiming, Prediction
from vical.evaluation.harness import build_env, run_trajectory
from vical.policies.greedy import greedy_information_policy
from vical.policies.rate_planner import rate_planner_policy

SETTLE = 0.1  # [s] the env's rest after a step


def _step(motion_time: float, excess: float, goal: bool = False) -> Prediction:
    return Prediction(np.zeros(6), motion_time, 0.1, 5, {}, excess, goal)


def test_the_score_is_the_excess_shed_per_second_of_recording():
    """From an excess of 2 e-folds: a step that sheds 1 in 0.9 s (+0.1 s rest) beats one that sheds 1.5 in 1.9 s,
    which the greedy planner's reward (40 an e-fold, less 2 a second) prefers; of two that reach the goal, the
    quicker wins."""
    planner = rate_planner_policy()
    env = SimpleNamespace(state=SimpleNamespace(excess=2.0), step_timing=ArmTiming(SETTLE))
    steps = [_step(0.9, 1.0), _step(1.9, 0.5), _step(2.9, 0.0, goal=True), _step(3.9, 0.0, goal=True)]
    np.testing.assert_allclose(planner.scores(steps, env), [1.0, 0.75, 2.0 / 3.0, 0.5])


@pytest.mark.integration
@pytest.mark.parametrize("seed", [3, 4])
def test_on_the_papers_sensors_it_reaches_the_joint_goal_sooner_than_the_greedy_planner(seed):
    """The paper's sensors, joint task: both planners reach the goal; the rate planner in less recording time, on a
    shorter path. Measured: 7.7 s / 0.07 m against 16.6 s / 0.60 m (seed 3), 11.6 s / 0.32 m against 12.9 s / 0.99 m
    (seed 4)."""
    env_cfg = env_config("joint", "practitioner")
    runs = {}
    for name, policy in (("rate", rate_planner_policy()), ("greedy", greedy_information_policy())):
        env = build_env(env_cfg, policy)
        try:
            runs[name] = run_trajectory(env, policy, seed)
        finally:
            env.close()
    assert runs["rate"].coverage_reached and runs["greedy"].coverage_reached
    times = {name: run.recording.duration for name, run in runs.items()}
    paths = {name: run.recording.path_length for name, run in runs.items()}
    assert times["rate"] < times["greedy"], times
    assert paths["rate"] < paths["greedy"], paths
