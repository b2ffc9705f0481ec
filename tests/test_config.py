"""Config validation helpers: messages name the key and the allowed range."""

from dataclasses import dataclass, field

import pytest

from vical.config import ConfigError, from_mapping, require_range


@dataclass
class Inner:
    timestep: float = 0.001

    def __post_init__(self):
        require_range("sim.physics.timestep", self.timestep, 0.0, None, low_open=True)


@dataclass
class Outer:
    physics: Inner = field(default_factory=Inner)
    name: str = "x"


def test_nested_mapping_builds_dataclasses():
    cfg = from_mapping(Outer, {"physics": {"timestep": 0.002}, "name": "y"}, "sim")
    assert isinstance(cfg.physics, Inner) and cfg.physics.timestep == 0.002


def test_out_of_range_value_names_key_and_interval():
    with pytest.raises(ConfigError, match=r"sim\.physics\.timestep must be a number in \(0\.0, inf\), got -0\.001"):
        from_mapping(Outer, {"physics": {"timestep": -0.001}}, "sim")


def test_unknown_key_is_listed():
    with pytest.raises(ConfigError, match=r"sim\.physics: unknown setting\(s\) \['timstep'\]"):
        from_mapping(Outer, {"physics": {"timstep": 0.001}}, "sim")


def test_nan_is_out_of_range():
    with pytest.raises(ConfigError, match="timestep"):
        require_range("sim.physics.timestep", float("nan"), 0.0, 1.0)
