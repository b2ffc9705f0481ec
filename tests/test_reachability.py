"""The reachability forecast: each group's time to tolerance against analytic growth, the verdict, its line."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from vical.config_checks import ConfigError
from vical.env.lookahead import ArmTiming, ReachTiming
from vical.env.reachability import ReachForecast, ReachSettings, check_horizon

TOLERANCES = {"rotation": 0.1, "translation": 2.0, "time_offset": 0.1}
STEP_S = 0.7  # [s] a step of recording, as the simulated Panda's


def feed(forecast: ReachForecast, ratio_of, until_s: float, start_s: float = 0.3) -> None:
    """``ratio_of(t)``: each group's ratio after ``t`` [s], fed once a step from ``start_s`` to ``until_s``."""
    for t in np.arange(start_s, until_s + 1e-9, STEP_S):
        forecast.add(float(t), ratio_of(float(t)))


def power_law(r0: float, t0: float, power: float):
    """A ratio ``r0`` at ``t0`` whose information grows as ``t^power``: ``r = r0 (t / t0)^(-power / 2)``."""
    return lambda t: r0 * (t / t0) ** (-power / 2)


@pytest.mark.parametrize("power", [0.6, 1.0, 1.7])
def test_the_time_a_group_needs_is_the_analytic_one_for_information_growing_as_a_power_of_time(power):
    ratio = power_law(3.0, 10.0, power)  # reaches 1 at t0 * r0^(2 / power)
    forecast = ReachForecast(TOLERANCES)
    feed(forecast, lambda t: {"rotation": ratio(t), "translation": 0.5, "time_offset": 0.5}, 20.0)
    needed = 10.0 * 3.0 ** (2 / power)
    groups = forecast.groups(45.0)
    assert groups["rotation"].needed_s == pytest.approx(needed, rel=1e-6)
    assert groups["rotation"].ratio_at_horizon == pytest.approx(ratio(45.0), rel=1e-6)
    assert groups["translation"].needed_s == pytest.approx(forecast.time_s)  # already within: now
    assert forecast.needed_s() == pytest.approx(needed, rel=1e-6)


def test_a_group_on_a_floor_is_never_reached_and_called_out_of_reach_once_held():
    forecast = ReachForecast(TOLERANCES)
    ratios = lambda t: {"rotation": 0.8, "translation": 0.7, "time_offset": max(1.6, 30 / t)}  # noqa: E731
    feed(forecast, ratios, 60.0)  # the latest half flat
    assert math.isinf(forecast.groups()["time_offset"].needed_s)
    verdict = forecast.verdict(45.0)
    assert verdict is not None and verdict.group == "time_offset"
    assert verdict.achievable == pytest.approx(0.16)  # the floor: 1.6 x 0.1 ms
    line = verdict.line()
    assert "time offset cannot reach its tolerance 0.1 ms within 45 s" in line
    assert "does not shrink any more" in line and "synchronised clock" in line and "\n" not in line


def test_a_slow_group_is_out_of_reach_with_the_time_it_needs_and_what_it_reaches_at_the_horizon():
    ratio = power_law(4.0, 10.0, 1.0)  # needs 10 * 16 = 160 s > 2 x 45 s
    forecast = ReachForecast(TOLERANCES)
    feed(forecast, lambda t: {"rotation": 0.5, "translation": 2 * ratio(t), "time_offset": 0.5}, 14.0)
    assert forecast.verdict(45.0) is None  # the warm-up
    feed(forecast, lambda t: {"rotation": 0.5, "translation": 2 * ratio(t), "time_offset": 0.5}, 40.0, 14.7)
    verdict = forecast.verdict(45.0)
    assert verdict.group == "translation" and verdict.needed_s == pytest.approx(640.0, rel=1e-6)
    assert verdict.achievable == pytest.approx(2.0 * 2 * ratio(45.0), rel=1e-6)
    assert "or a longer horizon (~640 s)" in verdict.line() and "lower-noise IMU" in verdict.line()
    assert verdict.as_dict()["needed_s"] == pytest.approx(640.0, abs=0.1)
    assert forecast.verdict(400.0) is None  # within 2 x 400 s: in reach


@pytest.mark.parametrize("board, group, aprilgrid", [("checkerboard", "translation", True),
                                                     ("aprilgrid", "translation", False),
                                                     ("checkerboard", "time_offset", False)])  # fmt: skip
def test_a_checkerboard_sensors_verdict_names_an_aprilgrid_where_the_board_limits_the_group(board, group, aprilgrid):
    # A checkerboard is detected only whole: its views never take the image's borders (docs/evaluation.md).
    ratio = power_law(4.0, 10.0, 1.0)
    forecast = ReachForecast(TOLERANCES, board_kind=board)
    others = dict.fromkeys(TOLERANCES, 0.5)
    feed(forecast, lambda t: {**others, group: 2 * ratio(t)}, 40.0)
    line = forecast.verdict(45.0).line()
    assert ("an aprilgrid instead of the checkerboard" in line) == aprilgrid
    assert ("lower-noise IMU" if group == "translation" else "synchronised clock") in line


@pytest.mark.parametrize("graded, group, calibrated_imu", [(True, "rotation", True), (False, "rotation", False),
                                                            (True, "time_offset", False)])  # fmt: skip
