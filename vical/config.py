"""Config validation shared by every component: errors that name the key and the allowed range.

Kept for old imports: new code imports from ``vical.config_checks``.
"""

from vical.config_checks import *  # noqa: F403
from vical.config_checks import (  # noqa: F401
    ConfigError,
    SettingError,
    from_mapping,
    require,
    require_range,
)
