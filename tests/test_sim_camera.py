"""Camera backends: analytic projection with visibility rules, rendering + distortion warp + detection."""

import os
import signal
import sys

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import pytest

from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.synthetic import wide_angle_camera
from vical.config_checks import ConfigError
from vical.geometry import (
    CameraModel,
    euler_to_matrix,
    make_transform,
    so3_exp,
)
from vical.sim import PandaSim, camera_pose_cv
from vical.sim.camera import (
    ProjectBackend,
    RenderBackend,
    VisibilityRules,
    cube_face_pinhole,
    distortion_maps,
    interpolate_pose,
    render_pinhole,
    warp_views,
)
from vical.sim.sampling import SensorSampling, mean_sensor, sample_sensor


@pytest.fixture(scope="module")
def sim():
    return PandaSim()


@pytest.fixture(scope="module")
def target(sim):
    return sim.cfg.board.target


@pytest.fixture(scope="module")
def renderer(sim, target):
    backend = RenderBackend(sim.model, target, detect_checkerboard)
    yield backend
    backend.close()


def _view(sim, target, rng, distance=(0.7, 1.5), tilt=0.35):
    """A camera pose looking at the board centre from a random direction within ``tilt`` [rad] of its normal."""
    T_board = sim.T_world_board
    centre = T_board[:3, :3] @ target.center + T_board[:3, 3]
    # Optical axis against the board normal; image rows along board x, columns along board y.
    R_board_cam = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    R = T_board[:3, :3] @ so3_exp(rng.uniform(-tilt, tilt, 3)) @ R_board_cam
    d = rng.uniform(*distance)
    return make_transform(R, centre - d * R[:, 2] + rng.normal(0.0, 0.03, 3))


def test_interpolated_pose_is_exact_between_steps():
    # Closed form: a rotation about a fixed axis and a straight translation, at 12.3 % of the step.
    axis = np.array([0.2, -0.6, 0.77]) / np.linalg.norm([0.2, -0.6, 0.77])
    R_base = euler_to_matrix([0.1, 0.2, 0.3])
    T0 = make_transform(R_base, [1.0, 2.0, 3.0])
    T1 = make_transform(R_base @ so3_exp(0.02 * axis), [1.001, 2.0, 2.999])
    T = interpolate_pose(1_000_123, 1_000_000, T0, 1_001_000, T1)
    expected = make_transform(R_base @ so3_exp(0.123 * 0.02 * axis), [1.000123, 2.0, 2.999877])
    np.testing.assert_allclose(T, expected, atol=1e-15)
    np.testing.assert_allclose(interpolate_pose(5, 5, T0, 6, T1), T0)
    with pytest.raises(ValueError, match="outside the interval"):
        interpolate_pose(7, 5, T0, 6, T1)


def test_whole_board_visible_at_mean_sensor_and_home(sim, target):
    sim.reset()
    camera = mean_sensor(SensorSampling()).camera
    backend = ProjectBackend(target, sim.T_world_board, 0.0)
    uv = backend.ideal_corners(camera, camera_pose_cv(sim.model, sim.data))
    assert uv is not None and uv.shape == (target.num_points, 2)
    assert np.all(camera.in_image(uv, border=50.0))


def test_projection_noise_has_the_configured_sigma(sim, target):
    sim.reset()
    camera = mean_sensor(SensorSampling()).camera
    backend = ProjectBackend(target, sim.T_world_board, 0.3)
    T = camera_pose_cv(sim.model, sim.data)
    ideal = backend.ideal_corners(camera, T)
    rng = np.random.default_rng(0)
    residuals = np.vstack([backend.observe(camera, T, rng)[0] - ideal for _ in range(200)])
    assert residuals.mean() == pytest.approx(0.0, abs=0.01)
    assert residuals.std() == pytest.approx(0.3, rel=0.05)
    _, ids = backend.observe(camera, T, rng)
    assert ids.tolist() == list(range(target.num_points))


