"""The sensor in a simulated person's hand: the scene, the IMU and camera against the hand's motion, a calibration."""

import mujoco
import numpy as np
import pytest
from configs import composed
from scipy.spatial.transform import Rotation

from vical.calib.result import FramePoses
from vical.calib.solve.plausibility import board_scale, wrong_board_scale
from vical.calib.tasks import CalibrationTask, run_task
from vical.collection.runner import CollectionStopped, Limits, SensorStream, read_until
from vical.config_checks import from_mapping
from vical.data import NS_PER_S
from vical.geometry import T_CAM_BODY, interpolate_transforms, invert_transform, make_transform
from vical.io.euroc import EurocStreamWriter
from vical.robot import SensorStreamError
from vical.sim.adapters import RigFaults
from vical.sim.hand_held import HandHeldRig
from vical.sim.panda import PandaSim
from vical.sim.person import HandModel
from vical.sim.sampling import SensorSampling
from vical.sim.scene import build_hand_held_model, camera_pose_cv, imu_pose_in_body, site_pose
from vical.sim.settings import SimConfig

EXACT = HandModel(placement_sigma_m=0.0, placement_sigma_deg=0.0, tremor_m=0.0, tremor_deg=0.0)


@pytest.fixture(scope="module")
def settings():
    cfg = composed("evaluate", ["task=joint", "workspace=practitioner"])
    task = from_mapping(CalibrationTask, cfg["task"], "task")
    return SimConfig.from_mapping(cfg["sim"]), SensorSampling.from_config(cfg["sensor"]), task


def test_the_hand_holds_the_rig_as_the_flange_does_before_the_same_board(settings):
    sim_config = settings[0]
    arm = PandaSim(sim_config)
    model, T_world_board, T_world_start = build_hand_held_model(sim_config)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert model.nq == 0 and model.nmocap == 1  # no arm: the rig is posed, not actuated
    np.testing.assert_allclose(T_world_board, arm.T_world_board, atol=1e-12)
    # the arm's start is its IK solution of the same pose (within 1e-6 m); the rig is fixed to the body alike
    np.testing.assert_allclose(T_world_start, arm.ee_pose(), atol=1e-5)
    T_arm_body = invert_transform(arm.ee_pose())
    for pose in (lambda m, d: camera_pose_cv(m, d), lambda m, d: site_pose(m, d, "imu")):
        in_hand = invert_transform(T_world_start) @ pose(model, data)
        np.testing.assert_allclose(in_hand, T_arm_body @ pose(arm.model, arm.data), atol=1e-12)


def _exact_rig(settings, seed: int = 2) -> HandHeldRig:
    sim_config, sampling, _ = settings
    return HandHeldRig(sim_config, sampling, seed, EXACT)


def test_a_turn_in_the_hand_reads_on_the_gyro_as_its_angle_and_peak_rate(settings):
    """A 1.2 rad turn about the body's vertical axis: the gyro's rate about it (the bias of the rest before
    removed) integrates to the angle and peaks at the minimum-jerk profile's 1.875 x angle / duration; about the
    other axes it reads nothing but its bias."""
    rig = _exact_rig(settings)
    rig.advance(1.0)
    turn = make_transform(Rotation.from_rotvec([0.0, 0.0, 1.2]).as_matrix(), np.zeros(3))
    reach = rig.suggest(rig.sim.T_world_start @ turn)
    rig.advance(reach.duration + 1.0)
    imu = rig.recording().imu
    t = imu.t / 1e9  # the simulation clock
    axis = imu_pose_in_body(rig.sim.model)[:3, :3].T @ np.array([0.0, 0.0, 1.0])  # body z in the IMU's axes
    rest, moving = (t > 0.2) & (t < reach.t0), (t >= reach.t0) & (t <= reach.t_end)
    gyro = imu.gyro - imu.gyro[rest].mean(axis=0)
    rate = gyro @ axis
    assert np.sum(rate[moving]) * np.median(np.diff(t)) == pytest.approx(1.2, abs=0.01)
    assert rate[moving].max() == pytest.approx(1.875 * 1.2 / reach.duration, rel=0.03)
    assert np.abs((gyro[moving] - np.outer(rate[moving], axis)).mean(axis=0)).max() < 0.01


def test_a_still_hand_frames_the_board_where_the_truth_camera_projects_it(settings):
    """Corners of frames taken while the hand rests: the board projected by the sensor's true camera from the
    rest pose, within the corner noise (0.25 px)."""
    rig = _exact_rig(settings, seed=4)
    rig.advance(1.0)
    recording = rig.recording()
    T_world_cam = rig.sim.T_world_start @ invert_transform(T_CAM_BODY)
    T_cam_board = invert_transform(T_world_cam) @ rig.sim.T_world_board
    residuals = []
    for frame in range(len(recording.frames)):
        ids = recording.frames.ids[frame]
        points = recording.target.points[ids]
        p_cam = points @ T_cam_board[:3, :3].T + T_cam_board[:3, 3]
        uv, _ = recording.truth.camera.project(p_cam)
        residuals.append(recording.frames.corners[frame] - uv)
    residuals = np.concatenate(residuals)
    assert len(residuals) > 100
    assert np.abs(residuals.mean(axis=0)).max() < 0.05
    assert np.sqrt(np.mean(residuals**2)) == pytest.approx(0.25, rel=0.15)


