"""Kalibr's omni camera (the unified projection, parameter xi), without distortion (vical's ``omni``, Kalibr's
omni-none) and with radtan on its projected coordinates (``omni-radtan``): projection against formulas written
here, Jacobians against finite differences, unprojection, Kalibr's files, and calibration of synthetic data.

``cv2.omnidir`` (OpenCV's Mei model) is not in the installed OpenCV (opencv-python-headless 5.0.0 has no
contrib modules), so the independent references are the formulas below and the eucm model, which with
``beta = 1`` is the same projection in other parameters.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import yaml

from vical.apps.calibrate import main as calibrate_main
from vical.calib.metrics import calibration_errors, image_differences_px
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.pipeline import calibrate_joint
from vical.calib.synthetic import Excitation, make_recording, scattered_views
from vical.data import ImuNoise, Target
from vical.geometry import CameraModel, CameraModelError
from vical.io.csvfiles import write_corners_csv
from vical.io.euroc import read_euroc, write_euroc
from vical.io.kalibr import read_camchain, write_camchain_imucam, write_target_yaml
from vical.io.kalibr_chain import read_chain, write_chain

TARGET = Target.checkerboard()
SIZE = (640, 480)
COEFFICIENTS = {"omni": [1.4], "omni-radtan": [0.9, -0.25, 0.06, 4e-4, -3e-4]}


def omni_camera(model: str, hfov_deg: float = 180.0) -> CameraModel:
    """A 640 x 480 lens of ``model`` with ``hfov_deg`` across the width, its principal point off centre."""
    camera = CameraModel.from_hfov(np.deg2rad(hfov_deg), *SIZE, dist=COEFFICIENTS[model], distortion=model)
    return camera.with_intrinsics(camera.fx * 1.01, camera.fy, camera.cx + 4.0, camera.cy - 3.0, camera.dist)


def unified_pixels(camera: CameraModel, p: np.ndarray) -> np.ndarray:
    """Kalibr's OmniProjection written out: ``m = (x, y) / (z + xi |p|)``, radtan on ``m``, then ``f m + c``."""
    xi = camera.dist[0]
    m = p[:, :2] / (p[:, 2] + xi * np.linalg.norm(p, axis=1))[:, None]
    if camera.distortion == "omni-radtan":
        k1, k2, p1, p2 = camera.dist[1:]
        x, y = m[:, 0], m[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + k1 * r2 + k2 * r2 * r2
        m = np.stack([x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y)
                      + 2 * p2 * x * y], axis=1)  # fmt: skip
    return m * [camera.fx, camera.fy] + [camera.cx, camera.cy]


def rays(max_angle_deg: float, n: int = 300, seed: int = 0) -> np.ndarray:
    """Points (n, 3) [m] 0.3-3 m away, up to ``max_angle_deg`` from the optical axis."""
    rng = np.random.default_rng(seed)
    theta = np.deg2rad(max_angle_deg) * np.sqrt(rng.uniform(0.0, 1.0, n))
    phi = rng.uniform(0.0, 2 * np.pi, n)
    direction = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], axis=1)
    return direction * rng.uniform(0.3, 3.0, n)[:, None]


# ------------------------------------------------------------------------------- geometry
@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_projection_is_kalibrs_unified_projection_beyond_90_deg(model):
    camera = omni_camera(model)
    p = rays(110.0)  # omni's xi = 1.4 projects one-to-one up to 135.6 deg (z / |p| > -1 / xi)
    uv, ok = camera.project(p)
    assert ok.all()
    np.testing.assert_allclose(uv, unified_pixels(camera, p), rtol=0, atol=1e-9)


def test_omni_is_eucm_with_beta_1():
    """eucm's ``alpha rho + (1 - alpha) z`` with ``rho = |p|`` (beta = 1) is ``(1 - alpha) (z + xi |p|)`` with
    ``xi = alpha / (1 - alpha)``: the same pixels at focal lengths ``(1 - alpha)`` times omni's."""
    for xi in (0.0, 0.6, 1.0, 1.4):
        alpha = xi / (1.0 + xi)
        omni = CameraModel("omni", *SIZE, 300.0, 310.0, 322.0, 238.0, [xi])
        eucm = CameraModel("eucm", *SIZE, 300.0 / (1 + xi), 310.0 / (1 + xi), 322.0, 238.0, [alpha, 1.0])
        p = rays(80.0, seed=1)
        np.testing.assert_allclose(omni.project(p)[0], eucm.project(p)[0], rtol=0, atol=1e-9)


