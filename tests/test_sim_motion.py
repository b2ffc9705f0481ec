"""IK, planning and execution of end-effector pose steps in MuJoCo physics."""

import copy
import os
import pickle

os.environ.setdefault("MUJOCO_GL", "egl")  # before mujoco is imported, for tests that render later

import mujoco
import numpy as np
import pytest

from vical.geometry import euler_to_matrix, make_transform, rotation_angle, so3_exp, transform_error
from vical.sim import PANDA_LIMITS, IKConfig, PandaSim, SimConfig
from vical.sim.motion import QUINTIC_PEAK_ACCELERATION, QUINTIC_PEAK_VELOCITY, motion_steps, quintic, quintic_plan


@pytest.fixture(scope="module")
def sim():
    return PandaSim(SimConfig())


def pose_step(T: np.ndarray, dp, drpy) -> np.ndarray:
    """``T`` moved by ``dp`` [m] (world) and rotated by Euler increments ``drpy`` [rad] (world)."""
    return make_transform(euler_to_matrix(drpy) @ T[:3, :3], T[:3, 3] + np.asarray(dp))


def test_quintic_profile_peaks_and_boundaries():
    tau = np.linspace(0.0, 1.0, 100_001)
    s, ds, dds = quintic(tau)
    assert s[0] == 0.0 and s[-1] == 1.0 and ds[0] == ds[-1] == 0.0 and dds[0] == dds[-1] == 0.0
    assert ds.max() == pytest.approx(QUINTIC_PEAK_VELOCITY, rel=1e-9)
    assert np.abs(dds).max() == pytest.approx(QUINTIC_PEAK_ACCELERATION, rel=1e-6)
    np.testing.assert_allclose(np.gradient(s, tau), ds, atol=1e-4)


def test_planned_durations_respect_scaled_velocity_and_acceleration_limits():
    rng = np.random.default_rng(3)
    dt = 0.001
    for _ in range(20):
        dq = rng.uniform(-1.5, 1.5, 7)
        steps = motion_steps(dq, PANDA_LIMITS, 0.5, 0.4, 0.2, dt)
        plan = quintic_plan(np.zeros(7), dq, steps, 0, dt)
        assert np.all(np.abs(plan.qd) <= 0.5 * PANDA_LIMITS.v_max + 1e-12)
        assert np.all(np.abs(plan.qdd) <= 0.4 * PANDA_LIMITS.a_max + 1e-12)
        # One step shorter would break a limit (or the minimum duration): the duration is tight.
        shorter = quintic_plan(np.zeros(7), dq, steps - 1, 0, dt)
        over_v = np.any(np.abs(shorter.qd) > 0.5 * PANDA_LIMITS.v_max)
        over_a = np.any(np.abs(shorter.qdd) > 0.4 * PANDA_LIMITS.a_max)
        assert over_v or over_a or (steps - 1) * dt < 0.2


def test_ik_reaches_50_random_reachable_targets():
    sim = PandaSim(SimConfig(ik=IKConfig(restart_spread=0.0)))  # restarts anywhere: a global search
    rng = np.random.default_rng(7)
    lo, hi = PANDA_LIMITS.inner(0.1)
    sim.reset()
    q_home = sim.q
    for _ in range(50):
        q_true = rng.uniform(lo, hi)
        p, R = sim.ik.forward(q_true)
        result = sim.solve_ik(make_transform(R, p), q_start=q_home)
        assert result.success
        p_ik, R_ik = sim.ik.forward(result.q)
        assert np.linalg.norm(p_ik - p) < 1e-3
        assert np.degrees(rotation_angle(R_ik.T @ R)) < 0.1
        assert np.all(result.q >= PANDA_LIMITS.q_min) and np.all(result.q <= PANDA_LIMITS.q_max)


def test_ik_step_is_numpys_damped_least_squares_to_the_last_bit(sim):
    rng = np.random.default_rng(8)
    q = np.array([0.0, -1.0, 0.0, -2.0, 0.0, 1.9, 0.79])  # inside every joint's range: nothing frozen
    for _ in range(200):
        J, err = rng.normal(size=(6, 7)), rng.normal(size=6) * 10.0 ** rng.integers(-6, 0)
        expected = J.T @ np.linalg.solve(J @ J.T + sim.cfg.ik.damping**2 * np.eye(6), err)
        assert np.array_equal(sim.ik._step(J, err, q), expected)


def test_ik_damping_must_be_positive():
    with pytest.raises(ValueError, match=r"sim\.ik\.damping"):
        IKConfig(damping=0.0)


