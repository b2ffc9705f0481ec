"""Recorder: frame timing and the time-offset sign, recordings that save and load exactly, bad input."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from dataclasses import replace

import cv2
import numpy as np
import pytest

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.config_checks import ConfigError
from vical.geometry import (
    CameraModel,
    euler_to_matrix,
    interpolate_transform,
    invert_transform,
    make_transform,
    transform_error,
)
from vical.io.recording import load_recording, save_recording
from vical.sim import PandaSim
from vical.sim.imu import ImuSimulationError
from vical.sim.recorder import SensorRecorder
from vical.sim.sampling import CameraSampling, ImuSampling, Normal, SensorSampling, mean_sensor, sample_sensor

OFFSET = 0.0123  # [s]


@pytest.fixture(scope="module")
def sim():
    return PandaSim()


def _record(sim, truth, sampling=None, detector=None, keep_images=False, steps=None, follow=False, on_step=None):
    """Record the motion ``steps``; ``follow`` reads the IMU samples after every motion, as the env does;
    ``on_step`` makes the motions run step by step."""
    sampling = sampling or SensorSampling()
    sim.reset()
    recorder = SensorRecorder(sim, sim.cfg.board.target, sampling, detector, keep_images)
    try:
        recorder.start(truth, np.random.default_rng(5))
        T = sim.ee_pose()
        for rpy, xyz in steps or [([0.25, 0.0, 0.25], [0.0, 0.08, 0.0]), ([-0.2, 0.15, -0.25], [0.05, -0.1, 0.05])]:
            T = T @ make_transform(euler_to_matrix(rpy), xyz)
            recorder.add_motion(sim.move_to(T, on_step=on_step, observer=recorder))
            if follow:
                recorder.imu_samples()
        return recorder.recording({"seed": 5, "note": "test"})
    finally:
        recorder.close()


def _rolled_or_stepped(sim, truth, keep_images, on_step):
    sim.reset()
    recorder = SensorRecorder(sim, sim.cfg.board.target, SensorSampling(), keep_images=keep_images)
    try:
        recorder.start(truth, np.random.default_rng(5))
        # 113 steps: with OFFSET the exposure at 112.3 ms lies between this motion's last step and the next one's first
        recorder.add_motion(sim.hold(0.113, on_step=on_step, observer=recorder))
        for rpy, xyz in [([0.25, 0.0, 0.25], [0.0, 0.08, 0.0]), ([-0.2, 0.1, 0.0], [0.05, 0.0, 0.0])]:
            T = sim.ee_pose() @ make_transform(euler_to_matrix(rpy), xyz)
            recorder.add_motion(sim.move_to(T, on_step=on_step, observer=recorder))
            recorder.imu_samples()
        return recorder.recording()
    finally:
        recorder.close()


@pytest.mark.parametrize(("time_offset", "keep_images"), [(0.0, False), (OFFSET, True), (-0.0047, False)])
def test_a_recording_rolled_out_is_the_one_stepped_one_step_at_a_time(sim, time_offset, keep_images):
    """Motions run in MuJoCo's rollout, cut only at the steps around the camera exposures (exposures on a step, between
    two steps, and between two motions); stepped one at a time with a callback they give the same recording to the
    last bit, rendered images included."""
    truth = replace(mean_sensor(SensorSampling()), time_offset=time_offset)
    rolled = _rolled_or_stepped(sim, truth, keep_images, None)
    stepped = _rolled_or_stepped(sim, truth, keep_images, lambda s, t_ns: None)
    assert len(rolled.frames) >= 8 and len(rolled.imu) > 150

    def arrays(r):
        return [r.imu.t, r.imu.gyro, r.imu.accel, r.frames.t, r.frames.images, *r.frames.corners, *r.frames.ids,
                r.trajectory.T_world_imu, r.trajectory.v_world, r.path_profile.length, [r.path_length]]  # fmt: skip

    for a, b in zip(arrays(rolled), arrays(stepped), strict=True):
        np.testing.assert_array_equal(a, b)


@pytest.fixture(scope="module")
def offset_recording(sim):
    sampling = replace(SensorSampling(), pixel_noise_px=0.0)
    truth = replace(sample_sensor(sampling, np.random.default_rng(2)), time_offset=OFFSET)
    return _record(sim, truth, sampling)


def test_the_recording_does_not_depend_on_when_the_imu_samples_are_read(sim, offset_recording):
    """The poses of every physics step become readings, truth and path when asked for: asking after every
    motion gives the recording of asking once, to the last bit."""
    followed = _record(sim, offset_recording.truth, replace(SensorSampling(), pixel_noise_px=0.0), follow=True)
    once = offset_recording
    assert len(once.imu) > 100 and once.path_profile.length[-1] > 0.1
    for ours, theirs in [
        (followed.imu.t, once.imu.t),
        (followed.imu.gyro, once.imu.gyro),
        (followed.imu.accel, once.imu.accel),
        (followed.trajectory.T_world_imu, once.trajectory.T_world_imu),
        (followed.trajectory.v_world, once.trajectory.v_world),
        (followed.trajectory.omega_imu, once.trajectory.omega_imu),
        (followed.path_profile.t, once.path_profile.t),
        (followed.path_profile.length, once.path_profile.length),
    ]:
        np.testing.assert_array_equal(ours, theirs)


def test_frames_are_stamped_on_the_camera_grid_and_exposed_inside_the_motion(offset_recording):
    rec = offset_recording
    assert np.all(rec.frames.t % 100_000_000 == 0)
    exposures = rec.frames.t + round(OFFSET * 1e9)
    assert exposures[0] >= 0 and exposures[-1] <= rec.duration * 1e9
    assert len(rec.frames) == int((rec.duration * 1e9 - round(OFFSET * 1e9)) // 100_000_000) + 1
    assert rec.frames.num_detections.min() == rec.target.num_points
    assert rec.duration > 0.5 and rec.path_length > 0.1
    assert rec.metadata == {"seed": 5, "note": "test"}


def _pnp_camera_poses(rec):
    """``T_world_cam`` (M, 4, 4) from PnP on every frame's corners (exact, noise-free corners)."""
    camera, T_world_board = rec.truth.camera, rec.T_world_target
    poses = []
    for corners, ids in zip(rec.frames.corners, rec.frames.ids, strict=True):
        ok, rvec, tvec = cv2.solvePnP(
            np.ascontiguousarray(rec.target.points[ids]),
            np.ascontiguousarray(corners),
            camera.K,
            np.append(camera.dist, 0.0),
            flags=cv2.SOLVEPNP_ITERATIVE,
        )
        assert ok
        T_cam_board = make_transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
        poses.append(T_world_board @ invert_transform(T_cam_board))
    return np.array(poses)


