"""Kalibr YAML: exact round trips, Kalibr's key layout, tolerant reading of other VIO variants."""

from __future__ import annotations

import logging

import numpy as np
import pytest
import yaml
from test_io_samples import make_camera, make_truth

from vical.data import ImuIntrinsics, ImuNoise, Target
from vical.geometry.camera import CameraModel
from vical.geometry.transforms import invert_transform
from vical.io.errors import KalibrFormatError
from vical.io.kalibr import (
    read_camchain,
    read_imu_intrinsics,
    read_imu_yaml,
    read_target_yaml,
    write_camchain_imucam,
    write_imu_yaml,
    write_target_yaml,
)
from vical.io.sample_checks import FormatWarning

EUROC_CAM0_SENSOR_YAML = """\
# General sensor definitions.
sensor_type: camera
comment: VI-Sensor cam0 (MT9M034)

# Sensor extrinsics wrt. the body-frame.
T_BS:
  cols: 4
  rows: 4
  data: [0.0148655429818, -0.999880929698, 0.00414029679422, -0.0216401454975,
         0.999557249008, 0.0149672133247, 0.025715529948, -0.064676986768,
        -0.0257744366974, 0.00375618835797, 0.999660727178, 0.00981073058949,
         0.0, 0.0, 0.0, 1.0]

# Camera specific definitions.
rate_hz: 20
resolution: [752, 480]
camera_model: pinhole
intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
distortion_model: radial-tangential
distortion_coefficients: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
"""

VINS_CONFIG = """\
%YAML:1.0
model_type: PINHOLE
camera_model: pinhole
resolution: [640, 480]
intrinsics: [460.0, 459.0, 320.5, 240.5]
distortion_model: plumb_bob
distortion_coeffs: [0.01, -0.02, 0.001, 0.0005]
body_T_cam0: !!opencv-matrix
   rows: 4
   cols: 4
   dt: d
   data: [0.0, -1.0, 0.0, 0.05, 1.0, 0.0, 0.0, -0.02, 0.0, 0.0, 1.0, 0.01, 0.0, 0.0, 0.0, 1.0]
td: -0.0042
"""


@pytest.mark.parametrize("distortion", ["radtan", "equidistant"])
def test_camchain_imucam_round_trip_is_exact(tmp_path, distortion):
    truth = make_truth(distortion)
    path = tmp_path / "camchain-imucam.yaml"
    write_camchain_imucam(path, truth.camera, truth.T_cam_imu, truth.time_offset)
    camera, T, shift = read_camchain(path)
    assert camera == truth.camera
    assert np.array_equal(T, truth.T_cam_imu)
    assert shift == truth.time_offset


def test_camchain_has_kalibr_keys_and_types(tmp_path):
    truth = make_truth()
    path = tmp_path / "camchain-imucam.yaml"
    write_camchain_imucam(path, truth.camera, truth.T_cam_imu, 0.0, rostopic="/cam0/image_raw")
    cam0 = yaml.safe_load(path.read_text())["cam0"]
    assert set(cam0) == {
        "camera_model",
        "intrinsics",
        "distortion_model",
        "distortion_coeffs",
        "resolution",
        "rostopic",
        "cam_overlaps",
        "T_cam_imu",
        "timeshift_cam_imu",
    }
    # Kalibr's ConfigReader rejects ints where it expects floats and vice versa.
    assert all(isinstance(v, float) for v in cam0["intrinsics"]) and cam0["intrinsics"][0] == 45.8
    assert cam0["resolution"] == [64, 48] and all(isinstance(v, int) for v in cam0["resolution"])
    assert isinstance(cam0["timeshift_cam_imu"], float)
    assert cam0["camera_model"] == "pinhole" and cam0["distortion_model"] == "radtan"
    assert np.array(cam0["T_cam_imu"]).shape == (4, 4)


def test_camchain_without_imu(tmp_path):
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, make_camera(), None, None)
    camera, T, shift = read_camchain(path)
    assert camera == make_camera() and T is None and shift is None
    assert "T_cam_imu" not in path.read_text()


def test_distortion_centre_offset_warns(tmp_path):
    cam = CameraModel("radtan", 64, 48, 45.8, 45.9, 31.7, 24.1, [0.1, 0, 0, 0], distortion_center_offset=[2.0, 0])
    with pytest.warns(UserWarning, match="distortion_center_offset"):
        write_camchain_imucam(tmp_path / "c.yaml", cam, None, None)