def test_ik_restarts_stay_near_the_start_unless_their_spread_is_zero(sim):
    q0 = np.array([0.0, -1.0, 0.0, -2.0, 0.0, 1.9, 0.79])  # every joint >= 1 rad inside its range
    rng = np.random.default_rng(3)
    near = np.array([sim.ik._restart(q0, rng) for _ in range(2000)])
    np.testing.assert_allclose(near.std(axis=0), 0.3, rtol=0.1)  # N(q0, 0.3) per joint (restart_spread)
    np.testing.assert_allclose(near.mean(axis=0), q0, atol=0.03)
    anywhere = PandaSim(SimConfig(ik=IKConfig(restart_spread=0.0))).ik
    spread = np.array([anywhere._restart(q0, rng) for _ in range(2000)]).std(axis=0)
    np.testing.assert_allclose(spread, (anywhere.q_hi - anywhere.q_lo) / np.sqrt(12.0), rtol=0.1)  # uniform


def test_pose_steps_track_the_plan_within_limits(sim):
    sim.reset()
    steps = [
        ([0.15, 0.1, -0.05], [0.1, 0.15, -0.05]),
        ([-0.1, -0.2, 0.1], [-0.2, 0.0, 0.1]),
        ([0.0, 0.1, 0.2], [0, 0, -0.2]),
    ]
    for dp, drpy in steps:
        T_target = pose_step(sim.ee_pose(), dp, drpy)
        result = sim.move_to(T_target)
        assert result.reached and not result.clamped and result.message == ""
        rot_err, pos_err = transform_error(result.T_final, T_target)
        assert pos_err < 1e-3 and np.degrees(rot_err) < 0.1
        assert 1e-7 < result.max_tracking_error < 2e-3  # [rad] feed-forward + PD
        assert result.position_margin > 0.0 and result.velocity_margin > 0.0
        # A joint-space line is not a Cartesian line: longer than the straight distance, not wildly.
        straight = np.linalg.norm(dp)
        assert straight <= result.path_length < 1.6 * straight
        assert result.duration >= sim.cfg.motion.min_duration
        assert result.t_end_ns - result.t_start_ns == result.num_steps * sim.timestep_ns
    assert np.all(sim.data.warning.number == 0)


