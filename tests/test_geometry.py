"""Geometry: rotations and transforms against closed forms, camera models against OpenCV."""

import cv2
import numpy as np
import pytest

from vical.geometry import (
    R_CAM_BODY,
    CameraModel,
    CameraModelError,
    body_imu_from_cam_imu,
    cam_imu_from_body_imu,
    camera_frame_turn,
    euler_to_matrix,
    invert_transform,
    make_transform,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_matrix,
    so3_exp,
    so3_log,
    step_pose,
    transform_points,
)


def random_rotations(n, seed=0):
    rng = np.random.default_rng(seed)
    return [so3_exp(rng.normal(size=3) * 1.2) for _ in range(n)]


@pytest.mark.parametrize("gap", [1e-9, 1e-6, 1e-5, 9e-5, 1.1e-4, 1e-3])
def test_so3_log_near_pi_about_a_generic_axis(gap):
    axis = np.array([0.3, -0.5, 0.8]) / np.linalg.norm([0.3, -0.5, 0.8])
    w = axis * (np.pi - gap)
    assert np.abs(so3_log(so3_exp(w)) - w).max() < 1e-9


def test_so3_exp_log_roundtrip_including_near_pi():
    rng = np.random.default_rng(1)
    for w in [*list(rng.normal(size=(20, 3))), np.array([np.pi - 1e-6, 0, 0]), np.array([0, 0, 1e-10])]:
        R = so3_exp(w)
        assert np.allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.allclose(so3_exp(so3_log(R)), R, atol=1e-9)


def test_so3_exp_matches_rodrigues_of_opencv():
    w = np.array([0.3, -1.1, 0.7])
    assert np.allclose(so3_exp(w), cv2.Rodrigues(w)[0], atol=1e-12)


def test_so3_log_matches_rodrigues_of_opencv():
    for R in [*random_rotations(50, seed=4), np.eye(3)]:  # (OpenCV gives 0 for angles of 1e-5 rad and less)
        np.testing.assert_allclose(so3_log(R), cv2.Rodrigues(R)[0].ravel(), rtol=0.0, atol=1e-12)


def test_quaternion_roundtrip_and_known_value():
    for R in random_rotations(20):
        q = matrix_to_quat(R)
        assert q[0] >= 0
        assert np.allclose(quat_to_matrix(q), R, atol=1e-12)
    # 90 deg about z: [w, x, y, z] = [cos 45, 0, 0, sin 45]
    Rz = quat_to_matrix([np.cos(np.pi / 4), 0, 0, np.sin(np.pi / 4)])
    assert np.allclose(Rz @ [1, 0, 0], [0, 1, 0])


def test_euler_order_is_rz_ry_rx():
    roll, pitch, yaw = 0.1, -0.2, 1.57
    Rx = so3_exp([roll, 0, 0])
    Ry = so3_exp([0, pitch, 0])
    Rz = so3_exp([0, 0, yaw])
    assert np.allclose(euler_to_matrix([roll, pitch, yaw]), Rz @ Ry @ Rx)
    for R in random_rotations(20, seed=3):
        assert np.allclose(euler_to_matrix(matrix_to_euler(R)), R, atol=1e-10)


def test_transform_inverse_and_points():
    R = so3_exp([0.2, 0.3, -0.4])
    T_a_b = make_transform(R, [1.0, -2.0, 0.5])
    p_b = np.array([[0.1, 0.2, 0.3], [1.0, 0.0, 0.0]])
    p_a = transform_points(T_a_b, p_b)
    assert np.allclose(p_a, (R @ p_b.T).T + [1.0, -2.0, 0.5])
    assert np.allclose(transform_points(invert_transform(T_a_b), p_a), p_b)


@pytest.fixture
def points_cam():
    rng = np.random.default_rng(5)
    p = rng.uniform([-0.8, -0.6, 1.0], [0.8, 0.6, 2.0], size=(200, 3))
    return p