def _true_camera_pose(rec, t_imu_ns):
    """Ground-truth ``T_world_cam`` at IMU time ``t_imu_ns`` (interpolated between trajectory samples)."""
    traj = rec.trajectory
    k = int(np.searchsorted(traj.t, t_imu_ns)) - 1
    s = (t_imu_ns - traj.t[k]) / (traj.t[k + 1] - traj.t[k])
    T_world_imu = interpolate_transform(traj.T_world_imu[k], traj.T_world_imu[k + 1], s)
    return T_world_imu @ invert_transform(rec.truth.T_cam_imu)


def test_time_offset_shows_up_with_kalibr_sign_in_pnp_poses(offset_recording):
    rec = offset_recording
    pnp = _pnp_camera_poses(rec)
    inside = (rec.frames.t - 40_000_000 > rec.trajectory.t[0]) & (rec.frames.t + 40_000_000 < rec.trajectory.t[-1])
    shifts = np.arange(-30.0, 30.01, 0.1) * 1e6  # candidate offsets [ns]

    def misfit(shift):
        return sum(
            sum(transform_error(pnp[i], _true_camera_pose(rec, int(rec.frames.t[i] + shift))))
            for i in np.flatnonzero(inside)
        )

    costs = np.array([misfit(s) for s in shifts])
    best = shifts[int(np.argmin(costs))] * 1e-9
    # t_imu = t_cam + time_offset: the PnP pose of the frame stamped t_cam is the true pose at t_cam + 12.3 ms,
    # to the 0.1 ms grid: the 0.3 ms below the physics step are there, not rounded to 12 or 13 ms.
    assert best == pytest.approx(OFFSET, abs=6e-5)
    assert costs[np.argmin(np.abs(shifts + OFFSET * 1e9))] > 10 * costs.min()