def test_reads_t_imu_cam_variant_and_says_so(tmp_path, caplog):
    truth = make_truth()
    path = tmp_path / "openvins.yaml"
    write_camchain_imucam(path, truth.camera, truth.T_cam_imu, 0.01)
    data = yaml.safe_load(path.read_text())
    data["cam0"]["T_imu_cam"] = invert_transform(np.array(data["cam0"].pop("T_cam_imu"))).tolist()
    path.write_text(yaml.safe_dump(data))
    with caplog.at_level(logging.INFO, logger="vical.io.kalibr"):
        _, T, _ = read_camchain(path)
    assert np.allclose(T, truth.T_cam_imu, atol=1e-15)
    assert "'T_imu_cam' (camera -> IMU, inverted)" in caplog.text


def test_reads_euroc_sensor_yaml(tmp_path):
    path = tmp_path / "sensor.yaml"
    path.write_text(EUROC_CAM0_SENSOR_YAML)
    camera, T_cam_imu, shift = read_camchain(path)
    assert camera.distortion == "radtan" and (camera.width, camera.height) == (752, 480)
    assert camera.fx == 458.654 and camera.dist[3] == 1.76187114e-05
    # T_BS maps camera points into the body (IMU) frame: the camera origin sits at T_BS's translation.
    T_imu_cam = invert_transform(T_cam_imu)
    assert np.allclose(T_imu_cam[:3, 3], [-0.0216401454975, -0.064676986768, 0.00981073058949])
    assert shift is None


def test_reads_vins_opencv_storage(tmp_path):
    path = tmp_path / "vins.yaml"
    path.write_text(VINS_CONFIG)
    camera, T_cam_imu, shift = read_camchain(path)
    assert camera.distortion == "radtan" and camera.cx == 320.5
    assert np.allclose(invert_transform(T_cam_imu)[:3, 3], [0.05, -0.02, 0.01])
    assert shift == -0.0042


def test_imu_yaml_round_trip_and_keys(tmp_path):
    noise = ImuNoise(0.0028, 0.00086, 0.00016, 2.2e-05, 400.0)
    path = tmp_path / "imu.yaml"
    write_imu_yaml(path, noise, rostopic="/imu0")
    assert read_imu_yaml(path) == noise
    data = yaml.safe_load(path.read_text())
    assert data["rostopic"] == "/imu0" and data["update_rate"] == 400.0
    assert data["gyroscope_random_walk"] == 2.2e-05


def test_reads_euroc_imu_sensor_yaml(tmp_path):
    path = tmp_path / "sensor.yaml"
    path.write_text(
        "sensor_type: imu\nrate_hz: 200\ngyroscope_noise_density: 1.6968e-04\ngyroscope_random_walk: 1.9393e-05\n"
        "accelerometer_noise_density: 2.0000e-3\naccelerometer_random_walk: 3.0000e-3\n"
    )
    assert read_imu_yaml(path) == ImuNoise(2.0e-3, 3.0e-3, 1.6968e-04, 1.9393e-05, 200.0)


@pytest.mark.parametrize(
    "target",
    [Target.checkerboard(rows=6, cols=7, square=0.07), Target("aprilgrid", 6, 6, 0.088, 0.088, 0.3)],
)
def test_target_round_trip(tmp_path, target):
    path = tmp_path / "target.yaml"
    write_target_yaml(path, target)
    assert read_target_yaml(path) == target


def test_reads_kalibr_aprilgrid_file(tmp_path):
    path = tmp_path / "april_6x6.yaml"
    path.write_text("target_type: 'aprilgrid'\ntagCols: 6\ntagRows: 6\ntagSize: 0.088\ntagSpacing: 0.3\n")
    t = read_target_yaml(path)
    assert (t.kind, t.rows, t.cols, t.row_spacing, t.tag_spacing) == ("aprilgrid", 6, 6, 0.088, 0.3)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("target_type: checkerboard\ntargetRows: 6\ntargetCols: 7\nrowSpacingMeters: 0.07\n", "colSpacingMeters"),
        ("target_type: checkerboard\ntargetRows: 6\ntargetCols: 7\nrowSpacingMeters: 70\ncolSpacingMeters: 70\n", "mm"),
        ("target_type: circlegrid\n", "circlegrid"),
        ("target_type: checkerboard\ntargetRows: [6\n", "line 2"),
        ("target_type: checkerboard\ntargetRows: 6.5\ntargetCols: 7\n", "targetRows must be an integer"),
    ],
)
def test_bad_target_files_name_file_and_key(tmp_path, text, message):
    path = tmp_path / "target.yaml"
    path.write_text(text)
    with pytest.raises(KalibrFormatError, match=message) as info:
        read_target_yaml(path)
    assert str(path) in str(info.value)


