"""Config validation helpers: messages name the key and the allowed range."""

from dataclasses import dataclass, field

import pytest

from vical.config_checks import ConfigError, SettingError, from_mapping, require_range


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


def test_a_setting_error_spells_every_setting_it_names_for_python_or_a_command_line():
    err = SettingError(
        "use every 3rd frame ({fix}) or raise the limit ({memory_limit_mb}) or search further ({max_time_offset})",
        "frame_stride", "3", "3", {"memory_limit_mb": (None, None), "max_time_offset": ("0.2", "0.2")},
    )  # fmt: skip
    assert str(err) == (
        "use every 3rd frame (frame_stride=3) or raise the limit (memory_limit_mb) or search further "
        "(max_time_offset=0.2)"
    )
    flags = {"frame_stride": "--frame-stride", "memory_limit_mb": "--memory-limit"}
    assert err.with_flags(flags) == (
        "use every 3rd frame (--frame-stride 3) or raise the limit (--memory-limit) or search further "
        "(max_time_offset=0.2)"
    )
    assert err.with_flags({"max_time_offset": "--max-time-offset"}).endswith(
        "(frame_stride=3) or raise the limit (memory_limit_mb) or search further (--max-time-offset 0.2)"
    )