def test_a_graded_imus_verdict_names_a_calibrated_imu_where_its_terms_limit_the_group(graded, group, calibrated_imu):
    # The grade's scales and misalignments leave the extrinsic a floor (the information state's considered terms).
    forecast = ReachForecast(TOLERANCES, imu_graded=graded)
    others = dict.fromkeys(TOLERANCES, 0.5)
    feed(forecast, lambda t: {**others, group: max(1.6, 30 / t)}, 60.0)
    line = forecast.verdict(45.0).line()
    assert ("an IMU whose scales and misalignments are calibrated" in line) == calibrated_imu
    assert ("lower-noise IMU" if group == "rotation" else "synchronised clock") in line


def test_a_group_in_reach_within_the_margin_is_not_called_out_of_reach():
    ratio = power_law(2.0, 20.0, 1.0)  # needs 80 s: past the 45 s horizon, within 2 x 45 s
    forecast = ReachForecast(TOLERANCES)
    feed(forecast, lambda t: {"rotation": ratio(t), "translation": 0.5, "time_offset": 0.5}, 44.0)
    assert forecast.groups(45.0)["rotation"].needed_s == pytest.approx(80.0, rel=1e-6)
    assert forecast.verdict(45.0) is None
    assert forecast.verdict(None) is None


def test_one_steps_setback_is_no_verdict_until_it_has_held_for_hold_s():
    # The information state's ratios are not monotone: a step can lose a view's information for a while.
    ratio = power_law(2.0, 10.0, 1.0)
    setback = lambda t: {"rotation": ratio(t) * (1.5 if 20.0 <= t < 24.0 else 1.0)}  # noqa: E731
    forecast = ReachForecast({"rotation": 0.1}, ReachSettings(hold_s=10.0))
    for t in np.arange(0.3, 40.0, STEP_S):
        forecast.add(float(t), setback(float(t)))
        assert forecast.verdict(45.0) is None, t


def test_updates_at_one_instant_replace_the_last_and_the_outlook_says_when_the_goal_is_due():
    forecast = ReachForecast({"rotation": 0.1})
    assert forecast.outlook() == "" and math.isnan(forecast.needed_s())
    forecast.add(1.0, {"rotation": 4.0})
    forecast.add(2.0, {"rotation": 3.0})
    forecast.add(2.0, {"rotation": 2.0})  # no new frame: the same instant
    assert forecast.groups()["rotation"].ratio == 2.0
    assert forecast.needed_s() == pytest.approx(4.0)  # J = 1/16 at 1 s, 1/4 at 2 s: J ~ t^2, 1 at 4 s
    assert forecast.outlook().startswith(", goal at ~")


@pytest.mark.parametrize(
    "key, value",
    [("warmup_s", -1.0), ("margin", 0.5), ("rate_fraction", 0.0), ("min_window_s", 0.0), ("hold_s", -1.0)],
)
def test_bad_settings_name_their_key(key, value):
    with pytest.raises(ConfigError, match=rf"reach\.{key}"):
        ReachSettings(**{key: value})


def test_a_horizon_below_one_step_is_refused_naming_its_key():
    check_horizon(None, "stop.horizon_s", 0.3, ArmTiming(0.1))
    check_horizon(0.8, "stop.horizon_s", 0.3, ArmTiming(0.1))  # 0.3 + 0.37 + 0.1
    with pytest.raises(ConfigError, match=r"stop.horizon_s must be at least one step of recording \(0.77 s"):
        check_horizon(0.5, "stop.horizon_s", 0.3, ArmTiming(0.1))
    with pytest.raises(ConfigError, match=r"limits\.horizon_s"):
        check_horizon(1.0, "limits.horizon_s", 0.3, ReachTiming(rest=0.5))


@pytest.mark.integration
def test_the_yardsticks_runs_stop_as_out_of_reach_and_their_verdict_is_checked_by_running_on():
    """The time-to-tolerance yardstick's protocol on two tuning sensors of the joint task with the information-rate
    planner: seed 40000 (a 5.3x-noise IMU) stops as out of reach within the horizon and, run on to twice it, does
    not reach the goal; seed 40001 reaches the goal, and the forecast halfway to it said about when."""
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from vical.apps.evaluate import CONF_DIR, policy_configs
    from vical.evaluation.harness import PolicyEvaluator, PolicySpec
    from vical.policies.stopping import StopRule

    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(
            config_name="evaluate", overrides=["+experiment=time_to_tolerance_joint", "policies=[rate_planner]"]
        )
    stop = StopRule.from_config(OmegaConf.to_container(cfg.stop, resolve=True))
    assert (stop.horizon_s, stop.out_of_reach, stop.verify_s) == (45, True, 90)
    spec = PolicySpec.from_config(policy_configs(cfg, "learned")[0], "policy")
    evaluator = PolicyEvaluator(dataclasses.replace(spec, stop=stop), OmegaConf.to_container(cfg.env, resolve=True))
    try:
        given_up, finished = evaluator.episode(40000)[-1], evaluator.episode(40001)[-1]
    finally:
        evaluator.close()
    assert given_up.out_of_reach and not given_up.coverage_reached and given_up.reached_s is None
    assert 15 <= given_up.verdict_s <= 45 and given_up.recording_time_s == pytest.approx(given_up.verdict_s, abs=0.2)
    assert not given_up.failed and given_up.time_offset_ms is not None  # calibrated up to the verdict
    assert finished.coverage_reached and not finished.out_of_reach and finished.reached_s < 45
    assert finished.predicted_s == pytest.approx(finished.recording_time_s, rel=0.5)