def test_camchain_with_non_string_keys_is_refused_clearly(tmp_path):
    path = tmp_path / "camchain.yaml"
    path.write_text("1: foo\ncam1: {}\n")
    with pytest.raises(KalibrFormatError, match=r"no section 'cam0'; the file has \['1', 'cam1'\]"):
        read_camchain(path)


def test_bad_camchain_files(tmp_path):
    truth = make_truth()
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, truth.camera, truth.T_cam_imu, 0.0)
    good = yaml.safe_load(path.read_text())

    def check(mutate, message):
        data = yaml.safe_load(yaml.safe_dump(good))
        mutate(data["cam0"])
        path.write_text(yaml.safe_dump(data))
        with pytest.raises(KalibrFormatError, match=message):
            read_camchain(path)

    check(lambda c: c.pop("intrinsics"), r"\[cam0\]: required key 'intrinsics'")
    check(lambda c: c.update(distortion_model="fov"), "'fov' is not supported")
    check(lambda c: c.update(camera_model="kb4"), "'kb4' is not supported")
    check(lambda c: c["T_cam_imu"][0].__setitem__(0, 2.0), "T_cam_imu is not a rigid transform")
    check(lambda c: c.update(T_imu_cam=c["T_cam_imu"]), "several extrinsics")
    check(lambda c: c.update(intrinsics=[-1.0, 1.0, 1.0, 1.0]), "focal lengths must be positive")
    with pytest.raises(KalibrFormatError, match="no section 'cam1'"):
        read_camchain(path, camera="cam1")
    path.write_text(path.read_text()[:30])
    with pytest.raises(KalibrFormatError, match=r"camchain\.yaml"):
        read_camchain(path)
    with pytest.raises(KalibrFormatError, match="does not exist"):
        read_camchain(tmp_path / "missing.yaml")


def test_a_rotation_rounded_when_written_is_re_orthonormalised_with_a_warning(tmp_path):
    truth = make_truth()
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, truth.camera, truth.T_cam_imu, 0.0)
    data = yaml.safe_load(path.read_text())
    data["cam0"]["T_cam_imu"] = [[round(v, 5) for v in row] for row in data["cam0"]["T_cam_imu"]]  # as published
    path.write_text(yaml.safe_dump(data))
    with pytest.warns(FormatWarning, match=r"T_cam_imu is .* from orthonormal \(rounded when written\)"):
        _, T, _ = read_camchain(path)
    R = T[:3, :3]
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(T, truth.T_cam_imu, atol=2e-5)  # the nearest rotation: the rounding's size
    data["cam0"]["T_cam_imu"][0][1] += 1e-3  # beyond rounding: not a rotation
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(KalibrFormatError, match=r"not a rigid transform .*beyond the 0\.0001"):
        read_camchain(path)


def test_an_aprilgrid_code_offset_is_refused_unless_zero(tmp_path):
    path = tmp_path / "target.yaml"
    grid = "target_type: aprilgrid\ntagRows: 6\ntagCols: 6\ntagSize: 0.088\ntagSpacing: 0.3\n"
    path.write_text(grid + "codeOffset: 0\n")
    assert read_target_yaml(path).kind == "aprilgrid"
    path.write_text(grid + "codeOffset: 36\n")
    with pytest.raises(KalibrFormatError, match=r"codeOffset 36 is not supported .*codeOffset 0"):
        read_target_yaml(path)


