"""IMU simulation: window averaging, Kalibr noise statistics, streaming, physics readings vs kinematics."""

from dataclasses import replace

import mujoco
import numpy as np
import pytest

from vical.data import ImuIntrinsics, ImuNoise
from vical.geometry import euler_to_matrix, make_transform, so3_log
from vical.sim import PandaSim, camera_pose_cv, set_imu_pose, site_pose
from vical.sim.imu import (
    ImuNoiseProcess,
    ImuSimulationError,
    ImuSimulator,
    ImuSiteReader,
    discrete_sigmas,
    window_weights,
)
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import ImuSampling, SensorSampling, mean_sensor, sample_sensor

STEP_NS = 1_000_000  # 1 ms physics step


@pytest.mark.parametrize("n", [1, 2, 4, 5, 10])
def test_average_window_integrates_the_sample_interval(n):
    offsets, weights = window_weights(n, "average")
    assert weights.sum() == pytest.approx(1.0)
    # Symmetric about the sample instant: no group delay.
    np.testing.assert_array_equal(offsets, -offsets[::-1])
    np.testing.assert_allclose(weights, weights[::-1])
    # Exact for a line; the quadratic's window mean (t^2 over [-n/2, n/2] -> n^2/12) within the rule's error.
    assert weights @ (3.0 * offsets + 1.0) == pytest.approx(1.0)
    rule_error = (1.0 / 6.0 if n % 2 == 0 else -1.0 / 12.0) if n > 1 else -n * n / 12.0
    assert weights @ offsets.astype(float) ** 2 == pytest.approx(n * n / 12.0 + rule_error)


def test_instant_window_is_one_reading():
    offsets, weights = window_weights(5, "instant")
    assert offsets.tolist() == [0] and weights.tolist() == [1.0]


def test_discrete_sigmas_follow_kalibr():
    sig = discrete_sigmas(ImuNoise(rate_hz=200.0))
    assert sig["accel_white"] == pytest.approx(0.004 * np.sqrt(200.0))
    assert sig["gyro_white"] == pytest.approx(0.0003394 * np.sqrt(200.0))
    assert sig["accel_walk"] == pytest.approx(0.006 / np.sqrt(200.0))
    assert sig["gyro_walk"] == pytest.approx(0.000038785 / np.sqrt(200.0))


def test_noise_statistics_match_the_densities():
    noise = ImuNoise(rate_hz=200.0)
    bias0_gyro, bias0_accel = np.array([0.01, -0.02, 0.03]), np.array([0.1, 0.2, -0.3])
    process = ImuNoiseProcess(noise, np.random.default_rng(11), bias0_gyro, bias0_accel)
    n = 200_000
    gyro, accel, biases = process.apply(np.zeros((n, 3)), np.zeros((n, 3)))
    np.testing.assert_array_equal(biases[0], np.concatenate([bias0_gyro, bias0_accel]))
    sig = discrete_sigmas(noise)
    white = np.hstack([gyro, accel]) - biases
    increments = np.diff(biases, axis=0)
    expected_white = [sig["gyro_white"]] * 3 + [sig["accel_white"]] * 3
    expected_walk = [sig["gyro_walk"]] * 3 + [sig["accel_walk"]] * 3
    # Variance within 10 % (its relative sigma over 2e5 samples is 0.3 %).
    np.testing.assert_allclose(white.var(axis=0), np.square(expected_white), rtol=0.1)
    np.testing.assert_allclose(increments.var(axis=0), np.square(expected_walk), rtol=0.1)
    # White noise is uncorrelated from sample to sample; the walk's increments too.
    assert abs(np.corrcoef(white[:-1, 0], white[1:, 0])[0, 1]) < 0.01
    assert abs(np.corrcoef(increments[:-1, 3], increments[1:, 3])[0, 1]) < 0.01


def test_bias_walk_grows_like_sqrt_time():
    noise = ImuNoise(rate_hz=200.0)
    runs = [ImuNoiseProcess(noise, np.random.default_rng(s), np.zeros(3), np.zeros(3)) for s in range(400)]
    final = np.array([r.apply(np.zeros((2001, 3)), np.zeros((2001, 3)))[2][-1] for r in runs])
    seconds = 2000 / 200.0
    np.testing.assert_allclose(final[:, 3:].std(axis=0), 0.006 * np.sqrt(seconds), rtol=0.15)