def test_visibility_rules_reject_what_a_detector_cannot_see(sim, target):
    sim.reset()
    camera = mean_sensor(SensorSampling()).camera
    backend = ProjectBackend(target, sim.T_world_board, 0.0)
    T_home = camera_pose_cv(sim.model, sim.data)
    turn = make_transform(euler_to_matrix([0.0, np.pi, 0.0]), np.zeros(3))
    assert backend.ideal_corners(camera, T_home @ turn) is None  # board behind the camera
    aside = make_transform(euler_to_matrix([0.0, 0.5, 0.0]), np.zeros(3))
    assert backend.ideal_corners(camera, T_home @ aside) is None  # board partly out of the image
    far = T_home @ make_transform(np.eye(3), [0.0, 0.0, -30.0])
    assert backend.ideal_corners(camera, far) is None  # squares too small
    # Seen at 70 deg from its normal (limit 60 deg) the board is refused even though it fits.
    T_board = sim.T_world_board
    centre = T_board[:3, :3] @ target.center + T_board[:3, 3]
    R = T_board[:3, :3] @ euler_to_matrix([0.0, np.radians(70.0), 0.0]) @ np.diag([1.0, -1.0, -1.0])
    oblique = make_transform(R, centre - 1.2 * R[:, 2])
    assert backend.ideal_corners(camera, oblique) is None
    assert (
        ProjectBackend(target, T_board, 0.0, VisibilityRules(max_obliquity=1.5)).ideal_corners(camera, oblique)
        is not None
    )
    with pytest.raises(ConfigError, match=r"visibility\.max_obliquity"):
        VisibilityRules(max_obliquity=2.0)


@pytest.mark.parametrize("distortion", ["radtan", "equidistant"])
def test_distortion_warp_round_trip(distortion):
    dist = [-0.04, 0.02, 0.001, -0.0005] if distortion == "radtan" else [0.02, -0.01, 0.005, 0.0]
    camera = CameraModel.from_hfov(1.05, dist=dist, distortion=distortion, distortion_center_offset=[12.0, -9.0])
    pinhole = render_pinhole(camera, 800, 600)
    map_x, map_y = distortion_maps(camera, pinhole)
    rng = np.random.default_rng(1)
    uv = rng.uniform([0, 0], [camera.width - 1, camera.height - 1], (2000, 2))
    # Bilinear lookup of the maps at the distorted pixels, as cv2.remap samples them.
    i0, j0 = np.floor(uv[:, 1]).astype(int), np.floor(uv[:, 0]).astype(int)
    fy, fx = uv[:, 1] - i0, uv[:, 0] - j0

    def bilinear(m):
        return (
            m[i0, j0] * (1 - fx) * (1 - fy)
            + m[i0, j0 + 1] * fx * (1 - fy)
            + m[i0 + 1, j0] * (1 - fx) * fy
            + m[i0 + 1, j0 + 1] * fx * fy
        )

    warped = np.stack([bilinear(map_x), bilinear(map_y)], axis=1)
    rays = camera.unproject(uv)
    expected, _ = pinhole.project(rays)
    assert np.max(np.linalg.norm(warped - expected, axis=1)) < 0.05
    # Every ray of the image lies inside the render (the warp never samples outside it).
    assert map_x.min() >= 0 and map_x.max() <= pinhole.width - 1
    assert map_y.min() >= 0 and map_y.max() <= pinhole.height - 1


