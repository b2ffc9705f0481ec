"""The simulated Panda (``PandaSim``) that executes end-effector pose steps in MuJoCo physics.

Kept for old imports: new code imports from ``vical.sim.panda``.
"""

from vical.sim.panda import *  # noqa: F403
from vical.sim.panda import (  # noqa: F401
    PandaSim,
    StepCallback,
    StepObserver,
    StepPoses,
)
