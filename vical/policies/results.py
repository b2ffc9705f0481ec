"""Results files read back, and the rule that picks the training seed to ship.

Kept for old imports: new code imports from ``vical.evaluation.results_file`` and ``vical.evaluation.seed_choice``.
"""

from vical.evaluation.results_file import *  # noqa: F403
from vical.evaluation.results_file import (  # noqa: F401
    REQUIRED,
    budgets_of,
    by_policy,
    compare,
    read_results,
)
from vical.evaluation.seed_choice import *  # noqa: F403
from vical.evaluation.seed_choice import (  # noqa: F401
    SCORED_GROUPS,
    ShipRule,
    TaskAssessment,
    assess,
    choose_seed,
    stopped_right,
)