def test_noise_does_not_depend_on_chunking():
    noise = ImuNoise(rate_hz=200.0)
    whole = ImuNoiseProcess(noise, np.random.default_rng(5), np.zeros(3), np.zeros(3))
    parts = ImuNoiseProcess(noise, np.random.default_rng(5), np.zeros(3), np.zeros(3))
    truth = np.arange(60.0).reshape(20, 3)
    g_whole, a_whole, _ = whole.apply(truth, truth)
    pieces = [parts.apply(truth[i:j], truth[i:j]) for i, j in [(0, 3), (3, 4), (4, 20)]]
    np.testing.assert_array_equal(np.vstack([p[0] for p in pieces]), g_whole)
    np.testing.assert_array_equal(np.vstack([p[1] for p in pieces]), a_whole)


def _readings(steps, signal):
    return np.array([np.concatenate([signal(k * STEP_NS), 2.0 * signal(k * STEP_NS)]) for k in steps])


def _feed(sim, steps, signal, chunk=1):
    """Feed the readings of ``steps`` (consecutive) ``chunk`` at a time."""
    readings = _readings(steps, signal)
    for i in range(0, len(steps), chunk):
        sim.add_readings(steps[i] * STEP_NS, readings[i : i + chunk])


def test_streaming_average_of_a_known_signal():
    # A cubic in time: the centred average of 5 readings is the value at the centre plus a known term.
    def signal(t_ns):
        s = t_ns * 1e-9
        return np.array([s, s**2, s**3])

    sim = ImuSimulator(STEP_NS, 5, "average")
    _feed(sim, range(3, 40), signal)
    samples = sim.samples()
    # First sample whose window [t-2, t+2] ms lies inside the readings from 3 ms: t = 5 ms; last: t = 35 ms.
    assert samples.t.tolist() == [5_000_000 * k for k in range(1, 8)]
    s = samples.t * 1e-9
    mean_sq = 2.0 * (1e-3) ** 2  # mean of (k dt)^2, k = -2..2
    np.testing.assert_allclose(samples.gyro[:, 0], s, atol=1e-15)
    np.testing.assert_allclose(samples.gyro[:, 1], s**2 + mean_sq, atol=1e-15)
    np.testing.assert_allclose(samples.gyro[:, 2], s**3 + 3 * s * mean_sq, atol=1e-15)
    np.testing.assert_allclose(samples.accel, 2.0 * samples.gyro, atol=1e-15)


def test_instant_samples_are_the_readings_on_the_imu_grid():
    sim = ImuSimulator(STEP_NS, 5, "instant")
    _feed(sim, range(0, 23), lambda t: np.full(3, t * 1e-9))
    samples = sim.samples()
    assert samples.t.tolist() == [0, 5_000_000, 10_000_000, 15_000_000, 20_000_000]
    np.testing.assert_allclose(samples.gyro[:, 0], samples.t * 1e-9)


def test_streaming_equals_one_batch_and_noise_is_seeded():
    def make():
        return ImuSimulator(STEP_NS, 5, "average", ImuNoise(), np.random.default_rng(2), np.ones(3), np.zeros(3))

    a, b, c = make(), make(), make()
    signal = lambda t: np.sin(np.arange(3) + t * 1e-8)  # noqa: E731
    _feed(a, range(100), signal, chunk=100)
    _feed(b, range(50), signal)
    b.samples()  # a query in the middle changes nothing
    _feed(b, range(50, 100), signal)
    c.add_readings(123 * STEP_NS, np.zeros((0, 6)))  # an empty block, at any time, changes nothing
    _feed(c, range(100), signal, chunk=7)  # chunks that end inside sample windows
    assert len(a.samples()) == 19
    for other in (b, c):
        np.testing.assert_array_equal(a.samples().gyro, other.samples().gyro)
        np.testing.assert_array_equal(a.samples().accel, other.samples().accel)


def test_missing_physics_step_is_an_error():
    sim = ImuSimulator(STEP_NS, 5, "average")
    sim.add_readings(0, np.zeros((2, 6)))
    with pytest.raises(ImuSimulationError, match="every physics step: expected t = 2000000 ns, got 3000000 ns"):
        sim.add_readings(3 * STEP_NS, np.zeros((1, 6)))
    with pytest.raises(ImuSimulationError, match="not on the physics grid"):
        sim.add_readings(STEP_NS + 7, np.zeros((1, 6)))


def test_noise_needs_a_generator():
    with pytest.raises(ValueError, match="seeded numpy Generator"):
        ImuSimulator(STEP_NS, 5, "average", ImuNoise())