def test_frames_exposed_outside_the_imu_span_are_dropped(sim):
    """Only frames exposed within the IMU samples are kept; the offset moves which stamps those are."""
    first_stamps = {}
    for offset in (0.0, -0.2, 0.2):
        truth = replace(mean_sensor(SensorSampling()), time_offset=offset)
        rec = _record(sim, truth, steps=[([0.0, 0.0, 0.1], [0.0, 0.0, 0.0])])
        exposure = rec.frames.t + round(offset * 1e9)
        assert exposure[0] >= rec.imu.t[0] and exposure[-1] <= rec.imu.t[-1]
        first_stamps[offset] = int(rec.frames.t[0])
    # The IMU starts at 5 ms: stamp 0 is exposed too early at offset 0, stamps up to 200 ms at -0.2 s,
    # and at +0.2 s stamp -200 ms is already exposed at 0 ms (too early) but -100 ms lands at 100 ms.
    assert first_stamps == {0.0: 100_000_000, -0.2: 300_000_000, 0.2: -100_000_000}


def test_recording_saves_and_loads_exactly(sim, tmp_path):
    sampling = SensorSampling(imu=ImuSampling(gyro_bias_std=0.01, accel_bias_std=0.05))
    truth = sample_sensor(sampling, np.random.default_rng(8), asymmetric=True)
    rec = _record(sim, truth, sampling, keep_images=True, steps=[([0.1, 0.0, 0.1], [0.03, 0.0, 0.0])])
    assert rec.frames.images.shape == (len(rec.frames), 480, 640)
    loaded = load_recording(save_recording(rec, tmp_path / "rec"))
    for a, b in [(rec.imu, loaded.imu), (rec.trajectory, loaded.trajectory)]:
        for name in a.__dataclass_fields__:
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    np.testing.assert_array_equal(rec.frames.t, loaded.frames.t)
    np.testing.assert_array_equal(rec.frames.images, loaded.frames.images)
    for c, d in zip(rec.frames.corners + rec.frames.ids, loaded.frames.corners + loaded.frames.ids, strict=True):
        np.testing.assert_array_equal(c, d)
    assert loaded.truth.to_dict() == rec.truth.to_dict()
    np.testing.assert_array_equal(loaded.T_world_target, rec.T_world_target)
    assert (loaded.path_length, loaded.duration, loaded.metadata) == (rec.path_length, rec.duration, rec.metadata)


def test_same_seed_same_recording(sim):
    truth = sample_sensor(SensorSampling(), np.random.default_rng(1))
    steps = [([0.1, 0.0, 0.0], [0.0, 0.02, 0.0])]
    a, b = _record(sim, truth, steps=steps), _record(sim, truth, steps=steps)
    np.testing.assert_array_equal(a.imu.accel, b.imu.accel)
    np.testing.assert_array_equal(np.vstack(a.frames.corners), np.vstack(b.frames.corners))


def test_render_backend_records_detections(sim):
    sampling = replace(SensorSampling(), backend="render")
    truth = mean_sensor(sampling)
    rec = _record(sim, truth, sampling, detect_checkerboard, steps=[([0.0, 0.1, 0.0], [0.0, 0.0, 0.03])])
    assert len(rec.frames) >= 3 and rec.frames.num_detections.min() == rec.target.num_points
    assert rec.frames.images is None


def test_bad_setups_are_refused(sim):
    target = sim.cfg.board.target
    with pytest.raises(ValueError, match="needs a corner detector"):
        SensorRecorder(sim, target, replace(SensorSampling(), backend="render"))
    with pytest.raises(ConfigError, match=r"sensor\.imu\.rate_hz"):
        SensorRecorder(sim, target, SensorSampling(imu=ImuSampling(rate_hz=300.0)))
    with pytest.raises(ConfigError, match=r"sensor\.camera\.rate_hz"):
        SensorRecorder(sim, target, SensorSampling(camera=CameraSampling(rate_hz=3.0)))
    recorder = SensorRecorder(sim, target, SensorSampling())
    small = replace(mean_sensor(SensorSampling()), camera=CameraModel.from_hfov(1.0, 320, 240))
    with pytest.raises(ValueError, match=r"320 x 240 px .*sensor\.camera\.width/height"):
        recorder.start(small, np.random.default_rng(0))
    with pytest.raises(RuntimeError, match=r"start\(truth, rng\) must be called before recording\(\)"):
        recorder.recording()
    with pytest.raises(RuntimeError, match=r"start\(truth, rng\) must be called before imu_samples\(\)"):
        recorder.imu_samples()
    with pytest.raises(RuntimeError, match=r"start\(truth, rng\) must be called before a motion"):
        sim.hold(0.01, observer=recorder)
    sim.reset()
    recorder.start(mean_sensor(SensorSampling()), np.random.default_rng(0))
    sim.hold(0.01)  # physics steps the recorder does not see
    steps = sim.step_count
    with pytest.raises(ImuSimulationError, match="every physics step"):
        sim.hold(0.01, observer=recorder)
    assert sim.step_count == steps  # refused before the motion ran


