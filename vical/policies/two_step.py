"""The two-step planner: the greedy planner's best first steps, each valued with the best step after it.

The information-greedy planner (``vical.policies.greedy``) takes the candidate whose predicted step earns the
most; a step that sets up a better next one earns nothing for it. The two-step planner predicts the same
candidates (the 12 axis moves and the random draws), keeps the ``branches`` best by that one-step score, and from
where each is predicted to leave the episode (``Lookahead.following``: its offset and its fork of the
information) predicts the 12 axis moves once more. Each branch is valued by its two steps' reward, undiscounted:

    r(s, a) + max_b r(s'(a), b)

at the learned run's prices, as the greedy planner scores one step; a branch predicted to reach the goal ends
the episode there (its bonus, no second step). The branch of the highest value is taken (the first of equals in
the one-step order). The prediction is the greedy planner's, from the current estimate and the data so far, never
the truth; with ``branches=2`` a step predicts at most 48 moves, twice the greedy planner's 24
(``experiments/bench_greedy.py`` measures its decision time). With ``branches=1`` it is the greedy planner.
"""

from __future__ import annotations

import numpy as np

from vical.config_checks import require
from vical.env.calibration import CalibrationEnv
from vical.env.lookahead import Lookahead, Prediction
from vical.env.settings import RewardWeights
from vical.policies.greedy import (
    DEFAULT_SAMPLES,
    GreedyInformationPolicy,
    axis_actions,
    planner_settings,
    predicted_moves,
)
from vical.policies.learned import DEFAULT_WORKSPACE

DEFAULT_BRANCHES = 2


class TwoStepPlannerPolicy(GreedyInformationPolicy):
    """The greedy planner's best ``branches`` first steps valued with their best next step (module doc).

    Args:
        settings: the learned run's ``state``, ``information`` and ``max_steps`` (its MDP).
        reward: the learned run's reward weights (the planner's prices).
        samples: random first-step candidates beside the 12 axis moves.
        branches: the first steps (best by their own score) given a second.
        name: shown in evaluation tables.
    """

    def __init__(
        self,
        settings: dict,
        reward: RewardWeights | None,
        samples: int = DEFAULT_SAMPLES,
        branches: int = DEFAULT_BRANCHES,
        name: str = "two-step planner",
    ) -> None:
        super().__init__(settings, reward, samples, name)
        ok = isinstance(branches, int) and not isinstance(branches, bool) and branches >= 1
        require(ok, "policy.branches", "an integer >= 1 (first steps valued with a second)", branches)
        self.branches = branches

    def choice(self, lookahead: Lookahead, predictions: list[Prediction], env: CalibrationEnv) -> int:
        """The best branch by its two steps' value (the first of equals in the one-step order)."""
        first = self.scores(predictions, env)
        branches = np.argsort(-first, kind="stable")[: self.branches]
        values = [first[i] + self.next_step_value(lookahead, predictions[i], env) for i in branches]
        return int(branches[int(np.argmax(values))])

    def next_step_value(self, lookahead: Lookahead, prediction: Prediction, env: CalibrationEnv) -> float:
        """The best predicted reward of an axis move after ``prediction`` (0 after a step that reaches the goal, or
        where no axis move can move)."""
        if prediction.goal_reached:
            return 0.0
        _, after = predicted_moves(lookahead.following(prediction), axis_actions(env.action_space.high))
        return max((self.score(step, prediction.excess, env) for step in after), default=0.0)


def two_step_planner_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    samples: int = DEFAULT_SAMPLES,
    branches: int = DEFAULT_BRANCHES,
    name: str = "two-step planner",
    max_steps: int | None = None,
) -> TwoStepPlannerPolicy:
    """The factory ``conf/policy/two_step_planner.yaml`` names: the two-step planner on the information state of the
    learned run ``run_dir`` (None: the policy shipped for the workspace named ``workspace``), at its prices, with
    its step limit (``max_steps``; None: the run's)."""
    settings, reward = planner_settings(run_dir, workspace, max_steps)
    return TwoStepPlannerPolicy(settings, reward, samples, branches, name)