# ------------------------------------------------------------------ physics readings vs kinematics
@pytest.fixture(scope="module")
def moving_rig():
    """A recorded motion with a tilted IMU: the recorder's noise-free samples and the executed joint states."""
    sim = PandaSim()
    sampling = SensorSampling(imu=ImuSampling(sampling="instant"))
    truth = replace(
        sample_sensor(sampling, np.random.default_rng(4)),
        imu_noise=ImuNoise(0.0, 0.0, 0.0, 0.0, 200.0),
    )
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling)
    recorder.start(truth, np.random.default_rng(0))
    states = {sim.time_ns: (sim.data.qpos.copy(), sim.data.qvel.copy())}

    def on_step(s, t_ns):
        states[t_ns + s.timestep_ns] = (s.data.qpos.copy(), s.data.qvel.copy())  # post-step state

    T_goal = sim.ee_pose() @ make_transform(euler_to_matrix([0.25, -0.15, 0.2]), [0.08, -0.06, 0.05])
    sim.move_to(T_goal, on_step=on_step, observer=recorder)
    return sim, recorder, states


def _kinematic_imu(sim, states, t_ns):
    """Angular rate, specific force, velocity and rotation of site imu at ``t_ns`` from positions only.

    Forward kinematics of the executed joint positions at ``t - h``, ``t`` and ``t + h`` and
    central differences: independent of MuJoCo's sensors and of its (half-step staggered)
    velocities, so it is the motion the camera sees.
    """
    model, h_ns = sim.model, sim.timestep_ns
    h = h_ns * 1e-9
    scratch = mujoco.MjData(model)
    site = model.site("imu").id
    poses = []
    for dt in (-h_ns, 0, h_ns):
        scratch.qpos[:] = states[t_ns + dt][0]
        mujoco.mj_kinematics(model, scratch)
        poses.append((scratch.site_xpos[site].copy(), scratch.site_xmat[site].reshape(3, 3).copy()))
    (p_m, R_m), (p_0, R_0), (p_p, R_p) = poses
    accel_world = (p_p - 2.0 * p_0 + p_m) / h**2
    specific_force = R_0.T @ (accel_world - model.opt.gravity)
    omega = (so3_log(R_0.T @ R_p) - so3_log(R_0.T @ R_m)) / (2.0 * h)
    return omega, specific_force, (p_p - p_m) / (2.0 * h), R_0


def _with_neighbours(states, times, step_ns):
    """Indices of ``times`` whose previous and next physics states were recorded."""
    return [k for k, t in enumerate(times) if int(t) - step_ns in states and int(t) + step_ns in states]


def test_noise_free_imu_matches_kinematics(moving_rig):
    sim, recorder, states = moving_rig
    imu = recorder.recording().imu
    keep = _with_neighbours(states, imu.t, sim.timestep_ns)
    assert len(keep) > 50
    reference = [_kinematic_imu(sim, states, int(imu.t[k])) for k in keep]
    gyro_ref = np.array([r[0] for r in reference])
    accel_ref = np.array([r[1] for r in reference])
    assert np.abs(gyro_ref).max() > 0.2 and np.abs(accel_ref - accel_ref[0]).max() > 0.2  # it moves
    np.testing.assert_allclose(imu.gyro[keep], gyro_ref, atol=1e-4)
    np.testing.assert_allclose(imu.accel[keep], accel_ref, atol=1e-4)


def test_ground_truth_trajectory_matches_kinematics(moving_rig):
    sim, recorder, states = moving_rig
    rec = recorder.recording()
    traj = rec.trajectory
    np.testing.assert_array_equal(traj.t, rec.imu.t)
    for k in _with_neighbours(states, traj.t, sim.timestep_ns)[::7]:
        omega, _, v_world, R = _kinematic_imu(sim, states, int(traj.t[k]))
        np.testing.assert_allclose(traj.T_world_imu[k, :3, :3], R, atol=1e-12)
        np.testing.assert_allclose(traj.v_world[k], v_world, atol=1e-6)
        np.testing.assert_allclose(traj.omega_imu[k], omega, atol=1e-6)


def test_imu_pose_is_the_camera_pose_times_the_extrinsic(moving_rig):
    sim, recorder, _ = moving_rig
    T_world_imu = site_pose(sim.model, sim.data, "imu")
    T_world_cam = camera_pose_cv(sim.model, sim.data)
    np.testing.assert_allclose(T_world_imu, T_world_cam @ recorder.truth.T_cam_imu, atol=1e-9)


