"""The frozen yardstick's fingerprint.

Kept for old imports: new code imports from ``vical.evaluation.yardstick``.
"""

from vical.evaluation.yardstick import *  # noqa: F403
from vical.evaluation.yardstick import (  # noqa: F401
    DRAW_SEED,
    NOT_EPISODE_KEYS,
    PROTOCOL_KEYS,
    fingerprint,
)
