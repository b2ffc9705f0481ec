"""The learned policy, then the greedy planner: a hybrid that hands over at the learned run's step limit.

A learned run trains on episodes of a fixed step limit (the shipped practitioner's policy: 40 steps, ~20 s of
recording). On the sensors it trained on it reaches the tolerances within them, sooner than the greedy planner
(docs/baselines.md); a practitioner's sensor (a noisier IMU, a checkerboard) often needs longer, and past its limit
the learned policy has nothing to say: its state's step fraction would be beyond anything it trained on. The
hybrid acts as the learned policy for the run's step limit, seeing the state exactly as in training (the step
fraction of the run's limit), then as the greedy planner (``vical.policies.greedy``) on the same information state
and at the run's prices, until every group is predicted within its tolerance or the hybrid's own step limit.
Both parts read the data so far and the sensor's guess, never the truth. ``decision_times`` keeps the planner's
steps only (the learned steps take well under a millisecond).
"""

from __future__ import annotations

import numpy as np

from vical.env.calibration import CalibrationEnv
from vical.env.settings import RewardWeights
from vical.policies.greedy import DEFAULT_SAMPLES, GreedyInformationPolicy, planner_settings
from vical.policies.learned import DEFAULT_WORKSPACE, LearnedPolicy, shipped_policy_dir

DEFAULT_STEPS = 120  # ~60 s of recording: the practitioner's training episodes (the shipped policy hands over at 40)


class HandoverPolicy(GreedyInformationPolicy):
    """The learned policy for its run's step limit, the greedy planner after it (module doc).

    Args:
        settings: the learned run's ``state``, ``information`` and ``max_steps`` (``max_steps``: the hybrid's limit).
        reward: the learned run's reward weights (the planner's prices).
        learned: the learned run's policy.
        handover: the step at which the planner takes over (the run's step limit: what its state's step fraction is
            of, whenever it hands over).
        samples: the planner's random candidates per step beside the 12 axis moves.
        name: shown in evaluation tables.
    """

    def __init__(
        self,
        settings: dict,
        reward: RewardWeights,
        learned: LearnedPolicy,
        handover: int,
        samples: int = DEFAULT_SAMPLES,
        name: str = "learned, then the planner",
    ) -> None:
        super().__init__(settings, reward, samples, name)
        self.learned = learned
        self.action_scale = learned.action_scale  # its first steps are the learned policy's
        self.handover = int(handover)
        self.trained_steps = int(learned.env_settings["max_steps"])

    def check(self, env: CalibrationEnv) -> None:
        super().check(env)
        self.learned.check(env)  # its workspace, action scale and state layout

    def reset(self, env: CalibrationEnv, rng: np.random.Generator) -> None:
        super().reset(env, rng)
        self.learned.reset(env, rng)

    def act(self, obs: np.ndarray, env: CalibrationEnv) -> np.ndarray:
        if env.steps < self.handover:  # the state as the run trained on it: the fraction of its own step limit
            fraction = env.steps / self.trained_steps
            state = env.state.information_observation(env.state.ratios, env.pose_offset, fraction)
            return self.learned.act(state, env)
        return super().act(obs, env)


def handover_policy(
    run_dir: str | None = None,
    workspace: str = DEFAULT_WORKSPACE,
    samples: int = DEFAULT_SAMPLES,
    name: str = "learned, then the planner",
    max_steps: int = DEFAULT_STEPS,
) -> HandoverPolicy:
    """The factory ``conf/policy/handover.yaml`` names: the learned run ``run_dir`` (None: the policy shipped for the
    workspace named ``workspace``) for its step limit, then the planner on its information state at its prices, up to
    the hybrid's step limit ``max_steps``."""
    settings, reward = planner_settings(run_dir, workspace, max_steps)
    learned = LearnedPolicy.from_run(run_dir or shipped_policy_dir(workspace))
    return HandoverPolicy(settings, reward, learned, learned.env_settings["max_steps"], samples, name)