def test_render_matches_projection_over_varied_poses(sim, target, renderer):
    sim.reset()
    rng = np.random.default_rng(3)
    sampling = SensorSampling()
    project = ProjectBackend(target, sim.T_world_board, 0.0)
    errors, compared = [], 0
    for k in range(12):
        camera = sample_sensor(sampling, rng, asymmetric=k % 2 == 1).camera
        renderer.set_camera(camera)
        T = _view(sim, target, rng)
        ideal = project.ideal_corners(camera, T)
        corners, ids, image = renderer.observe(sim.data, T)
        assert image.shape == (480, 640) and image.dtype == np.uint8
        if ideal is None:
            continue
        assert len(ids) == target.num_points, f"view {k}: projection says visible, detector found {len(ids)}"
        errors.append(corners - ideal[ids])
        compared += 1
    errors = np.vstack(errors)
    rms = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    assert compared >= 8
    print(f"render vs project: {compared} views, {rms:.3f} px RMS, bias {errors.mean(axis=0)}")
    assert rms <= 0.3, rms
    assert np.all(np.abs(errors.mean(axis=0)) < 0.05)  # no bias (pixel-centre convention)


def test_render_reports_nothing_when_the_board_is_out_of_view(sim, target, renderer):
    sim.reset()
    renderer.set_camera(mean_sensor(SensorSampling()).camera)
    T_away = camera_pose_cv(sim.model, sim.data) @ make_transform(euler_to_matrix([0.0, 0.9, 0.0]), np.zeros(3))
    corners, ids, _ = renderer.observe(sim.data, T_away)
    assert corners.shape == (0, 2) and ids.shape == (0,)


def test_render_pose_is_the_given_pose_not_the_arm(sim, target, renderer):
    # The rendered view follows T_world_cam even when the arm sits elsewhere: shifting the camera
    # 5 cm right moves the board left in the image by f * 0.05 / z.
    sim.reset()
    camera = mean_sensor(SensorSampling()).camera
    renderer.set_camera(camera)
    T = camera_pose_cv(sim.model, sim.data)
    a, _, _ = renderer.observe(sim.data, T)
    b, _, _ = renderer.observe(sim.data, T @ make_transform(np.eye(3), [0.05, 0.0, 0.0]))
    shift = (b - a).mean(axis=0)
    assert shift[0] == pytest.approx(-camera.fx * 0.05 / sim.cfg.board.distance, abs=0.1)
    assert abs(shift[1]) < 0.1


def test_render_size_beyond_the_offscreen_buffer_is_refused(sim, target):
    with pytest.raises(ValueError, match="exceeds the scene's offscreen buffer 1280 x 960"):
        RenderBackend(sim.model, target, detect_checkerboard, render_size=(2000, 1500))
    backend = RenderBackend(sim.model, target, detect_checkerboard, render_size=(320, 240))
    try:
        with pytest.raises(RuntimeError, match="set_camera"):
            backend.image(sim.data, np.eye(4))
    finally:
        backend.close()


