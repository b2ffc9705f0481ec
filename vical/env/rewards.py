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

from vical.env.config import RewardWeights


def step_reward(
    coverage_before: np.ndarray, coverage_after: np.ndarray, path_length: float, rotation: float, w: RewardWeights
) -> float:
    """Coverage gain minus motion cost of one step (coverage vectors (18,))."""
    gain = float(np.abs(np.asarray(coverage_after) - np.asarray(coverage_before)).sum())
    return w.coverage_weight * gain - w.path_weight * float(path_length) - w.rotation_weight * float(rotation)


def accuracy_reward(error_pct: float | None, w: RewardWeights) -> float:
    """``c4 min(1, e_floor / e)``; 0 for a failed calibration (``None``) or a non-finite error."""
    if error_pct is None or not np.isfinite(error_pct):
        return 0.0
    return w.accuracy_weight * min(1.0, w.accuracy_error_floor / max(float(error_pct), 1e-12))


def terminal_reward(error_pct: float | None, w: RewardWeights) -> float:
    """``c3`` plus the accuracy reward of the terminal calibration."""
    return w.terminal_bonus + accuracy_reward(error_pct, w)
