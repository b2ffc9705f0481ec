"""Per-episode sensor sampling: reproducible draws, moments of the configured distributions, bad input."""

from pathlib import Path

import numpy as np
import pytest
import yaml

from vical.config_checks import ConfigError
from vical.data import ImuNoise
from vical.geometry import R_CAM_BODY, matrix_to_euler
from vical.sim.sampling import (
    ImuSampling,
    SensorSampling,
    mean_sensor,
    sample_sensor,
    sensor_imu_pose,
)

PAPER = Path(__file__).resolve().parents[1] / "conf" / "sensor" / "paper.yaml"


@pytest.fixture(scope="module")
def paper():
    return SensorSampling.from_config(yaml.safe_load(PAPER.read_text()))


@pytest.fixture(scope="module")
def draws(paper):
    rng = np.random.default_rng(7)
    return [sample_sensor(paper, rng, asymmetric=True) for _ in range(3000)]


def test_paper_file_holds_the_paper_values(paper):
    assert (paper.camera.width, paper.camera.height, paper.camera.rate_hz, paper.imu.rate_hz) == (640, 480, 10.0, 200.0)
    assert (paper.camera.hfov.mean, paper.camera.hfov.std) == (1.0, 0.05)
    assert paper.extrinsic.position_mean == (0.06, 0.0, -0.10)
    assert paper.extrinsic.rpy_mean == (0.0, 0.0, 1.57)
    noise = paper.imu.kalibr_noise()
    assert (noise.accel_noise_density, noise.accel_random_walk) == (0.004, 0.006)
    assert (noise.gyro_noise_density, noise.gyro_random_walk) == (0.0003394, 0.000038785)


def test_the_simulated_imu_noise_defaults_to_the_data_types(paper):
    """One home of the paper's IMU noise: ImuNoise's defaults, which the sensor distribution and the file agree with."""
    assert ImuSampling().kalibr_noise() == ImuNoise() == paper.imu.kalibr_noise()


def test_same_seed_same_sensor(paper):
    a = sample_sensor(paper, np.random.default_rng(3), asymmetric=True)
    b = sample_sensor(paper, np.random.default_rng(3), asymmetric=True)
    c = sample_sensor(paper, np.random.default_rng(4), asymmetric=True)
    assert a.to_dict() == b.to_dict()
    assert a.to_dict() != c.to_dict()


def _check_moments(samples, mean, std):
    samples = np.asarray(samples)
    n = len(samples)
    # 5-sigma bounds on the sample mean; 10 % on the sample std (its relative sigma is 1/sqrt(2n) = 1.3 %).
    assert abs(samples.mean() - mean) < 5 * std / np.sqrt(n) + 1e-12
    assert samples.std(ddof=1) == pytest.approx(std, rel=0.1)


def test_camera_moments(paper, draws):
    hfov = [2 * np.arctan(s.camera.width / (2 * s.camera.fx)) for s in draws]
    _check_moments(hfov, 1.0, 0.05)
    assert all(s.camera.fx == s.camera.fy and s.camera.cx == 319.5 and s.camera.cy == 239.5 for s in draws)
    dist = np.array([s.camera.dist for s in draws])
    _check_moments(dist[:, 0], 0.0, 0.02)
    _check_moments(dist[:, 1], 0.0, 0.02)
    _check_moments(dist[:, 2], 0.0, paper.camera.tangential_std)
    offsets = np.array([s.camera.distortion_center_offset for s in draws])
    _check_moments(offsets[:, 0] / 640, 0.0, 0.05)
    _check_moments(offsets[:, 1] / 480, 0.0, 0.05)


def test_extrinsic_moments_in_body_frame(draws):
    T = np.array([sensor_imu_pose(s) for s in draws])
    for axis, (mean, std) in enumerate([(0.06, 0.01), (0.0, 0.01), (-0.10, 0.01)]):
        _check_moments(T[:, axis, 3], mean, std)
    rpy = np.array([matrix_to_euler(t[:3, :3]) for t in T])
    for axis, mean in enumerate([0.0, 0.0, 1.57]):
        _check_moments(rpy[:, axis], mean, 0.1)