@pytest.mark.parametrize("model", ["ds", "eucm"])
def test_a_180_deg_lens_warps_from_the_cube_faces_its_rays_cross(model):
    camera = wide_angle_camera(model, 180.0)
    views = warp_views(camera, 704, 528)
    assert len(views.rotations) == 5  # front and four sides; no ray looks backwards
    assert views.seen.mean() > 0.98  # the ds lens's image circle leaves its image corners dark
    rng = np.random.default_rng(2)
    uv = rng.uniform([0, 0], [camera.width - 1, camera.height - 1], (3000, 2))
    i, j = np.rint(uv[:, 1]).astype(int), np.rint(uv[:, 0]).astype(int)
    i, j = i[views.seen[i, j]], j[views.seen[i, j]]
    src = np.stack([views.map_x[i, j], views.map_y[i, j]], axis=1).astype(float)
    face = (src[:, 1] // 528).astype(int)
    local = views.pinhole.unproject(src - np.stack([np.zeros(len(src)), face * 528.0], axis=1))
    rays = np.einsum("nij,nj->ni", views.rotations[face], local)
    expected, _ = camera.bearings(np.stack([j, i], axis=1).astype(float))
    angle = np.arccos(np.clip(np.sum(rays / np.linalg.norm(rays, axis=1, keepdims=True) * expected, axis=1), -1, 1))
    assert np.rad2deg(angle).max() < 1e-3
    # Every ray lands inside its face, away from the neighbouring face's rows.
    row = src[:, 1] - face * 528.0
    assert src[:, 0].min() >= 1.0 and src[:, 0].max() <= 702.0 and row.min() >= 1.0 and row.max() <= 526.0
    assert cube_face_pinhole(704, 528).project(np.array([[1.0, 1.0, 1.0]]))[0].tolist() == [
        [701.0, 525.0]
    ]  # 2 px inside the last pixel centre


def test_render_of_a_180_deg_fisheye_matches_the_projection(sim, target, renderer):
    """The board 50-60 deg off the axis of a 180 deg double-sphere lens, beyond what one pinhole render covers."""
    sim.reset()
    camera = wide_angle_camera("ds", 180.0)
    renderer.set_camera(camera)
    project = ProjectBackend(target, sim.T_world_board, 0.0)
    T_board = sim.T_world_board
    centre = T_board[:3, :3] @ target.center + T_board[:3, 3]
    R_board_cam = np.array([[0.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
    errors = []
    for yaw in (0.9, -0.85):
        R = T_board[:3, :3] @ R_board_cam @ so3_exp([0.0, yaw, 0.0])
        T = make_transform(R, centre - 0.35 * (T_board[:3, :3] @ R_board_cam)[:, 2])
        ideal = project.ideal_corners(camera, T)
        corners, ids, _ = renderer.observe(sim.data, T)
        assert ideal is not None and len(ids) == target.num_points
        errors.append(corners - ideal[ids])
    errors = np.vstack(errors)
    rms = float(np.sqrt(np.mean(np.sum(errors**2, axis=1))))
    print(f"fisheye render vs project: {rms:.3f} px RMS")
    assert rms < 0.3
    # A 240 deg lens folds 123 deg off its axis: the image corners beyond have no ray and stay black.
    renderer.set_camera(CameraModel.from_hfov(np.deg2rad(240.0), dist=[-0.2, 0.6], distortion="ds"))
    image = renderer.image(sim.data, camera_pose_cv(sim.model, sim.data))
    dark = ~renderer.views.seen
    assert dark[0, 0] and dark[-1, -1] and not dark[240, 320]
    assert image[dark].max() == 0 and image[~dark].max() > 200  # the white board squares


def _opengl_calls(k: int | None, counted: list[int]):
    """A trace function: count the calls into PyOpenGL's Python code (its ctypes argument converters among them) and
    send this process SIGINT at the ``k``-th: a Ctrl-C landing inside the GL context's calls."""

    def trace(frame, event, arg):
        if event == "call" and f"{os.sep}OpenGL{os.sep}" in frame.f_code.co_filename:
            counted[0] += 1
            if counted[0] == k:
                signal.raise_signal(signal.SIGINT)
        return None

    return trace


def test_a_ctrl_c_inside_the_gl_calls_of_a_render_stops_it_as_an_interrupt(sim, renderer):
    """ctypes turns an exception raised while it converts a foreign call's argument into ``ctypes.ArgumentError``: a
    Ctrl-C landing in PyOpenGL's converters (the GL context made current at every render) must still end the render as
    ``KeyboardInterrupt`` (a command's one line and status 130), and the renderer renders on after it."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)  # an xdist worker may ignore SIGINT
    try:
        sim.reset()
        renderer.set_camera(mean_sensor(SensorSampling()).camera)
        T = camera_pose_cv(sim.model, sim.data)
        counted = [0]
        sys.settrace(_opengl_calls(None, counted))
        try:
            expected = renderer.image(sim.data, T)
        finally:
            sys.settrace(None)
        assert counted[0] >= 1  # the render calls into PyOpenGL (EGL's eglMakeCurrent)
        for k in range(1, counted[0] + 1):
            sys.settrace(_opengl_calls(k, [0]))
            try:
                with pytest.raises(KeyboardInterrupt):
                    renderer.image(sim.data, T)
            finally:
                sys.settrace(None)
        np.testing.assert_array_equal(renderer.image(sim.data, T), expected)
    finally:
        signal.signal(signal.SIGINT, previous)