@pytest.mark.parametrize("tremor", [False, True], ids=["still", "tremor"])
def test_a_hand_held_recording_calibrates_within_its_sigmas(settings, tremor):
    """A person turning and moving the sensor along each axis (12 suggestions, 30 s): the joint task's extrinsic
    and time offset within 3 reported sigma, with and without the model's tremor (1 mm, 0.3 deg at 8-12 Hz).
    Measured (seeds 0-3): without tremor 1.1-2.7 mm, 0.03-0.06 deg, at most 2.1 sigma; with it 1.1-3.1 mm, at
    most 2.5 sigma. Before the calibrator integrated the motion's cubic interpolant from the readings' interval
    means (the trapezoid rule of their linear interpolant shrinks a 10 Hz tremor at 200 Hz by 0.8 %, the interval
    mean by another 0.4 %) the tremor gave 2.9-6.7 mm and t_z up to 5.1 sigma (3.2 on seed 1)."""
    sim_config, sampling, task = settings
    z = []
    for seed in (0, 1):
        hand = HandModel() if tremor else HandModel(tremor_m=0.0, tremor_deg=0.0)
        rig = HandHeldRig(sim_config, sampling, seed, hand, asymmetric_distortion=task.asymmetric_distortion)
        rig.advance(0.5)
        for axis in range(3):
            for sign in (1.0, -1.0):
                rotation = make_transform(Rotation.from_rotvec(0.5 * sign * np.eye(3)[axis]).as_matrix(), np.zeros(3))
                for move in (rotation, make_transform(np.eye(3), 0.12 * sign * np.eye(3)[axis])):
                    rig.suggest(rig.sim.T_world_start @ move)
                    rig.advance(2.5)
        recording = rig.recording()
        result = run_task(task, recording).result
        truth = recording.truth
        rotation = Rotation.from_matrix(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T).as_rotvec()
        error = np.r_[
            rotation, result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3], result.time_offset - truth.time_offset
        ]
        names = ["rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset"]
        z.append(np.abs(error) / np.array([result.sigma(n) for n in names]))
    assert np.all(np.concatenate(z) <= 3.0), z


def test_the_hand_held_sensor_streams_frames_in_which_the_runner_finds_the_board(settings):
    """Read as vical-collect reads a live sensor (``SensorStream``: rendered images, the board detected in them)
    while the person turns it: a frame every camera period, each with the board's corners where the analytic
    projection puts them."""
    sim_config, sampling, _ = settings
    rig = HandHeldRig(sim_config, sampling, 5, keep_images=True)
    stream = SensorStream(rig.sensor, rig.target, None, Limits())
    rig.sensor.start()
    turn = make_transform(Rotation.from_rotvec([0.0, 0.15, 0.1]).as_matrix(), np.zeros(3))
    reach = rig.suggest(rig.sim.T_world_start @ turn)
    seen = []
    while rig.time < reach.t_end:
        seen += stream.read()
    try:
        analytic, ids = rig.recorder.detections_since(0)  # every exposure (the recording keeps those in the IMU span)
        assert len(seen) == len(analytic) >= 10 * reach.t_end
        for (_, corners, found), projected, expected in zip(seen, analytic, ids, strict=True):
            common, here, there = np.intersect1d(found, expected, return_indices=True)
            assert len(common) >= 0.8 * len(expected) > 0
            assert np.median(np.linalg.norm(corners[here] - projected[there], axis=1)) < 0.5
    finally:
        rig.close()


def test_at_corner_level_the_sensor_delivers_the_analytic_corners_which_are_not_written_as_euroc(settings, tmp_path):
    """Without images (a comparison that renders nothing) the sensor's frames are the board's analytic corners;
    a EuRoC writer needs images and says so in one line."""
    sim_config, sampling, _ = settings
    rig = HandHeldRig(sim_config, sampling, 6)
    stream = SensorStream(rig.sensor, rig.target, None, Limits())
    rig.sensor.start()
    rig.suggest(rig.sim.T_world_start @ make_transform(np.eye(3), [0.0, 0.1, 0.0]))
    seen = []
    while rig.time < 2.0:
        seen += stream.read()
    corners, ids = rig.recorder.detections_since(0)
    assert len(seen) == len(corners) >= 20
    for (_, uv, found), expected_uv, expected_ids in zip(seen, corners, ids, strict=True):
        np.testing.assert_array_equal(found, expected_ids)
        np.testing.assert_array_equal(uv, expected_uv)
    writer = EurocStreamWriter(tmp_path / "recording", rig.sensor.image_size, 10.0, 200.0, rig.datasheet.imu_noise)
    stream = SensorStream(rig.sensor, rig.target, writer, Limits())
    stream.start_recording()
    with pytest.raises(SensorStreamError, match="without images, and a EuRoC recording needs the images"):
        while True:
            stream.read()
    writer.close()


