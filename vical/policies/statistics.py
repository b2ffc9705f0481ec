"""Bootstrap and binomial confidence intervals.

Kept for old imports: new code imports from ``vical.evaluation.intervals``.
"""

from vical.evaluation.intervals import *  # noqa: F403
from vical.evaluation.intervals import (  # noqa: F401
    LEVEL,
    RESAMPLES,
    Interval,
    bootstrap_mean,
    paired_difference,
    proportion,
)