def test_extrinsic_composes_with_the_optical_frame(draws):
    s = draws[0]
    np.testing.assert_allclose(s.T_cam_imu[:3, :3], R_CAM_BODY @ sensor_imu_pose(s)[:3, :3], atol=1e-12)
    np.testing.assert_allclose(s.T_cam_imu[:3, 3], R_CAM_BODY @ sensor_imu_pose(s)[:3, 3], atol=1e-12)


def test_symmetric_sensors_have_no_centre_offset_or_tangential_terms(paper):
    s = sample_sensor(paper, np.random.default_rng(0), asymmetric=False)
    assert np.all(s.camera.distortion_center_offset == 0) and np.all(s.camera.dist[2:] == 0)


def test_time_offset_and_biases_are_drawn(paper):
    raw = yaml.safe_load(PAPER.read_text())
    raw["time_offset"] = {"mean": 0.005, "std": 0.002}
    raw["imu"]["gyro_bias_std"] = 0.01
    raw["imu"]["accel_bias_std"] = 0.1
    cfg = SensorSampling.from_config(raw)
    rng = np.random.default_rng(1)
    sensors = [sample_sensor(cfg, rng) for _ in range(2000)]
    _check_moments([s.time_offset for s in sensors], 0.005, 0.002)
    _check_moments([s.gyro_bias[1] for s in sensors], 0.0, 0.01)
    _check_moments([s.accel_bias[2] for s in sensors], 0.0, 0.1)


def test_mean_sensor_is_the_nominal_rig(paper):
    s = mean_sensor(paper)
    np.testing.assert_allclose(sensor_imu_pose(s)[:3, 3], [0.06, 0.0, -0.10], atol=1e-12)
    np.testing.assert_allclose(matrix_to_euler(sensor_imu_pose(s)[:3, :3]), [0, 0, 1.57], atol=1e-12)
    assert s.camera.hfov == pytest.approx(1.0)


def test_discrete_noise_units_convert_to_kalibr_densities():
    cfg = SensorSampling.from_config(
        {"imu": {"noise_units": "discrete", "rate_hz": 100.0, "gyro_noise": 0.01, "gyro_random_walk": 0.001}}
    )
    noise = cfg.imu.kalibr_noise()
    assert noise.gyro_noise_density == pytest.approx(0.01 / 10.0)
    assert noise.gyro_random_walk == pytest.approx(0.001 * 10.0)


@pytest.mark.parametrize(
    ("override", "match"),
    [
        ({"camera": {"hfov": {"mean": 3.2, "std": 0.05}}}, r"sensor\.camera\.hfov\.mean"),
        ({"camera": {"hfov": {"mean": 0.0, "std": 0.05}}}, r"sensor\.camera\.hfov\.mean"),
        ({"camera": {"k1": {"mean": float("nan"), "std": 0.0}}}, r"sensor\.camera\.k1\.mean"),
        ({"camera": {"k2": {"mean": 0.0, "std": -1.0}}}, r"sensor\.camera\.k2\.std"),
        ({"camera": {"width": 0}}, r"sensor\.camera\.width"),
        ({"extrinsic": {"rpy_std": [0.1, 0.1]}}, r"sensor\.extrinsic\.rpy_std"),
        ({"imu": {"noise_units": "psd"}}, r"sensor\.imu\.noise_units"),
        ({"imu": {"gyro_noise": -1.0}}, r"sensor\.imu\.gyro_noise"),
        ({"backend": "raytrace"}, r"sensor\.backend"),
        ({"camera": {"fov": 1.0}}, r"sensor\.camera: unknown setting"),
    ],
)
def test_bad_config_names_the_field(override, match):
    with pytest.raises(ConfigError, match=match):
        SensorSampling.from_config(override)


def test_distortion_that_always_folds_over_is_refused():
    cfg = SensorSampling.from_config({"camera": {"k1": {"mean": -3.0, "std": 0.0}}})
    with pytest.raises(ConfigError, match=r"no valid camera.*k1\.std"):
        sample_sensor(cfg, np.random.default_rng(0))


def test_paper_file_equals_the_dataclass_defaults(paper):
    assert paper == SensorSampling()