def test_averaged_samples_are_the_window_mean_of_the_kinematics():
    sim = PandaSim()
    sampling = SensorSampling()  # average
    truth = replace(mean_sensor(sampling), imu_noise=ImuNoise(0.0, 0.0, 0.0, 0.0, 200.0))
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling)
    recorder.start(truth, np.random.default_rng(0))
    states = {sim.time_ns: (sim.data.qpos.copy(), sim.data.qvel.copy())}

    def on_step(s, t_ns):
        states[t_ns + s.timestep_ns] = (s.data.qpos.copy(), s.data.qvel.copy())

    T_goal = sim.ee_pose() @ make_transform(euler_to_matrix([-0.2, 0.1, 0.15]), [0.0, 0.05, 0.05])
    sim.move_to(T_goal, on_step=on_step, observer=recorder)
    imu = recorder.recording().imu
    offsets, weights = window_weights(5, "average")
    for k in range(1, len(imu) - 1, 9):
        t = int(imu.t[k])
        window = [_kinematic_imu(sim, states, t + int(o) * STEP_NS) for o in offsets]
        np.testing.assert_allclose(imu.gyro[k], weights @ np.array([w[0] for w in window]), atol=1e-4)
        np.testing.assert_allclose(imu.accel[k], weights @ np.array([w[1] for w in window]), atol=1e-4)


def test_accelerometer_reads_gravity_at_rest():
    sim = PandaSim()
    sampling = SensorSampling()
    truth = replace(sample_sensor(sampling, np.random.default_rng(9)), imu_noise=ImuNoise(0.0, 0.0, 0.0, 0.0, 200.0))
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling)
    recorder.start(truth, np.random.default_rng(0))
    sim.hold(0.2, observer=recorder)
    imu = recorder.recording().imu
    R_world_imu = site_pose(sim.model, sim.data, "imu")[:3, :3]
    np.testing.assert_allclose(imu.accel, np.tile(R_world_imu.T @ [0.0, 0.0, 9.81], (len(imu), 1)), atol=1e-4)
    np.testing.assert_allclose(imu.gyro, 0.0, atol=1e-6)


def test_kinematic_gyro_agrees_with_mujocos_gyro_sensor_at_the_midpoint_velocity():
    """MuJoCo's gyro reads the semi-implicit velocity v_k, the rate of the step before t_k. Moved to
    the midpoint velocity (v_k + v_{k+1}) / 2 through the site Jacobian, it is the rate at t_k that the
    position-based reading must match; unmoved it lags by half a step."""
    sim = PandaSim()
    sim.reset()
    set_imu_pose(sim.model, make_transform(euler_to_matrix([0.1, -0.2, 1.5]), [0.06, 0.01, -0.1]))
    mujoco.mj_forward(sim.model, sim.data)
    reader = ImuSiteReader(sim.model)
    reader.reset(sim.time_ns)
    site_id = sim.model.site("imu").id
    velocity = {"before": sim.data.qvel.copy()}
    sensor, midpoint, readings = {}, {}, {}

    def on_step(s, t_ns):
        jac_r = np.zeros((3, s.model.nv))
        mujoco.mj_jacSite(s.model, s.data, None, jac_r, site_id)
        R = s.data.site_xmat[site_id].reshape(3, 3)
        sensor[t_ns] = s.data.sensor("gyro").data.copy()
        midpoint[t_ns] = sensor[t_ns] + R.T @ jac_r @ (s.data.qvel - velocity["before"]) / 2.0
        velocity["before"] = s.data.qvel.copy()
        reader.record(s.data, t_ns, s.timestep_ns)

    sim.move_to(sim.ee_pose() @ make_transform(euler_to_matrix([0.3, -0.2, 0.25]), [0.05, 0.05, -0.05]), on_step)
    site = reader.readings()
    readings = dict(zip(site.t_ns.tolist(), site.reading[:, :3], strict=True))
    ours = np.array(list(readings.values()))
    assert np.abs(ours).max() > 0.3  # it rotates
    np.testing.assert_allclose(ours, [midpoint[t] for t in readings], atol=1e-5)
    lag = np.abs(ours - np.array([sensor[t] for t in readings])).max()
    assert lag > 1e-3  # the half-step lead of the raw sensor is real and visible