def test_a_hands_tremor_is_no_evidence_of_a_wrong_board(settings):
    """A person's small reaches with the model's tremor (1 mm, 0.3 deg at 8-12 Hz): the board-scale check on the
    camera's true poses at its frames reads the board's true size (it read 0.77 with the lever arm fitted, a wrong
    board, while it carried the frames' orientations to the IMU's samples by interpolating them: a 10 Hz camera sees
    the tremor's turning as a slow wobble that tilts gravity)."""
    sim_config, sampling, _ = settings
    rig = HandHeldRig(sim_config, sampling, 3)
    rig.advance(0.5)
    for axis in range(3):
        for sign in (1.0, -1.0):
            rig.suggest(rig.sim.T_world_start @ make_transform(np.eye(3), 0.07 * sign * np.eye(3)[axis]))
            rig.advance(2.0)
    recording = rig.recording()
    truth, trajectory = recording.truth, recording.trajectory
    stamps = recording.frames.t[3:-3]
    exposed = stamps + round(truth.time_offset * 1e9)
    T_world_cam = interpolate_transforms(trajectory.t, trajectory.T_world_imu, exposed) @ invert_transform(
        truth.T_cam_imu
    )
    posed = FramePoses(stamps, np.linalg.inv(T_world_cam) @ recording.T_world_target)
    found = board_scale(posed, recording.imu, truth.T_cam_imu[:3, :3], truth.time_offset)
    assert found.lever_arm[0] == pytest.approx(1.0, abs=0.05)
    assert not wrong_board_scale(found)


@pytest.mark.parametrize(
    ("faults", "says"),
    [
        ({"imu_gap": (0.0, 1e6)}, "no IMU samples for 1 s while the camera streams (limits.wait_timeout); check that"),
        ({"camera_gap": (0.0, 1e6)}, "no camera images for 1 s while the IMU streams (limits.wait_timeout); check"),
        ({"imu_gap": (0.0, 1e6), "camera_gap": (0.0, 1e6)}, "no sensor data for 1 s (limits.wait_timeout); check"),
    ],
    ids=["no IMU", "no images", "nothing"],
)
def test_a_sensor_that_delivers_no_images_or_no_imu_stops_the_reading_naming_the_silent_stream(settings, faults, says):
    """The person holds a sensor one of whose streams delivers nothing: reading it (as the guide does while the
    person reaches) stops after ``limits.wait_timeout`` with one line naming that stream."""
    sim_config, sampling, _ = settings
    rig = HandHeldRig(sim_config, sampling, 7, faults=RigFaults(**faults))
    stream = SensorStream(rig.sensor, rig.target, None, Limits(wait_timeout=1.0))
    rig.sensor.start()
    try:
        with pytest.raises(SensorStreamError) as stopped:
            read_until(stream, lambda: rig.time > 300.0, lambda detections: None)
        assert str(stopped.value).startswith(says)
        assert rig.time < 300.0
    finally:
        rig.close()


def test_a_covered_lens_delivers_dark_frames_without_the_board_until_the_guide_stops(settings):
    """``faults.lens_covered`` from 1 s on: the frames before show the board, those after still come (the camera
    streams) but dark and without it, and reading them stops after ``limits.lost_frames`` of them in a row."""
    sim_config, sampling, _ = settings
    rig = HandHeldRig(sim_config, sampling, 7, keep_images=True, faults=RigFaults(lens_covered=(1.0, 1e6)))
    stream = SensorStream(rig.sensor, rig.target, None, Limits(lost_frames=5))
    seen: list[tuple[int, np.ndarray, np.ndarray]] = []
    images: list[np.ndarray] = []
    stream.viewer = lambda frame, corners, ids: images.append(frame.image)
    rig.sensor.start()
    try:
        with pytest.raises(CollectionStopped, match=r"^the board was out of view for 5 frames in a row"):
            read_until(stream, lambda: rig.time > 30.0, seen.extend)
    finally:
        rig.close()
    before = [ids for t, _, ids in seen if t < 0.9 * NS_PER_S]
    assert before and all(len(ids) >= 20 for ids in before)
    assert images[-1].max() == 0 and images[0].max() > 100
    assert 1.0 < rig.time < 2.0  # stopped at the fifth dark frame (10 Hz)
