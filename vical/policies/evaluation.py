"""The evaluation harness: episodes, calibrations at path budgets, table rows.

Kept for old imports: new code imports from ``vical.evaluation.harness``.
"""

from vical.evaluation.harness import *  # noqa: F403
from vical.evaluation.harness import (  # noqa: F401
    COLUMNS,
    END,
    EPISODE_FAILED,
    SPEC_KEYS,
    EpisodeRow,
    EpisodeTask,
    Evaluation,
    PolicyEvaluator,
    PolicySpec,
    Summary,
    Trajectory,
    adopt,
    build_env,
    calibrate_row,
    check_budgets,
    evaluate_policies,
    evaluate_policy,
    fill_outcome,
    instantiate_policy,
    policy_mdp,
    prior_score,
    release_evaluators,
    run_episode,
    run_trajectory,
    summarize,
)