@pytest.mark.parametrize(("model", "coeffs"), [("ds", [-0.21, 0.59]), ("eucm", [0.61, 1.12])])
def test_wide_angle_camchain_has_kalibrs_layout_and_round_trips(tmp_path, model, coeffs):
    camera = CameraModel(model, 640, 480, 171.5, 170.9, 321.2, 238.7, coeffs)
    path = tmp_path / "camchain.yaml"
    write_camchain_imucam(path, camera, None, None)
    cam0 = yaml.safe_load(path.read_text())["cam0"]
    # Kalibr's ds / eucm: the two model coefficients lead the intrinsics, no distortion on top.
    assert cam0["camera_model"] == model and cam0["intrinsics"] == [*coeffs, 171.5, 170.9, 321.2, 238.7]
    assert cam0["distortion_model"] == "none" and cam0["distortion_coeffs"] == []
    assert read_camchain(path)[0] == camera


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ("camera_model: kb4\nintrinsics: [300, 300, 320, 240]\ndistortion_model: none",
         r"camera_model 'kb4' is not supported; use one of \['pinhole', 'ds', 'eucm', 'omni'\]"),
        ("camera_model: omni\nintrinsics: [0.8, 300, 300, 320, 240]\ndistortion_model: equidistant\n"
         "distortion_coeffs: [0.1, 0, 0, 0]", "camera_model omni with distortion_model 'equidistant' and "
         r"distortion_coeffs \[0\.1, 0, 0, 0\] is not supported; vical reads camera_model omni with distortion_model "
         r"none \(and an empty list\) or radtan"),
        ("camera_model: omni\nintrinsics: [-0.8, 300, 300, 320, 240]\ndistortion_model: none",
         "omni parameter xi must be >= 0, got -0.8"),
        ("camera_model: omni\nintrinsics: [300, 300, 320, 240]\ndistortion_model: none",
         "intrinsics must hold 5 finite numbers"),
        ("camera_model: ds\nintrinsics: [300, 300, 320, 240]\ndistortion_model: none",
         "intrinsics must hold 6 finite numbers"),
        ("camera_model: ds\nintrinsics: [-0.2, 1.4, 300, 300, 320, 240]\ndistortion_model: none",
         r"ds parameter alpha must be in \[0, 1\], got 1.4"),
        ("camera_model: eucm\nintrinsics: [0.6, 0.0, 300, 300, 320, 240]\ndistortion_model: none",
         "eucm parameter beta must be > 0"),
        ("camera_model: ds\nintrinsics: [-0.2, 0.6, 300, 300, 320, 240]\ndistortion_model: radtan\n"
         "distortion_coeffs: [0.1, 0, 0, 0]", "camera_model ds with distortion_model 'radtan'"),
    ],
)  # fmt: skip
def test_bad_wide_angle_camchains_name_the_key(tmp_path, entry, message):
    path = tmp_path / "camchain.yaml"
    path.write_text("cam0:\n  " + entry.replace("\n", "\n  ") + "\n  resolution: [640, 480]\n")
    with pytest.raises(KalibrFormatError, match=message):
        read_camchain(path)


def test_imu_intrinsics_round_trip_in_kalibrs_scale_misalignment_keys(tmp_path):
    intrinsics = ImuIntrinsics.from_vector(np.random.default_rng(1).normal(0.0, 0.01, 24))
    write_imu_yaml(tmp_path / "imu.yaml", ImuNoise(), intrinsics=intrinsics)
    raw = yaml.safe_load((tmp_path / "imu.yaml").read_text())
    assert raw["model"] == "scale-misalignment"
    assert set(raw["accelerometers"]) == {"M"} and set(raw["gyroscopes"]) == {"M", "A", "C_gyro_i"}
    read = read_imu_intrinsics(tmp_path / "imu.yaml")
    for name in ("M_accel", "M_gyro", "C_gyro_i", "A_gyro"):
        np.testing.assert_array_equal(getattr(read, name), getattr(intrinsics, name))
    assert read_imu_yaml(tmp_path / "imu.yaml").gyro_noise_density == ImuNoise().gyro_noise_density
    # Kalibr's result file: the same keys in an imu0 section
    (tmp_path / "result.yaml").write_text(yaml.safe_dump({"imu0": raw}))
    np.testing.assert_array_equal(read_imu_intrinsics(tmp_path / "result.yaml").M_gyro, intrinsics.M_gyro)
    write_imu_yaml(tmp_path / "plain.yaml", ImuNoise())
    assert read_imu_intrinsics(tmp_path / "plain.yaml") is None


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (
            {"model": "scale-misalignment-size-effect", "accelerometers": {"M": [[1.01, 0, 0], [0, 1, 0], [0, 0, 1]]}},
            "accelerometers.M differs from an ideal IMU's",
        ),
        ({"model": "bosch"}, "model 'bosch' is not a Kalibr or OpenVINS IMU model"),
        ({"accelerometers": {"M": [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}}, "M_accel must be lower triangular"),
        ({"gyroscopes": {"M": np.eye(3).tolist(), "A": np.zeros((3, 3)).tolist()}}, "required key 'C_gyro_i'"),
    ],
)
def test_bad_imu_intrinsics_are_refused_naming_the_file(tmp_path, change, match):
    write_imu_yaml(tmp_path / "imu.yaml", ImuNoise(), intrinsics=ImuIntrinsics())
    raw = yaml.safe_load((tmp_path / "imu.yaml").read_text()) | change
    (tmp_path / "imu.yaml").write_text(yaml.safe_dump(raw))
    with pytest.raises(KalibrFormatError, match=match) as refused:
        read_imu_intrinsics(tmp_path / "imu.yaml")
    assert str(tmp_path / "imu.yaml") in str(refused.value)
