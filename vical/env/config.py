"""Settings of the calibration MDP (``conf/env/calibration.yaml``), validated at start-up.

Kept for old imports: new code imports from ``vical.env.settings``.
"""

from vical.env.settings import *  # noqa: F403
from vical.env.settings import (  # noqa: F401
    FRAMES,
    GOAL_GROUPS,
    GROUP_TOLERANCE,
    STATES,
    InformationSettings,
    MdpConfig,
    RewardWeights,
    Thresholds,
    Tolerances,
    Workspace,
)
