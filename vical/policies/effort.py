"""Error versus effort at path budgets, paired comparisons, the figure.

Kept for old imports: new code imports from ``vical.evaluation.error_vs_effort``.
"""

from vical.evaluation.error_vs_effort import *  # noqa: F403
from vical.evaluation.error_vs_effort import (  # noqa: F401
    BudgetSummary,
    budget_label,
    effort_figure,
    rows_at_budget,
    significance_lines,
    summarize_budget,
    summarize_effort,
    write_effort_figure,
)