def test_radtan_projection_matches_opencv(points_cam):
    cam = CameraModel.from_hfov(1.0, dist=[0.03, -0.02, 0.001, -0.0008])
    uv, front = cam.project(points_cam)
    ref, _ = cv2.projectPoints(points_cam, np.zeros(3), np.zeros(3), cam.K, np.r_[cam.dist, 0.0])
    assert front.all()
    assert np.abs(uv - ref[:, 0]).max() < 1e-9


def test_equidistant_projection_matches_opencv_fisheye(points_cam):
    cam = CameraModel.from_hfov(1.2, dist=[0.01, -0.005, 0.002, -0.001], distortion="equidistant")
    uv, _ = cam.project(points_cam)
    ref, _ = cv2.fisheye.projectPoints(points_cam[:, None, :], np.zeros(3), np.zeros(3), cam.K, cam.dist)
    assert np.abs(uv - ref[:, 0]).max() < 1e-9


@pytest.mark.parametrize("distortion", ["radtan", "equidistant"])
def test_unproject_inverts_project(points_cam, distortion):
    cam = CameraModel.from_hfov(
        1.0, dist=[0.02, 0.01, 0.0, 0.0], distortion=distortion, distortion_center_offset=[12.0, -8.0]
    )
    uv, _ = cam.project(points_cam)
    rays = cam.unproject(uv)
    assert np.abs(rays[:, :2] - points_cam[:, :2] / points_cam[:, 2:]).max() < 1e-11


JACOBIAN_CAMERAS = {
    "radtan": CameraModel.from_hfov(1.0, dist=[0.03, -0.02, 0.001, -0.0008]),
    "equidistant": CameraModel.from_hfov(1.2, dist=[0.01, -0.005, 0.002, -0.001], distortion="equidistant"),
}


def _numeric_jacobian(f, x0: np.ndarray, step: float) -> np.ndarray:
    """Central differences of f: (D,) -> (N, 2) at x0, as (N, 2, D)."""
    columns = []
    for d in range(len(x0)):
        dx = np.zeros_like(x0)
        dx[d] = step
        columns.append((f(x0 + dx) - f(x0 - dx)) / (2 * step))
    return np.stack(columns, axis=2)


@pytest.mark.parametrize("distortion", ["radtan", "equidistant"])
def test_projection_jacobians_match_central_differences(points_cam, distortion):
    cam = JACOBIAN_CAMERAS[distortion]
    points = np.vstack([points_cam, [[0.0, 0.0, 1.5], [1e-8, -2e-8, 1.2]]])  # on and next to the optical axis
    uv, d_point, d_params = cam.project_jacobians(points)
    assert np.abs(uv - cam.project(points)[0]).max() < 1e-9
    numeric_params = _numeric_jacobian(lambda q: cam.with_parameters(q).project(points)[0], cam.parameters, 1e-7)
    # Central differences on ~500 px values round off at ~1e-6 px per unit of the parameter.
    assert np.allclose(d_params, numeric_params, rtol=1e-6, atol=1e-5)
    for n in (0, 57, len(points) - 2, len(points) - 1):
        numeric = _numeric_jacobian(lambda p, n=n: cam.project(p[None])[0], points[n], 1e-7)[0]
        assert np.abs(d_point[n] - numeric).max() < 1e-5 * np.abs(numeric).max()


def test_projection_jacobians_match_opencv(points_cam):
    # cv2.projectPoints' Jacobian columns: rvec (3), tvec (3), fx, fy, cx, cy, k1, k2, p1, p2, k3.
    cam = JACOBIAN_CAMERAS["radtan"]
    _, d_point, d_params = cam.project_jacobians(points_cam)
    _, J = cv2.projectPoints(points_cam, np.zeros(3), np.zeros(3), cam.K, np.r_[cam.dist, 0.0])
    J = J.reshape(-1, 2, J.shape[1])
    assert np.abs(d_params - J[:, :, 6:14]).max() < 1e-8 * np.abs(J[:, :, 6:14]).max()
    assert np.abs(d_point - J[:, :, 3:6]).max() < 1e-8 * np.abs(J[:, :, 3:6]).max()  # d/d tvec = d/d point


