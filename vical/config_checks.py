"""Config validation shared by every component: errors that name the key and the allowed range."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import MISSING, fields, is_dataclass
from types import UnionType
from typing import Any, get_args, get_type_hints


class ConfigError(ValueError):
    """A config value that is missing, malformed or out of range."""


class SettingError(ValueError):
    """A problem that changing one setting fixes; the message spells the setting as its caller wrote it.

    ``str(err)`` spells the fix as a Python argument (``gyro_unit='deg/s'``); a command-line app
    spells it as its own flag: ``err.with_flags({"gyro_unit": "--gyro-unit"})``. The template says
    ``{fix}`` where the fix goes; a message that names further settings says ``{<setting>}`` for each
    one of ``others``, spelled by ``spelled``'s ``flags`` (as Python arguments without). Subclasses add
    the error family (``vical.io.errors.UnitError`` is also a ``FormatError``).

    Attributes:
        setting: the Python argument (``gyro_unit``); python_value, cli_value: the suggested value as
            Python and a command line write it (``'deg/s'``, ``deg/s``), or None when the message names the
            setting without a value.
        others: ``{setting: (python_value, cli_value)}`` of the further settings the message names
            (a value None: the setting alone).
    """

    def __init__(
        self,
        template: str,
        setting: str,
        python_value: str | None,
        cli_value: str | None,
        others: Mapping[str, tuple[str | None, str | None]] | None = None,
    ) -> None:
        self.template, self.setting, self.python_value, self.cli_value = template, setting, python_value, cli_value
        self.others = dict(others or {})
        super().__init__(self.spelled(_spell(setting, python_value, "=")))

    def spelled(self, fix: str, flags: Mapping[str, str] | None = None) -> str:
        """The message with the fix written as ``fix`` (where the template says ``{fix}``) and each of
        ``others`` as ``flags[setting] cli_value`` (``setting=python_value`` for a setting not in ``flags``)."""
        text = self.template.replace("{fix}", fix)
        for name, (python_value, cli_value) in self.others.items():
            flag = (flags or {}).get(name)
            spelling = _spell(name, python_value, "=") if flag is None else _spell(flag, cli_value, " ")
            text = text.replace("{" + name + "}", spelling)
        return text

    def with_flags(self, flags: Mapping[str, str]) -> str:
        """The message with every setting that ``flags`` names spelled as its command-line flag."""
        if self.setting in flags:
            return self.spelled(_spell(flags[self.setting], self.cli_value, " "), flags)
        return self.spelled(_spell(self.setting, self.python_value, "="), flags)


def _spell(name: str, value: str | None, joiner: str) -> str:
    return name if value is None else f"{name}{joiner}{value}"


def require(ok: bool, key: str, allowed: str, value: Any) -> None:
    """Raise ``ConfigError`` ``"<key> must be <allowed>, got <value>"`` unless ``ok``."""
    if not ok:
        raise ConfigError(f"{key} must be {allowed}, got {value!r}")


def require_range(
    key: str,
    value: float,
    low: float | None = None,
    high: float | None = None,
    low_open: bool = False,
    high_open: bool = False,
) -> None:
    """Check ``low <= value <= high`` (``<`` where open); names the key and the interval on failure."""
    ok = isinstance(value, int | float) and value == value
    if ok and low is not None:
        ok = value > low if low_open else value >= low
    if ok and high is not None:
        ok = value < high if high_open else value <= high
    lo = "-inf" if low is None else f"{low}"
    hi = "inf" if high is None else f"{high}"
    interval = f"{'(' if low_open or low is None else '['}{lo}, {hi}{')' if high_open or high is None else ']'}"
    require(ok, key, f"a number in {interval}", value)


def from_mapping(cls: type, cfg: Mapping[str, Any], key: str) -> Any:
    """Build the dataclass ``cls`` from a config mapping, refusing unknown keys by name.

    Nested dataclass fields are built recursively; ``key`` is the dotted config path used in
    error messages (e.g. ``"sim.physics"``).
    """
    if not is_dataclass(cls):
        raise TypeError(f"{cls} is not a dataclass")
    if not isinstance(cfg, Mapping):
        raise ConfigError(f"{key} must be a mapping of settings, got {cfg!r}")
    known = {f.name: f for f in fields(cls)}
    unknown = sorted(set(cfg) - set(known))
    if unknown:
        raise ConfigError(f"{key}: unknown setting(s) {unknown}; known settings are {sorted(known)}")
    missing = [name for name, f in known.items() if name not in cfg and f.default is f.default_factory is MISSING]
    if missing:
        raise ConfigError(f"{key}: missing setting(s) {missing}; give each a value")
    hints = get_type_hints(cls)
    kwargs = {}
    for name, value in cfg.items():
        target = _nested_dataclass(hints.get(name))
        if target is not None and not (value is None and _is_optional(hints.get(name))):
            kwargs[name] = from_mapping(target, value, f"{key}.{name}")
        else:
            kwargs[name] = value
    return cls(**kwargs)


def _nested_dataclass(hint: Any) -> type | None:
    """The dataclass of a field typed ``X`` or ``X | None``, else None."""
    if isinstance(hint, type) and is_dataclass(hint):
        return hint
    if isinstance(hint, UnionType):
        classes = [a for a in get_args(hint) if isinstance(a, type) and is_dataclass(a)]
        return classes[0] if len(classes) == 1 else None
    return None


def _is_optional(hint: Any) -> bool:
    return isinstance(hint, UnionType) and type(None) in get_args(hint)
