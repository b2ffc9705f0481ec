"""Simulator settings (Hydra group ``sim/``), validated at start-up.

Kept for old imports: new code imports from ``vical.sim.settings``.
"""

from vical.sim.settings import *  # noqa: F403
from vical.sim.settings import (  # noqa: F401
    NUM_JOINTS,
    BoardConfig,
    IKConfig,
    MotionConfig,
    PhysicsConfig,
    SimConfig,
    StartPose,
)
