"""The greedy planner's candidates scored by a learned critic: one step predicted, what follows valued by the agent.

The information-greedy planner (``vical.policies.greedy``) looks one step ahead and stops there: a step that sets
up a good next one earns nothing for it, and near the goal it cannot see that one more view of a kind finishes
the episode two steps later. A SAC agent trained on the information state has learned the value of every state
(its value network ``V``: the discounted return of acting on from there, at its prices). The hybrid takes the
planner's candidates and predictions (``Lookahead``) and scores each candidate ``a`` by a one-step backup of the
agent's value:

    r(s, a) + gamma * path_discount ** path(a) * V(s'(a))

- ``r``: the planner's score, the information MDP's reward of the predicted step at the run's prices;
- ``s'(a)``: the observation the agent would see after the step, built from the prediction: each group's predicted
  ratio, the offset the step heads for and the next step's fraction of the run's step limit (capped at 1: a
  longer episode than the run trained on looks to it like its last step);
- ``gamma`` and ``path_discount``: the run's discount per step and per metre, as it trained; a prediction that
  reaches the goal ends the episode (its bonus in ``r``, no value after it).

The agent's value network and the state, tolerances and prices come from the same learned run (``run_dir``),
so the backup is the Bellman equation the agent trained on, with the planner's model in place of the
simulator. It plans from the current estimate and the data so far, never the truth, as the planner does; the
value adds one network call for all candidates to the planner's decision time.
"""

from __future__ import annotations

import numpy as np
import torch

from vical.env.calibration import CalibrationEnv
from vical.env.lookahead import Prediction
from vical.env.settings import RewardWeights
from vical.policies.greedy import DEFAULT_SAMPLES, GreedyInformationPolicy, planner_settings
from vical.policies.learned import DEFAULT_WORKSPACE, LearnedPolicy, shipped_policy_dir


class CriticPlannerPolicy(GreedyInformationPolicy):
    """The planner's candidates scored by the learned run's value of the state each leads to (module doc).

    Args:
        settings: the learned run's ``state``, ``information`` and ``max_steps`` (its MDP; ``max_steps`` the
            episode's step limit).
        reward: the learned run's reward weights.
        critic: the learned run's policy (its agent's value network and discount; its workspace and action
            scale are checked against the env).
        trained_steps: the step limit the run trained with (the observation's step fraction).
        samples: random candidates per step beside the 12 axis moves.
        name: shown in evaluation tables.
    """

    def __init__(
        self,
        settings: dict,
        reward: RewardWeights,
        critic: LearnedPolicy,
        trained_steps: int,
        samples: int = DEFAULT_SAMPLES,
        name: str = "critic-scored planner",
    ) -> None:
        super().__init__(settings, reward, samples, name)
        self.critic = critic
        self.trained_steps = int(trained_steps)
        self.gamma = float(critic.agent.config.gamma)

    def check(self, env: CalibrationEnv) -> None:
        super().check(env)
        self.critic.check(env)  # its value is of the workspace and action box it trained in

    def scores(self, predictions: list[Prediction], env: CalibrationEnv) -> np.ndarray:
        """Each predicted step's reward plus the discounted value of the state it leads to."""
        rewards = super().scores(predictions, env)
        fraction = min((env.steps + 1) / self.trained_steps, 1.0)
        after = np.stack([env.state.information_observation(p.ratios, p.goal, fraction, p.axes) for p in predictions])
        with torch.no_grad():
            values = self.critic.agent.v(torch.as_tensor(after)).numpy().astype(float)
        paths = np.array([p.path_length for p in predictions])
        going_on = np.array([not p.goal_reached for p in predictions], dtype=float)
        return rewards + self.gamma * self.reward.path_discount**paths * going_on * values


def critic_planner_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    samples: int = DEFAULT_SAMPLES,
    name: str = "critic-scored planner",
    max_steps: int | None = None,
) -> CriticPlannerPolicy:
    """The factory ``conf/policy/critic_planner.yaml`` names: the planner on the information state of the learned
    run ``run_dir`` (None: the policy shipped for the workspace named ``workspace``), its candidates scored with
    that run's value network; its step limit ``max_steps`` (None: the run's)."""
    settings, reward = planner_settings(run_dir, workspace, max_steps)
    critic = LearnedPolicy.from_run(run_dir or shipped_policy_dir(workspace))
    return CriticPlannerPolicy(settings, reward, critic, critic.env_settings["max_steps"], samples, name)