@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_jacobians_match_finite_differences(model):
    camera = omni_camera(model)
    p = rays(100.0, n=50, seed=2)
    uv, d_point, d_params = camera.project_jacobians(p)
    np.testing.assert_array_equal(uv, camera.project(p)[0])
    eps = 1e-6
    numeric_point = np.stack(
        [(camera.project(p + e)[0] - camera.project(p - e)[0]) / (2 * eps) for e in np.eye(3) * eps], axis=2
    )
    np.testing.assert_allclose(d_point, numeric_point, rtol=1e-6, atol=1e-4)
    params = camera.parameters
    numeric_params = []
    for k in range(len(params)):
        step = np.zeros_like(params)
        step[k] = eps * max(1.0, abs(params[k]))
        up, down = (
            camera.with_parameters(params + step).project(p)[0],
            camera.with_parameters(params - step).project(p)[0],
        )
        numeric_params.append((up - down) / (2 * step[k]))
    np.testing.assert_allclose(d_params, np.stack(numeric_params, axis=2), rtol=1e-6, atol=1e-4)
    assert camera.parameter_names == ["fx", "fy", "cx", "cy", "xi", *(["k1", "k2", "p1", "p2"] if "-" in model else [])]


@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_unprojection_inverts_projection(model):
    camera = omni_camera(model)
    p = rays(125.0, seed=3)
    uv, _ = camera.project(p)
    bearings, seen = camera.bearings(uv)
    assert seen.all()
    np.testing.assert_allclose(bearings, p / np.linalg.norm(p, axis=1, keepdims=True), rtol=0, atol=1e-9)
    front = p[p[:, 2] > 0.05]  # unit-depth rays: in front of the camera
    np.testing.assert_allclose(camera.unproject(camera.project(front)[0]), front / front[:, 2:], rtol=0, atol=1e-8)
    xy = front[:, :2] / front[:, 2:]
    np.testing.assert_allclose(camera.undistort(camera.distort(xy)), xy, rtol=0, atol=1e-8)


def test_a_lens_with_xi_above_1_projects_up_to_its_fold_only():
    camera = CameraModel("omni", *SIZE, 400.0, 400.0, 320.0, 240.0, [2.0])  # folds at z / |p| = -1 / 2: 120 deg
    angles = np.deg2rad([119.0, 121.0])
    p = np.stack([np.sin(angles), np.zeros(2), np.cos(angles)], axis=1)
    assert camera.project(p)[1].tolist() == [True, False]
    far = camera.bearings(np.array([[320.0 + 400.0 / np.sqrt(3.0) * 1.01, 240.0]]))  # beyond r^2 = 1 / (xi^2 - 1)
    assert not far[1][0] and np.isnan(far[0]).all()


def test_a_negative_xi_is_refused_naming_it():
    with pytest.raises(CameraModelError, match=r"^omni parameter xi must be >= 0, got -0.1$"):
        CameraModel("omni", *SIZE, 300.0, 300.0, 320.0, 240.0, [-0.1])
    with pytest.raises(CameraModelError, match=r"omni-radtan needs 5 coefficients \['xi', 'k1', 'k2', 'p1', 'p2'\]"):
        CameraModel("omni-radtan", *SIZE, 300.0, 300.0, 320.0, 240.0, [0.9])


def test_an_omni_radtan_lens_whose_radtan_folds_in_the_image_is_not_invertible():
    omni_camera("omni-radtan").check_invertible()
    folding = CameraModel("omni-radtan", *SIZE, 372.0, 368.0, 320.0, 240.0, [0.9, -0.6, 0.0, 0.0, 0.0])
    with pytest.raises(CameraModelError, match=r"omni-radtan coefficients .* are not invertible over the image"):
        folding.check_invertible()  # x (1 - 0.6 r^2) turns back at r = 0.75; the image corners reach r = 1.07


# ------------------------------------------------------------------------------- Kalibr's files
KALIBR_OMNI_RADTAN = """\
cam0:
  cam_overlaps: []
  camera_model: omni
  distortion_coeffs: [-0.2452873129, 0.0597421851, 0.0004125581, -0.0002980047]
  distortion_model: radtan
  intrinsics: [0.9012781264, 373.4517287361, 368.1903112854, 327.1825736431, 233.6904028845]
  resolution: [640, 480]
  rostopic: /cam0/image_raw
"""


def test_a_kalibr_omni_radtan_camchain_is_read_and_kept_whole(tmp_path):
    path = tmp_path / "camchain.yaml"
    path.write_text(KALIBR_OMNI_RADTAN)
    camera, _, _ = read_camchain(path)
    assert camera.distortion == "omni-radtan"
    np.testing.assert_array_equal(camera.dist, [0.9012781264, -0.2452873129, 0.0597421851, 0.0004125581, -0.0002980047])
    np.testing.assert_array_equal(camera.intrinsics, [373.4517287361, 368.1903112854, 327.1825736431, 233.6904028845])
    out = tmp_path / "out.yaml"
    write_chain(out, read_chain(path))
    assert yaml.safe_load(out.read_text()) == yaml.safe_load(KALIBR_OMNI_RADTAN)