def test_on_step_reports_pre_step_time_of_derived_quantities(sim):
    """After mj_step, site poses and sensors belong to the pre-step state; t_ns says so."""
    sim.reset()
    times, site_pos, post_q = [], [], []

    def record(s, t_ns):
        times.append(t_ns)
        site_pos.append(s.data.site_xpos[s.model.site("ee").id].copy())
        post_q.append(s.data.qpos.copy())

    q_start = sim.q
    result = sim.move_to(pose_step(sim.ee_pose(), [0.05, 0.05, 0.05], [0.1, 0.0, 0.0]), on_step=record)
    assert len(times) == result.num_steps
    np.testing.assert_array_equal(np.diff(times), sim.timestep_ns)
    assert times[0] == result.t_start_ns and times[-1] == result.t_end_ns - sim.timestep_ns
    pre_q = [q_start, *post_q[:-1]]
    for k in (0, 1, len(times) // 2, len(times) - 1):
        np.testing.assert_allclose(site_pos[k], sim.ik.forward(pre_q[k])[0], atol=1e-12)


def test_settling_holds_still_and_mujocos_imu_sensors_read_rest(sim):
    sim.reset()
    gyro, accel_norm = [], []

    def record(s, t_ns):
        gyro.append(np.linalg.norm(s.data.sensor("gyro").data))
        accel_norm.append(np.linalg.norm(s.data.sensor("accel").data))

    result = sim.move_to(pose_step(sim.ee_pose(), [0.1, 0.0, 0.0], [0, 0.1, 0]), on_step=record, settle_time=0.2)
    assert result.settle_time == pytest.approx(0.2) and result.num_steps == round(1000 * (result.duration + 0.2))
    rest = slice(-150, None)  # the last 150 ms of the 200 ms rest
    assert max(gyro[rest]) < 1e-3  # [rad/s]
    np.testing.assert_allclose(accel_norm[rest], 9.81, atol=2e-3)
    assert max(gyro) > 0.05  # it did rotate before


def test_unreachable_target_runs_closest_pose_and_says_so(sim):
    sim.reset()
    T_far = make_transform(np.eye(3), [2.5, 0.0, 0.5])
    result = sim.move_to(T_far)
    assert not result.reached and result.clamped
    assert "unreachable" in result.message and "mm" in result.message
    rot_err, pos_err = transform_error(result.T_final, result.T_goal)
    assert pos_err < 1e-3 and rot_err < np.radians(0.1)
    assert result.T_final[0, 3] > sim.ik.forward(sim.model.key("home").qpos[:7])[0][0]  # it reached out
    assert result.position_margin > 0.0 and result.velocity_margin > 0.0


def test_target_in_the_floor_stops_before_contact(sim):
    sim.reset()
    T_floor = pose_step(sim.ee_pose(), [0.2, 0.0, -0.6], [0.0, 0.0, 0.0])
    result = sim.move_to(T_floor)
    assert result.clamped and "collides" in result.message and "floor" in result.message
    assert sim.data.ncon == 0
    assert result.T_final[2, 3] > 0.0
    assert np.all(sim.data.warning.number == 0)


def test_bad_pose_is_a_clear_error(sim):
    T = np.eye(4)
    T[0, 3] = np.nan
    with pytest.raises(ValueError, match="T_world_ee_target must be a finite"):
        sim.move_to(T)
    with pytest.raises(ValueError, match="not a rotation matrix"):
        sim.move_to(make_transform(so3_exp([0.1, 0, 0]) * 1.1, np.zeros(3)))


def _run_episode(seed: int) -> tuple[np.ndarray, np.ndarray]:
    sim = PandaSim(SimConfig(seed=seed))
    log_q, log_sensor = [], []

    def record(s, t_ns):
        log_q.append(s.data.qpos.copy())
        log_sensor.append(s.data.sensordata.copy())

    for dp, drpy in [([0.1, 0.1, 0.0], [0.1, 0.0, 0.1]), ([2.0, 0.0, 0.0], [0.0, 0.0, 0.0])]:
        sim.move_to(pose_step(sim.ee_pose(), dp, drpy), on_step=record)
    return np.array(log_q), np.array(log_sensor)


def test_same_seed_gives_bit_identical_trajectories():
    q_a, s_a = _run_episode(11)
    q_b, s_b = _run_episode(11)
    assert q_a.shape[0] > 1000
    np.testing.assert_array_equal(q_a, q_b)
    np.testing.assert_array_equal(s_a, s_b)


def test_motion_never_writes_qpos_directly(sim, monkeypatch):
    """Joint positions come from integration only: qpos changes by at most qvel * dt per step."""
    sim.reset()
    previous = {"q": sim.q, "v": sim.data.qvel.copy()}
    worst = []

    def record(s, t_ns):
        dq = s.data.qpos - previous["q"]
        worst.append(np.max(np.abs(dq - s.data.qvel * s.model.opt.timestep)))
        previous["q"], previous["v"] = s.data.qpos.copy(), s.data.qvel.copy()

    sim.move_to(pose_step(sim.ee_pose(), [0.0, 0.1, 0.0], [0.0, 0.0, 0.2]), on_step=record)
    # Semi-implicit Euler: q_{k+1} = q_k + dt * v_{k+1}, exactly.
    assert max(worst) < 1e-12
    assert mujoco.mjtIntegrator(sim.model.opt.integrator) == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_a_motion_without_callback_runs_in_rollout_to_the_same_floats():
    """Without ``on_step`` the steps run in MuJoCo's rollout; the result and the final state are those of stepping one
    at a time in Python, to the last bit (the frame sensors of panda.xml give the logged poses)."""

    def run(on_step):
        sim = PandaSim(SimConfig(seed=4))
        results = [
            sim.move_to(pose_step(sim.ee_pose(), dp, drpy), on_step=on_step)
            for dp, drpy in [([0.1, -0.05, 0.05], [0.2, 0.0, -0.1]), ([0.0, 0.08, 0.0], [0.0, 0.3, 0.0])]
        ]
        return results, sim

    (rolled, sim_a), (stepped, sim_b) = run(None), run(lambda s, t_ns: None)
    for a, b in zip(rolled, stepped, strict=True):
        for field in ("path_length", "rotation_length", "max_tracking_error", "position_margin", "velocity_margin"):
            assert getattr(a, field) == getattr(b, field), field
        np.testing.assert_array_equal(a.T_final, b.T_final)
        assert a.num_steps == b.num_steps > 300
    for name in ("qpos", "qvel", "qacc_warmstart", "site_xpos", "sensordata"):
        np.testing.assert_array_equal(getattr(sim_a.data, name), getattr(sim_b.data, name))
    assert sim_a.step_count == sim_b.step_count
    ee = sim_a.model.site("ee").id
    np.testing.assert_array_equal(sim_a.data.sensor("ee_pos").data, sim_a.data.site_xpos[ee])
    np.testing.assert_array_equal(sim_a.data.sensor("ee_xaxis").data, sim_a.data.site_xmat[ee].reshape(3, 3)[:, 0])


def test_a_simulator_copy_moves_as_the_original():
    """A PandaSim can be deep-copied and pickled (envs are), and the copy runs the same motion to the last bit."""
    sim = PandaSim(SimConfig(seed=5))
    twin = pickle.loads(pickle.dumps(copy.deepcopy(sim)))
    goal = pose_step(sim.ee_pose(), [0.05, 0.0, -0.05], [0.0, 0.1, 0.1])
    a, b = sim.move_to(goal), twin.move_to(goal)
    assert a.path_length == b.path_length
    np.testing.assert_array_equal(sim.data.qpos, twin.data.qpos)
