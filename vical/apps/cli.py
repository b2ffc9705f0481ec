"""What the Hydra apps share on the command line: one-line errors and reading an override early.

``vical-train`` and ``vical-evaluate`` check some arguments before Hydra composes (a ``resume=``
directory must exist before Hydra creates it; an unknown ``policy=`` is one line, not Hydra's
traceback), and report user errors as ``<app>: error: <message>`` with exit status 2.
"""

from __future__ import annotations

import sys
from typing import NoReturn

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException

EXIT_USER_ERROR = 2


def fail(app: str, err: BaseException) -> NoReturn:
    """Print ``<app>: error: <message>`` on one line to stderr and exit with status 2."""
    message = " ".join(str(err).split())
    print(f"{app}: error: {message}", file=sys.stderr)
    raise SystemExit(EXIT_USER_ERROR)


def override_value(argv: list[str], key: str) -> str | None:
    """The string value of a ``key=value`` (or ``+key=value``) override in ``argv``.

    None when absent, null, empty, a sweep, or malformed (Hydra then reports the syntax error itself).
    """
    for arg in argv:
        if arg.lstrip("+").startswith(f"{key}="):
            try:
                (override,) = OverridesParser.create().parse_overrides([arg])
            except HydraException:
                return None
            value = None if override.is_sweep_override() else override.value()
            return value if isinstance(value, str) and value else None
    return None