def test_from_hfov_focal_and_centre():
    cam = CameraModel.from_hfov(1.0, 640, 480)
    assert cam.fx == pytest.approx(320.0 / np.tan(0.5))
    assert (cam.cx, cam.cy) == (319.5, 239.5)
    assert cam.hfov == pytest.approx(1.0)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"hfov": 0.0}, "FOV"),
        ({"hfov": np.pi}, "FOV"),
        ({"hfov": 1.0, "dist": [np.nan, 0, 0, 0]}, "finite"),
        ({"hfov": 1.0, "distortion": "fov"}, "unknown"),
    ],
)
def test_impossible_cameras_are_rejected(kwargs, message):
    with pytest.raises(CameraModelError, match=message):
        CameraModel.from_hfov(**kwargs)


def test_folding_distortion_is_reported():
    CameraModel.from_hfov(1.0, dist=[-0.05, 0.02, 0, 0]).check_invertible()
    with pytest.raises(CameraModelError, match="not invertible"):
        CameraModel.from_hfov(1.0, dist=[-2.0, 0.0, 0, 0]).check_invertible()


def test_camera_body_to_optical_frame_axes():
    # docs/conventions.md: body forward -> optical z, body left -> optical -x, body up -> optical -y.
    assert np.allclose(R_CAM_BODY @ [1, 0, 0], [0, 0, 1])
    assert np.allclose(R_CAM_BODY @ [0, 1, 0], [-1, 0, 0])
    assert np.allclose(R_CAM_BODY @ [0, 0, 1], [0, -1, 0])
    T_body_imu = make_transform(so3_exp([0.1, -0.2, 1.5]), [0.06, 0.01, -0.1])
    assert np.allclose(body_imu_from_cam_imu(cam_imu_from_body_imu(T_body_imu)), T_body_imu)


def test_step_pose_moves_in_world_and_adds_euler_increments():
    T = make_transform(euler_to_matrix([0.1, -0.2, 0.3]), [1.0, 2.0, 3.0])
    T2 = step_pose(T, [0.1, 0.0, -0.1], [0.05, 0.1, -0.2])
    np.testing.assert_allclose(T2[:3, 3], [1.1, 2.0, 2.9])
    np.testing.assert_allclose(matrix_to_euler(T2[:3, :3]), [0.15, -0.1, 0.1], atol=1e-12)


@pytest.mark.parametrize("model", ["radtan", "ds"])
def test_a_principal_point_shift_turns_the_camera_frame_by_about_its_angle_at_the_centre(model):
    """Two calibrations of one camera, 7 px apart in cx: the frames' best-fit turn is about the optical axis's
    angle between them (atan(7 / fx) at the centre, about y; the lens bends the rays further out by a little)."""
    coefficients = np.array([-0.28, 0.07, 0.0, 0.0]) if model == "radtan" else np.array([-0.2, 0.6])
    camera = CameraModel.from_hfov(np.radians(80), 752, 480, coefficients, model)
    shifted = camera.with_intrinsics(camera.fx, camera.fy, camera.cx + 7.0, camera.cy, camera.dist)
    turn = so3_log(camera_frame_turn(camera, shifted))
    centre_rays = [shifted.bearings(np.array([[camera.cx, camera.cy]]))[0][0], np.array([0.0, 0.0, 1.0])]
    at_centre = np.arccos(centre_rays[0] @ centre_rays[1])
    assert turn[1] < 0 and abs(turn[1]) == pytest.approx(at_centre, rel=0.03)
    assert np.hypot(turn[0], turn[2]) < 0.01 * abs(turn[1])
    np.testing.assert_allclose(camera_frame_turn(camera, camera), np.eye(3), atol=1e-12)
    # from each to the other: one turn and its inverse
    assert np.allclose(camera_frame_turn(shifted, camera) @ camera_frame_turn(camera, shifted), np.eye(3), atol=1e-9)