def test_wide_angle_lenses_are_drawn_up_to_180_deg_and_beyond():
    rng = np.random.default_rng(5)
    for model in ("ds", "eucm"):
        cfg = SensorSampling.from_config({"camera": {"distortion": model, "hfov": {"mean": 3.3, "std": 0.05}}})
        cameras = [sample_sensor(cfg, rng, asymmetric=True).camera for _ in range(400)]
        assert {c.distortion for c in cameras} == {model} and not any(c.distortion_center_offset.any() for c in cameras)
        # The edge ray of every draw sits at the image edge: the field of view is the drawn one.
        coeffs = np.array([c.dist for c in cameras])
        means, stds = ([-0.2, 0.6], [0.05, 0.03]) if model == "ds" else ([0.6, 1.1], [0.03, 0.05])
        for k in range(2):
            _check_moments(coeffs[:, k], means[k], stds[k])
        hfov = [2 * np.arccos(c.bearings(np.array([[c.cx + c.width / 2, c.cy]]))[0][0, 2]) for c in cameras]
        _check_moments(hfov, 3.3, 0.05)
    assert mean_sensor(cfg).camera.dist.tolist() == [0.6, 1.1]


def test_a_wide_angle_field_of_view_for_a_pinhole_model_is_refused():
    with pytest.raises(ConfigError, match=r"sensor\.camera\.hfov\.mean"):
        SensorSampling.from_config({"camera": {"hfov": {"mean": 3.3, "std": 0.0}}})
    with pytest.raises(ConfigError, match=r"sensor\.camera\.distortion must be one of"):
        SensorSampling.from_config({"camera": {"distortion": "omni"}})


@pytest.mark.parametrize(
    ("model", "mean", "message"),
    [
        ("eucm", {"beta": -1.0}, "sensor.camera.beta.mean must be > 0 for the eucm model, got -1.0"),
        ("eucm", {"alpha": 1.4}, "sensor.camera.alpha.mean must be in [0, 1] for the eucm model, got 1.4"),
        ("ds", {"xi": 1.2}, "sensor.camera.xi.mean must be in [-1, 1] for the ds model, got 1.2"),
        ("ds", {"alpha": -0.1}, "sensor.camera.alpha.mean must be in [0, 1] for the ds model, got -0.1"),
        ("ds", {"hfov": 6.2}, "sensor.camera.hfov.mean must be a field of view the mean lens projects (ds with"),
    ],
)
def test_a_wide_angle_mean_outside_the_models_range_names_its_key(model, mean, message):
    # Before the check, only the first draw failed, with "100 draws gave no valid camera ... reduce the spread".
    camera = {"distortion": model, **{name: {"mean": value, "std": 0.05} for name, value in mean.items()}}
    with pytest.raises(ConfigError) as refused:
        SensorSampling.from_config({"camera": camera})
    assert str(refused.value).startswith(message)


def test_imu_intrinsics_are_drawn_only_when_configured(paper):
    rng_a, rng_b = np.random.default_rng(5), np.random.default_rng(5)
    exact = sample_sensor(paper, rng_a)
    assert exact.imu_intrinsics.is_identity()
    raw = yaml.safe_load(PAPER.read_text())
    raw["imu"].update(accel_scale_std=0.01, gyro_misalignment_std=0.002, g_sensitivity_std=0.0005)
    cfg = SensorSampling.from_config(raw)
    first = sample_sensor(cfg, rng_b)
    # Drawn after everything else: the same sensor otherwise, so configurations without them are unchanged.
    assert first.camera == exact.camera and np.array_equal(first.T_cam_imu, exact.T_cam_imu)
    sensors = [sample_sensor(cfg, rng_b) for _ in range(2000)]
    _check_moments([s.imu_intrinsics.M_accel[1, 1] for s in sensors], 1.0, 0.01)
    _check_moments([s.imu_intrinsics.M_gyro[2, 0] for s in sensors], 0.0, 0.002)
    _check_moments([s.imu_intrinsics.A_gyro[0, 2] for s in sensors], 0.0, 0.0005)
    assert all(np.array_equal(np.diag(s.imu_intrinsics.M_gyro), np.ones(3)) for s in sensors)  # scale std 0
    restored = type(first).from_dict(first.to_dict())
    np.testing.assert_allclose(restored.imu_intrinsics.vector(True), first.imu_intrinsics.vector(True), atol=1e-15)