SPINNER = """
<mujoco>
  <option timestep="0.001"/>
  <worldbody>
    <body name="arm">
      <joint name="spin" type="hinge" axis="0 0 1"/>
      <geom type="sphere" size="0.01" mass="0.1"/>
      <site name="imu" pos="0.3 0 0" euler="0.4 0 0"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_reader_matches_a_site_spinning_on_a_circle():
    """Independent reference: a site at radius r on an arm turning at omega(t) = w0 + alpha t about world z
    has angular rate omega e_z and acceleration (-omega^2 r) e_radial + (alpha r) e_tangential."""
    model = mujoco.MjModel.from_xml_string(SPINNER)
    data = mujoco.MjData(model)
    reader = ImuSiteReader(model)
    reader.reset(0)
    r, w0, alpha, h = 0.3, 2.0, 3.0, 1e-3
    for k in range(400):
        t = k * h
        data.qpos[0] = w0 * t + 0.5 * alpha * t * t
        mujoco.mj_kinematics(model, data)
        reader.record(data, k * STEP_NS, STEP_NS)
    site = reader.readings()
    assert site.t_ns.tolist() == [k * STEP_NS for k in range(1, 399)]  # the first and last lack a neighbour
    for k in range(0, len(site.t_ns), 37):
        t = site.t_ns[k] * 1e-9
        angle, omega = w0 * t + 0.5 * alpha * t * t, w0 + alpha * t
        radial, tangential = np.array([np.cos(angle), np.sin(angle), 0]), np.array([-np.sin(angle), np.cos(angle), 0])
        accel_world = -(omega**2) * r * radial + alpha * r * tangential
        R = site.R_world_site[k]
        np.testing.assert_allclose(site.reading[k, :3], R.T @ [0.0, 0.0, omega], atol=1e-6)
        np.testing.assert_allclose(site.reading[k, 3:], R.T @ (accel_world - model.opt.gravity), atol=1e-5)
        # The position differences see chords of the circle: (omega h)^2 / 6 ~ 1e-6 relative below the arc.
        np.testing.assert_allclose(site.v_world[k], omega * r * tangential, atol=1e-5)


def _spin(reader, model, data, steps):
    for k in steps:
        data.qpos[0] = 0.5 * np.sin(0.02 * k) + 1e-3 * k * k
        mujoco.mj_kinematics(model, data)
        reader.record(data, k * STEP_NS, STEP_NS)


def test_reader_gives_the_same_floats_however_often_it_is_read():
    """Read after every step, in uneven chunks or once: the same readings to the last bit."""
    model = mujoco.MjModel.from_xml_string(SPINNER)
    data = mujoco.MjData(model)
    batches = {}
    for chunk in (1, 13, 300):
        reader = ImuSiteReader(model)
        reader.reset(0)
        parts = []
        for start in range(0, 300, chunk):
            _spin(reader, model, data, range(start, min(start + chunk, 300)))
            parts.append(reader.readings())
        batches[chunk] = [np.concatenate([getattr(p, field) for p in parts]) for field in parts[0]._fields]
    assert len(batches[300][0]) == 298
    for chunk in (1, 13):
        for ours, whole in zip(batches[chunk], batches[300], strict=True):
            np.testing.assert_array_equal(ours, whole)


def test_reader_refuses_a_skipped_step():
    model = mujoco.MjModel.from_xml_string(SPINNER)
    data = mujoco.MjData(model)
    reader = ImuSiteReader(model)
    with pytest.raises(ImuSimulationError, match="before reset"):
        reader.record(data, 0, STEP_NS)
    reader.reset(0)
    reader.record(data, 0, STEP_NS)
    with pytest.raises(ImuSimulationError, match="expected the physics step starting at 1000000 ns, got 2000000 ns"):
        reader.record(data, 2 * STEP_NS, STEP_NS)


def test_intrinsics_scale_and_misalign_the_ideal_readings_before_the_noise():
    intrinsics = ImuIntrinsics.from_vector(np.random.default_rng(0).normal(0.0, 0.01, 24))

    def run(with_intrinsics):
        sim = ImuSimulator(STEP_NS, 5, "average", intrinsics=intrinsics if with_intrinsics else None)
        _feed(sim, range(100), lambda t: np.array([np.sin(t * 1e-7), 0.5, -0.2]))  # accel: twice the gyro
        return sim.samples()

    exact, distorted = run(False), run(True)
    gyro, accel = intrinsics.distort(exact.gyro, exact.accel)
    np.testing.assert_allclose(distorted.gyro, gyro, atol=1e-15)
    np.testing.assert_allclose(distorted.accel, accel, atol=1e-15)
    # Kalibr's accelerometer model: a = M_a a_i, M_a lower triangular.
    np.testing.assert_allclose(distorted.accel[:, 0], intrinsics.M_accel[0, 0] * exact.accel[:, 0], atol=1e-15)
