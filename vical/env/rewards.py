"""Rewards of the calibration MDP (paper Eq. 2 and 3, with a bounded accuracy term).

Step reward: ``R_t = w ||S_t[0:18] - S_{t-1}[0:18]||_1 - c1 L_t - c2 Theta_t`` where ``L_t`` [m] and
``Theta_t`` [rad] are the path length and rotation angle the end effector actually travelled in
the step (the paper writes the pose difference; the executed path is what the evaluation reports
and is never shorter).

Terminal reward: ``R_T = c3 + c4 min(1, e_floor / e)`` with ``e`` the task's relative calibration
error [%]. The paper's ``c4 ||Phi|| / ||Phi - Phi_hat||`` is ``c4 100 / e`` in these units and
unbounded: one lucky episode with a near-zero error would dominate every other return. With
``c4 = 100`` and ``e_floor = 0.1 %`` the term equals the authors' ``0.1 / error`` for errors above
0.1 % (10 at 1 %) and is capped at 100. A failed calibration earns only ``c3``.
"""

from __future__ import annotations

import numpy as np

from vical.env.settings import InformationSettings, RewardWeights
from vical.sim.motion import MotionResult


def step_reward_terms(
    coverage_before: np.ndarray, coverage_after: np.ndarray, motion: MotionResult, w: RewardWeights
) -> dict[str, float]:
    """The step reward's terms by name (their sum is ``R_t``): coverage gain, path and rotation costs.

    Coverage vectors (18,); ``motion`` is the step's executed motion (path length [m], rotation [rad]).
    """
    gain = float(np.abs(np.asarray(coverage_after) - np.asarray(coverage_before)).sum())
    return {
        "coverage": w.coverage_weight * gain,
        "path": -w.path_weight * float(motion.path_length),
        "rotation": -w.rotation_weight * float(motion.rotation_length),
    }


def information_reward_terms(
    excess_before: float,
    excess_after: float,
    path_length: float,
    duration: float,
    goal_reached: bool,
    s: InformationSettings,
    w: RewardWeights,
) -> dict[str, float]:
    """The information MDP's step reward by term (docs/env.md): the e-folds of excess shed (``excess_*``), the
    path [m] and motion time [s] charged, the bonus when every goal group is within tolerance after the step."""
    terms = {
        "information": s.information_weight * (excess_before - excess_after),
        "path": -w.path_weight * float(path_length),
        "time": -s.time_weight * float(duration),
    }
    if goal_reached:
        terms["terminal"] = w.terminal_bonus
    return terms


def accuracy_reward(error_pct: float | None, w: RewardWeights) -> float:
    """``c4 min(1, e_floor / e)``; 0 for a failed calibration (``None``) or a non-finite error."""
    if error_pct is None or not np.isfinite(error_pct):
        return 0.0
    return w.accuracy_weight * min(1.0, w.accuracy_error_floor / max(float(error_pct), 1e-12))


def terminal_reward_terms(error_pct: float | None, w: RewardWeights) -> dict[str, float]:
    """The terminal reward's terms by name (their sum is ``R_T``): the bonus ``c3`` and the accuracy reward."""
    return {"terminal": w.terminal_bonus, "accuracy": accuracy_reward(error_pct, w)}