LINE_DELAY = 30e-6  # [s/row]: a 14.4 ms readout at 480 rows


@pytest.fixture(scope="module")
def rolling_recording(sim):
    sampling = replace(SensorSampling(), pixel_noise_px=0.0)
    truth = replace(sample_sensor(sampling, np.random.default_rng(2)), time_offset=OFFSET, line_delay=LINE_DELAY)
    return _record(sim, truth, sampling)


def test_a_rolling_shutter_sees_each_corner_at_its_rows_time(rolling_recording):
    """Each noise-free corner is the board point projected from the true pose at ``t_cam + offset + line_delay * v``
    (row 0 at the timestamp), to the interpolation between the 5 ms truth samples (a d^2 / 8: 0.02 px); from the
    timestamp's pose alone it would be pixels away."""
    rec = rolling_recording
    points = rec.target.points @ rec.T_world_target[:3, :3].T + rec.T_world_target[:3, 3]
    worst, shift = 0.0, 0.0
    inside = (rec.frames.t + 40_000_000 < rec.trajectory.t[-1]) & (rec.frames.num_detections > 0)
    for i in np.flatnonzero(inside):
        uv, ids = rec.frames.corners[i], rec.frames.ids[i]
        start = int(rec.frames.t[i] + round(OFFSET * 1e9))
        for k in range(len(ids)):
            T = _true_camera_pose(rec, start + round(LINE_DELAY * uv[k, 1] * 1e9))
            p = invert_transform(T)[:3, :3] @ points[ids[k]] + invert_transform(T)[:3, 3]
            worst = max(worst, float(np.abs(rec.truth.camera.project(p[None])[0][0] - uv[k]).max()))
        T0 = invert_transform(_true_camera_pose(rec, start))
        still = rec.truth.camera.project(points[ids] @ T0[:3, :3].T + T0[:3, 3])[0]
        shift = max(shift, float(np.abs(still - uv).max()))
    assert worst < 0.05 and shift > 1.0, (worst, shift)  # 0.018 px: the 5 ms samples' interpolation
    assert rec.truth.line_delay == LINE_DELAY


def test_a_rendered_rolling_shutter_is_detected_where_its_rows_put_the_corners(sim, monkeypatch):
    """Rendered in bands (each at its middle row's pose), the detected checkerboard corners are the exact rolling
    shutter's (the project backend's) to the detector's noise (measured 0.058 px RMS, as with a global shutter); one
    band (every row at the middle row's time) is 0.67 px RMS off, 2.9 px at most."""
    truth = replace(mean_sensor(SensorSampling()), line_delay=LINE_DELAY)
    steps = [([0.25, 0.0, 0.25], [0.0, 0.08, 0.0]), ([-0.2, 0.15, -0.25], [0.05, -0.1, 0.05]),
             ([0.2, -0.1, 0.2], [0.0, 0.05, 0.0])]  # fmt: skip
    exact = _record(sim, truth, replace(SensorSampling(), pixel_noise_px=0.0), steps=steps)

    def rms_error() -> float:
        rendered = _record(sim, truth, replace(SensorSampling(), backend="render"), detect_checkerboard, steps=steps)
        pairs = zip(rendered.frames.corners, exact.frames.corners, rendered.frames.ids, exact.frames.ids, strict=True)
        errors = np.concatenate([c - e for c, e, i, j in pairs if len(i) and len(j)])
        assert len(errors) > 500
        return float(np.sqrt(np.mean(errors**2)))

    banded = rms_error()
    monkeypatch.setattr("vical.sim.camera.BAND_ERROR_PX", 1e9)  # one band
    assert banded < 0.1 and rms_error() > 4 * banded


def test_a_line_delay_is_drawn_per_episode_within_a_frame_and_not_beyond_it():
    sampling = replace(SensorSampling(), camera=CameraSampling(line_delay=Normal(30e-6, 10e-6)))
    drawn = [sample_sensor(sampling, np.random.default_rng(seed)).line_delay for seed in range(200)]
    assert 25e-6 < np.mean(drawn) < 35e-6 and np.std(drawn) > 5e-6 and min(drawn) >= 0
    # a sensor without a spread draws what it always drew
    plain = sample_sensor(SensorSampling(), np.random.default_rng(3))
    assert plain.line_delay == 0.0
    with pytest.raises(ConfigError, match=r"sensor.camera.line_delay.mean must be \[s/row\] >= 0 whose readout"):
        CameraSampling(line_delay=Normal(1e-3, 0.0))
