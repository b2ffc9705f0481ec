"""The simulated person: placement error, reaches within the speed bounds, tremor in its band, lag, bad settings; the
sensor in its hand moved as the arm moves it for the calibration env."""

import numpy as np
import pytest
from hydra import compose, initialize_config_dir
from hydra.utils import instantiate
from omegaconf import OmegaConf
from scipy.spatial.transform import Rotation

from vical.apps.train import CONF_DIR
from vical.config_checks import ConfigError
from vical.env.calibration import CalibrationEnv
from vical.env.lookahead import ReachTiming
from vical.geometry import make_transform
from vical.sim import SimConfig
from vical.sim.hand_held import HandHeldSim
from vical.sim.motion import QUINTIC_PEAK_VELOCITY
from vical.sim.person import HandModel, SimulatedPerson

STILL = HandModel(tremor_m=0.0, tremor_deg=0.0)  # the reaches alone


def _angles(R: np.ndarray) -> np.ndarray:
    return np.linalg.norm(Rotation.from_matrix(R).as_rotvec(), axis=-1)


def _rates(T: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Speeds [m/s] and rotation rates [rad/s] between consecutive poses ``T`` (N, 4, 4) ``dt`` apart."""
    speed = np.linalg.norm(np.diff(T[:, :3, 3], axis=0), axis=1) / dt
    rate = _angles(np.einsum("nji,njk->nik", T[:-1, :3, :3], T[1:, :3, :3])) / dt
    return speed, rate


def test_the_hand_settles_around_the_suggestion_by_the_models_error():
    """4 cm per axis (6.9 cm rms in 3-D) and an rms angle of 10 deg, in the suggestion's frame."""
    suggestion = make_transform(Rotation.from_euler("xyz", [0.3, -0.2, 1.0]).as_matrix(), [0.4, -0.1, 0.9])
    person = SimulatedPerson(np.eye(4), np.random.default_rng(1), STILL)
    ends = np.array([person.follow(suggestion, 0.0).end for _ in range(4000)])
    errors = np.einsum("ij,njk->nik", np.linalg.inv(suggestion), ends)
    np.testing.assert_allclose(errors[:, :3, 3].std(axis=0), 0.04, rtol=0.05)
    assert np.abs(errors[:, :3, 3].mean(axis=0)).max() < 0.003
    assert np.sqrt(np.mean(np.sum(errors[:, :3, 3] ** 2, axis=1))) == pytest.approx(0.0693, rel=0.05)
    assert np.sqrt(np.mean(_angles(errors[:, :3, :3]) ** 2)) == pytest.approx(np.radians(10.0), rel=0.05)


@pytest.mark.parametrize(
    ("distance", "angle_deg", "duration"),
    [
        (0.1, 10.0, 1.5),  # a short reach: the settling time
        (2.0, 0.0, QUINTIC_PEAK_VELOCITY * 2.0 / 0.5),  # walked at the peak speed bound
        (0.0, 180.0, QUINTIC_PEAK_VELOCITY * 180.0 / 90.0),  # turned at the peak rate bound
    ],
)
def test_a_reach_takes_the_settling_time_or_is_slowed_to_the_speed_bounds(distance, angle_deg, duration):
    goal = make_transform(Rotation.from_rotvec([0.0, 0.0, np.radians(angle_deg)]).as_matrix(), [distance, 0.0, 0.0])
    person = SimulatedPerson(np.eye(4), np.random.default_rng(0), HandModel(0.0, 0.0, tremor_m=0.0, tremor_deg=0.0))
    reach = person.follow(goal, 0.0)
    assert reach.duration == pytest.approx(duration)
    dt = 1e-3
    T = person.poses(np.arange(0.0, reach.duration + 0.5, dt))
    speed, rate = _rates(T, dt)
    assert speed.max() <= 0.5 * (1 + 1e-3) and rate.max() <= np.radians(90.0) * (1 + 1e-3)
    peak = max(speed.max() / 0.5, rate.max() / np.radians(90.0))
    assert peak == pytest.approx(1.0, rel=1e-3) if duration > 1.5 else peak < 1.0
    np.testing.assert_allclose(T[-1], goal, atol=1e-12)  # at rest at the goal (no placement error here)
    np.testing.assert_allclose(T[0], np.eye(4), atol=1e-12)


def test_the_tremor_has_the_models_rms_in_its_band():
    """Time-averaged over 120 s: 1 mm and 0.3 deg rms per axis; its power within 8-12 Hz."""
    person = SimulatedPerson(np.eye(4), np.random.default_rng(3))
    dt = 1e-3
    t = np.arange(0.0, 120.0, dt)
    T = person.poses(t)
    translation = T[:, :3, 3]
    rotation = Rotation.from_matrix(T[:, :3, :3]).as_rotvec()
    np.testing.assert_allclose(np.sqrt(np.mean(translation**2, axis=0)), 0.001, rtol=0.03)
    np.testing.assert_allclose(np.sqrt(np.mean(rotation**2, axis=0)), np.radians(0.3), rtol=0.03)
    spectrum = np.abs(np.fft.rfft(translation * np.hanning(len(t))[:, None], axis=0)) ** 2
    frequencies = np.fft.rfftfreq(len(t), dt)
    band = (frequencies >= 7.9) & (frequencies <= 12.1)
    assert np.all(spectrum[band].sum(axis=0) / spectrum.sum(axis=0) > 0.999)


def test_a_suggestion_given_while_the_hand_moves_waits_for_it_to_settle_and_the_path_is_continuous():
    person = SimulatedPerson(np.eye(4), np.random.default_rng(5))
    first = person.follow(make_transform(np.eye(3), [0.5, 0.0, 0.0]), 0.0)
    second = person.follow(make_transform(np.eye(3), [0.5, 0.5, 0.0]), 0.5 * first.duration)
    later = person.follow(np.eye(4), second.t_end + 2.0)
    assert second.t0 == first.t_end and later.t0 == second.t_end + 2.0
    np.testing.assert_array_equal(second.start, first.end)
    dt = 1e-3
    speed, rate = _rates(person.poses(np.arange(0.0, later.t_end + 1.0, dt)), dt)
    # no jump: the tremor adds at most 2 pi 12 Hz x its summed amplitudes (8 x 0.5 mm, 8 x 0.15 deg per axis)
    shake = 2 * np.pi * 12 * 8 * np.sqrt(3)
    assert speed.max() < 0.5 + shake * 0.0005 and rate.max() < np.radians(90.0 + shake * 0.15)


def test_one_seed_gives_one_person():
    def walk(seed: int) -> np.ndarray:
        person = SimulatedPerson(np.eye(4), np.random.default_rng(seed))
        person.follow(make_transform(np.eye(3), [0.3, 0.1, 0.0]), 0.0)
        return person.poses(np.linspace(0.0, 3.0, 50))

    np.testing.assert_array_equal(walk(7), walk(7))
    assert not np.allclose(walk(7), walk(8))


@pytest.mark.parametrize(
    ("setting", "value", "message"),
    [
        ("settle_s", 0.0, r"person\.settle_s must be a number in \(0\.0, inf\)"),
        ("placement_sigma_m", -0.01, r"person\.placement_sigma_m must be a number in \[0\.0, inf\)"),
        ("max_rate", float("nan"), r"person\.max_rate must be a number in \(0\.0, inf\)"),
        ("tremor_band_hz", (12.0, 8.0), r"person\.tremor_band_hz must be \[low, high\]"),
    ],
)
def test_bad_hand_settings_are_refused_by_key(setting, value, message):
    with pytest.raises(ConfigError, match=message):
        HandModel(**{setting: value})


@pytest.mark.integration
def test_the_hand_held_sim_moves_as_the_arm_does_for_the_env_the_person_reaching_each_goal():
    """``HandHeldSim.move_to`` (the env's person): a still, exact hand ends where it is sent, its path the straight
    distance and its rotation the geodesic angle (the minimum-jerk reach), the reach's duration plus the rest
    recorded; with the model's errors the goals are reached within 4 cm per axis."""
    exact = HandModel(placement_sigma_m=0.0, placement_sigma_deg=0.0, tremor_m=0.0, tremor_deg=0.0)
    sim = HandHeldSim(SimConfig(), np.random.default_rng(0), exact)
    start = sim.ee_pose()
    turn = Rotation.from_euler("xyz", [0.2, -0.1, 0.3]).as_matrix()
    goal = make_transform(start[:3, :3] @ turn, start[:3, 3] + [0.1, -0.05, 0.02])
    motion = sim.move_to(goal, settle_time=0.3)
    np.testing.assert_allclose(motion.T_final, goal, atol=1e-9)
    assert motion.path_length == pytest.approx(np.linalg.norm([0.1, -0.05, 0.02]), rel=1e-6)
    assert motion.rotation_length == pytest.approx(_angles(turn), rel=1e-4)
    assert motion.duration == pytest.approx(1.5, abs=1e-3) and motion.settle_time == 0.3
    assert motion.t_end_ns - motion.t_start_ns == pytest.approx(1.8e9, abs=1e6)

    sim = HandHeldSim(SimConfig(), np.random.default_rng(1), HandModel(tremor_m=0.0, tremor_deg=0.0))
    errors = []
    for _ in range(300):
        T_before = sim.ee_pose()
        errors.append(np.linalg.inv(T_before) @ sim.move_to(T_before).T_final)
    errors = np.array(errors)
    np.testing.assert_allclose(errors[:, :3, 3].std(axis=0), 0.04, rtol=0.15)
    sim.reset(seed=5)
    assert sim.time_ns == 0
    np.testing.assert_allclose(sim.ee_pose(), start, atol=1e-9)


@pytest.mark.parametrize(
    ("translation", "rotvec"),
    [
        ([0.1, -0.05, 0.02], [0.0, 0.0, 0.0]),  # short: the shortest reach
        ([0.5, 0.3, 0.0], [0.0, 0.0, 0.0]),  # far: slowed to the peak speed
        ([0.05, 0.0, 0.0], [0.0, 0.0, 2.0]),  # a large turn: slowed to the peak rate
        ([0.3, 0.1, -0.1], [0.0, 0.9, 0.0]),  # both
    ],
)
def test_the_planners_timing_of_a_reach_is_the_simulated_persons(translation, rotvec):
    """``ReachTiming`` (what a planner predicts a guided step to take) gives the duration of the simulated person's
    reach over the same change of pose (an exact, still hand), for a reach of each of its three limits."""
    exact = HandModel(placement_sigma_m=0.0, placement_sigma_deg=0.0, tremor_m=0.0, tremor_deg=0.0)
    person = SimulatedPerson(np.eye(4), np.random.default_rng(0), exact)
    reach = person.follow(make_transform(Rotation.from_rotvec(rotvec).as_matrix(), translation), 0.0)
    timing = ReachTiming.of(exact, rest=0.5)
    assert timing.motion_time(np.r_[translation, rotvec]) == pytest.approx(reach.duration, rel=1e-9)
    assert timing.rest == 0.5 and timing.motion_time(np.zeros(6)) == 0.0
    assert ReachTiming() == ReachTiming.of(HandModel(), 0.0)  # its defaults: the simulated person's


@pytest.mark.parametrize("setting", ["min_s", "max_speed", "max_rate"])
def test_a_reach_timing_without_time_or_speed_is_refused_by_key(setting):
    with pytest.raises(ConfigError, match=rf"reach\.{setting} must be a number in \(0\.0, inf\)"):
        ReachTiming(**{setting: 0.0})


def test_the_env_with_a_hand_steps_through_the_person():
    """``CalibrationEnv(hand={})``: each step is the person's reach (at least 1.5 s, then ``settle_time``), the
    sensor lands near the goal (the hand's error, not the arm's precision), and a seed gives one episode."""
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="train", overrides=["+experiment=train_person_policy"])
    env = instantiate(cfg.env, _convert_="all")
    try:
        episodes = []
        for _ in range(2):
            env.reset(seed=7)
            actions = np.random.default_rng(3).uniform(env.action_space.low, env.action_space.high, (3, 6))
            steps = [env.step(a)[1] for a in actions]
            episodes.append((steps, env.recording().duration, env.pose_offset))
        assert episodes[0][0] == episodes[1][0] and episodes[0][1] == episodes[1][1]
        np.testing.assert_array_equal(episodes[0][2], episodes[1][2])
        assert 3 * (1.5 + 0.3) <= episodes[0][1] - cfg.env.reset_hold < 3 * 4.0
        # a planner in this env predicts the person's reaches, then the env's rest
        assert env.step_timing == ReachTiming.of(env.hand, env.config.settle_time)
    finally:
        env.close()
    settings = {k: v for k, v in OmegaConf.to_container(cfg.env, resolve=True).items() if k != "_target_"}
    with pytest.raises(ConfigError, match=r"env\.hand: unknown setting\(s\) \['steadiness'\]"):
        CalibrationEnv(**{**settings, "hand": {"steadiness": 1.0}})