@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_omni_cameras_round_trip_through_kalibrs_and_euroc_files(tmp_path, model):
    camera = omni_camera(model)
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, camera, None, None)
    entry = yaml.safe_load(path.read_text())["cam0"]
    lens = {"omni": ("none", []), "omni-radtan": ("radtan", COEFFICIENTS["omni-radtan"][1:])}[model]
    assert entry["camera_model"] == "omni" and entry["intrinsics"] == [camera.dist[0], *camera.intrinsics]
    assert (entry["distortion_model"], entry["distortion_coeffs"]) == lens
    assert read_camchain(path)[0] == camera
    rec = make_recording(duration=2.0, camera=camera, seed=4)
    blank = np.zeros((len(rec.frames), SIZE[1], SIZE[0]), np.uint8)  # EuRoC folders hold images
    euroc = tmp_path / "euroc"
    write_euroc(replace(rec, frames=replace(rec.frames, images=blank)), euroc)
    sensor = yaml.safe_load((euroc / "mav0" / "cam0" / "sensor.yaml").read_text())
    assert sensor["distortion_model"] == {"omni": "none", "omni-radtan": "radial-tangential"}[model]
    assert read_euroc(euroc, rec.target).truth.camera == camera


# ------------------------------------------------------------------------------- calibration
@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_noise_free_omni_intrinsics_are_recovered_exactly(model):
    camera = omni_camera(model)
    frames, _ = scattered_views(camera, TARGET, 25, seed=1)
    result = calibrate_intrinsics(frames, TARGET, model, SIZE)
    assert np.abs(result.camera.parameters - camera.parameters).max() < 1e-6
    assert result.reprojection.rms < 1e-6


@pytest.mark.parametrize("model", ["omni", "omni-radtan"])
def test_noisy_180_deg_omni_lens_is_recovered_within_3_sigma(model):
    camera = omni_camera(model)
    frames, _ = scattered_views(camera, TARGET, 30, pixel_sigma=0.3, seed=2)
    result = calibrate_intrinsics(frames, TARGET, model, SIZE)
    z = (result.estimate - camera.parameters) / np.sqrt(np.diag(result.covariance))
    distance = image_differences_px(result.camera, camera)
    print(f"{model}: z {np.round(z, 2)}, image rms {np.sqrt(np.mean(distance**2)):.3f} px")
    assert np.all(np.abs(z) < 3.0), z
    assert np.sqrt(np.mean(distance**2)) < 0.5
    assert result.pixel_sigma == pytest.approx(0.3, abs=0.03)
    assert not [w for w in result.warnings if "does not fit" in w]


def test_an_omni_camera_imu_recording_is_calibrated_jointly_within_3_sigma():
    """A camera + IMU recording (``make_recording``) with a 180 deg omni lens: xi, the intrinsics and the extrinsic."""
    rec = make_recording(duration=12.0, camera=omni_camera("omni"), imu_noise=ImuNoise(), pixel_sigma=0.3, seed=2,
                         time_offset=0.004, excitation=Excitation(distance=0.45))  # fmt: skip
    result = calibrate_joint(rec.frames, rec.imu, rec.target, "omni", SIZE, rec.truth.imu_noise)
    sigmas = np.sqrt(np.diag(result.covariance))[:5]
    z = (result.estimate[:5] - rec.truth.camera.parameters) / sigmas
    errors = calibration_errors(result, rec.truth)
    print(f"joint: z {np.round(z, 2)}, {errors.rotation_deg:.4f} deg, {errors.translation_mm:.2f} mm")
    assert result.parameter_names[:5] == ["fx", "fy", "cx", "cy", "xi"] and np.all(np.abs(z) < 3.0), z
    assert errors.rotation_deg < 0.1 and errors.translation_mm < 4.0 and errors.time_offset_ms < 0.3


def test_vical_calibrate_writes_kalibrs_omni_radtan(tmp_path):
    camera = omni_camera("omni-radtan")
    frames, _ = scattered_views(camera, TARGET, 25, pixel_sigma=0.3, seed=3)
    write_corners_csv(frames, tmp_path / "corners.csv")
    write_target_yaml(tmp_path / "target.yaml", TARGET)
    args = [str(tmp_path / "corners.csv"), "--target", str(tmp_path / "target.yaml"), "--task", "intrinsic",
            "--image-size", "640", "480", "--no-report", "--model", "omni-radtan",
            "--out", str(tmp_path / "out")]  # fmt: skip
    assert calibrate_main(args) == 0
    entry = yaml.safe_load((tmp_path / "out" / "camchain.yaml").read_text())["cam0"]
    assert entry["camera_model"] == "omni" and entry["distortion_model"] == "radtan"
    assert len(entry["intrinsics"]) == 5 and len(entry["distortion_coeffs"]) == 4
    calibrated, _, _ = read_camchain(tmp_path / "out" / "camchain.yaml")
    assert np.sqrt(np.mean(image_differences_px(calibrated, camera) ** 2)) < 0.5
