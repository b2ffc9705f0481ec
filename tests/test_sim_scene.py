"""The MuJoCo scene: compiles and rests without warnings, frames and texture follow docs/conventions.md."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path

import cv2
import mujoco
import numpy as np
import pytest
import yaml

from vical.config_checks import ConfigError
from vical.geometry import R_CAM_BODY, CameraModel, euler_to_matrix, invert_transform, make_transform, transform_points
from vical.sim import PandaSim, SimConfig, body_pose, camera_pose_cv, imu_pose_in_body, set_imu_pose, site_pose
from vical.sim.settings import PhysicsConfig

CONF = Path(__file__).resolve().parents[1] / "conf" / "sim" / "default.yaml"


@pytest.fixture(scope="module")
def sim():
    return PandaSim(SimConfig.from_mapping(yaml.safe_load(CONF.read_text())))


def test_default_yaml_matches_dataclass_defaults():
    assert SimConfig.from_mapping(yaml.safe_load(CONF.read_text())) == SimConfig()


def test_omegaconf_node_builds_the_same_config():
    from omegaconf import OmegaConf

    node = OmegaConf.load(CONF)
    node.board = {"distance": 1.2}  # the board comes from the workspace group (conf/workspace/)
    cfg = SimConfig.from_mapping(node)
    assert cfg.board.distance == 1.2 and cfg.motion.kp == SimConfig().motion.kp


def test_scene_rests_for_one_second_without_warnings(sim):
    sim.reset()
    q_home = sim.q
    result = sim.hold(1.0)
    assert sim.time_ns == 1_000_000_000 and result.num_steps == 1000
    assert np.all(sim.data.warning.number == 0), sim.data.warning.number
    assert sim.data.ncon == 0
    # Gravity feed-forward holds the arm: it drifts less than 1e-5 rad in a second.
    assert np.max(np.abs(sim.q - q_home)) < 1e-5
    assert result.max_tracking_error < 1e-5


def test_home_camera_looks_at_board_centre_from_board_distance(sim):
    sim.reset()
    T_world_cam = camera_pose_cv(sim.model, sim.data)
    target = sim.cfg.board.target
    centre_cam = transform_points(invert_transform(T_world_cam) @ sim.T_world_board, target.center)
    np.testing.assert_allclose(centre_cam, [0.0, 0.0, sim.cfg.board.distance], atol=1e-9)
    # The board's z axis points from the printed side back towards the camera (optical -z).
    z_board_in_cam = (invert_transform(T_world_cam) @ sim.T_world_board)[:3, 2]
    np.testing.assert_allclose(z_board_in_cam, [0.0, 0.0, -1.0], atol=1e-9)
    # At home the camera body is level: x forward (world +x), z up.
    np.testing.assert_allclose(sim.ee_pose()[:3, :3], np.eye(3), atol=1e-6)


def test_camera_pose_cv_is_body_frame_with_fixed_optical_rotation(sim):
    sim.reset()
    T_world_body = body_pose(sim.model, sim.data, "cam_body")
    T_world_cam = camera_pose_cv(sim.model, sim.data)
    np.testing.assert_allclose(T_world_cam, T_world_body @ make_transform(R_CAM_BODY.T, np.zeros(3)), atol=1e-9)
    np.testing.assert_allclose(site_pose(sim.model, sim.data, "ee"), T_world_body, atol=1e-9)


def test_imu_site_pose_and_accelerometer_at_rest(sim):
    T_body_imu = make_transform(euler_to_matrix([0.1, -0.2, 1.57]), [0.06, 0.01, -0.1])
    set_imu_pose(sim.model, T_body_imu)
    try:
        sim.reset()
        np.testing.assert_allclose(imu_pose_in_body(sim.model), T_body_imu, atol=1e-12)
        T_world_imu = site_pose(sim.model, sim.data, "imu")
        np.testing.assert_allclose(T_world_imu, body_pose(sim.model, sim.data, "cam_body") @ T_body_imu, atol=1e-9)
        accel = sim.data.sensor("accel").data
        gyro = sim.data.sensor("gyro").data
        # Specific force at rest: +g along world up, seen in the IMU frame.
        np.testing.assert_allclose(accel, T_world_imu[:3, :3].T @ [0.0, 0.0, 9.81], atol=1e-6)
        np.testing.assert_allclose(gyro, 0.0, atol=1e-9)
    finally:
        set_imu_pose(sim.model, np.eye(4))


def test_set_imu_pose_rejects_non_rotation(sim):
    with pytest.raises(ValueError, match="rotation"):
        set_imu_pose(sim.model, make_transform(2.0 * np.eye(3), np.zeros(3)))


def test_board_texture_corners_match_projection_within_half_pixel(sim):
    """Scene, texture orientation and the camera flip agree: detected corners = projected board points."""
    sim.reset()
    width, height = 640, 480
    renderer = mujoco.Renderer(sim.model, height, width)
    try:
        renderer.update_scene(sim.data, camera="cam")
        gray = cv2.cvtColor(renderer.render(), cv2.COLOR_RGB2GRAY)
    finally:
        renderer.close()
    target = sim.cfg.board.target
    found, corners = cv2.findChessboardCorners(gray, (target.cols, target.rows))
    assert found
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    corners = cv2.cornerSubPix(gray, corners, (5, 5), (-1, -1), criteria).reshape(-1, 2)
    fovy = np.radians(sim.model.cam_fovy[sim.model.camera("cam").id])
    f = (height / 2) / np.tan(fovy / 2)
    camera = CameraModel("radtan", width, height, f, f, (width - 1) / 2, (height - 1) / 2)
    T_cam_board = invert_transform(camera_pose_cv(sim.model, sim.data)) @ sim.T_world_board
    uv, in_front = camera.project(transform_points(T_cam_board, target.points))
    assert in_front.all()
    # OpenCV returns corners in Kalibr id order (rows down, columns right) or reversed; the colour
    # check below pins which one, so the order must match without reordering.
    assert np.max(np.linalg.norm(corners - uv, axis=1)) < 0.5
    # Colour convention of vical.data.Target: the square diagonally outside point id 0 is black,
    # and the border beyond it is white.
    outside_0 = transform_points(T_cam_board, [[-0.5 * target.row_spacing, -0.5 * target.col_spacing, 0.0]])
    border = transform_points(T_cam_board, [[-1.5 * target.row_spacing, -1.5 * target.col_spacing, 0.0]])
    (u0, v0), (ub, vb) = camera.project(outside_0)[0][0], camera.project(border)[0][0]
    assert gray[round(v0), round(u0)] < 60
    assert gray[round(vb), round(ub)] > 200


@pytest.mark.parametrize(
    ("mapping", "message"),
    [
        ({"physics": {"timestep": -0.001}}, r"sim\.physics\.timestep must be a number in \(0\.0, 0\.01\]"),
        ({"physics": {"timestep": 1.5e-10}}, r"sim\.physics\.timestep must be a whole number of nanoseconds"),
        ({"board": {"distance": -1.5}}, r"sim\.board\.distance must be a number in \[0\.3, 5\.0\], got -1\.5"),
        (
            {"board": {"tilt_rpy": [0.0, 2.0, 0.0]}},
            r"sim\.board\.tilt_rpy \(pitch\) must be a number in \[-1\.2, 1\.2\]",
        ),
        ({"board": {"offset": [0.0]}}, r"sim\.board\.offset must be a list of 2 finite numbers"),
        ({"motion": {"kp": [1.0] * 6}}, r"sim\.motion\.kp must be a list of 7 finite numbers"),
        ({"motion": {"velocity_scale": 1.5}}, r"sim\.motion\.velocity_scale must be a number in \(0\.0, 1\.0\]"),
        ({"ik": {"max_iterations": 0}}, r"sim\.ik\.max_iterations must be an integer in \[1, 10000\]"),
        ({"boards": {}}, r"sim: unknown setting\(s\) \['boards'\]"),
        ({"physics": {"time_step": 0.001}}, r"sim\.physics: unknown setting\(s\) \['time_step'\]"),
    ],
)
def test_bad_config_names_key_and_range(mapping, message):
    with pytest.raises(ConfigError, match=message):
        SimConfig.from_mapping(mapping)


def test_sensor_rates_must_be_whole_multiples_of_the_physics_step():
    physics = PhysicsConfig(timestep=0.001)
    assert physics.timestep_ns == 1_000_000
    assert physics.steps_per_period(200.0, "sensor.imu.rate_hz") == 5
    assert physics.steps_per_period(10.0, "sensor.camera.rate_hz") == 100
    with pytest.raises(ConfigError, match=r"sensor\.imu\.rate_hz must be a rate whose period is a whole multiple"):
        physics.steps_per_period(300.0, "sensor.imu.rate_hz")
    with pytest.raises(ConfigError, match=r"sensor\.imu\.rate_hz must be a number in \(0\.0, 1000\.0\]"):
        physics.steps_per_period(2000.0, "sensor.imu.rate_hz")
    with pytest.raises(ConfigError, match=r"sensor\.camera\.rate_hz"):
        PhysicsConfig(timestep=0.003).steps_per_period(200.0, "sensor.camera.rate_hz")


def test_board_offset_and_tilt_are_applied_about_the_board_centre():
    cfg = SimConfig.from_mapping({"board": {"distance": 1.2, "offset": [0.1, -0.05], "tilt_rpy": [0.3, -0.2, 0.1]}})
    sim = PandaSim(cfg)
    T_body_board = invert_transform(body_pose(sim.model, sim.data, "cam_body")) @ sim.T_world_board
    centre = transform_points(T_body_board, cfg.board.target.center)
    np.testing.assert_allclose(centre, [1.2, 0.1, -0.05], atol=1e-9)
    facing = np.array([[0.0, 0.0, -1.0], [0.0, -1.0, 0.0], [-1.0, 0.0, 0.0]])
    np.testing.assert_allclose(T_body_board[:3, :3], facing @ euler_to_matrix([0.3, -0.2, 0.1]), atol=1e-9)
    board = sim.model.body("board").id
    np.testing.assert_allclose(sim.data.xpos[board], sim.T_world_board[:3, 3], atol=1e-9)
