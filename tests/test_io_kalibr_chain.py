"""Kalibr and OpenVINS files kept whole: N-camera chains and IMU files round-trip every key, or are refused.

The files are written here in the layouts the formats document: Kalibr's wiki ("YAML formats":
camchain with ``T_cn_cnm1``, ``cam_overlaps``, ``rostopic``; the IMU result of the scale-misalignment
model) and OpenVINS's ``config/*/kalibr_imucam_chain.yaml`` and ``kalibr_imu_chain.yaml``.
"""

from __future__ import annotations

import re
import warnings
from dataclasses import replace
from decimal import Decimal

import numpy as np
import pytest
import yaml

from vical.data import ImuNoise
from vical.geometry.transforms import euler_to_matrix, invert_transform, make_transform
from vical.io.errors import KalibrFormatError
from vical.io.kalibr import read_imu_intrinsics, read_imu_yaml
from vical.io.kalibr_chain import chain_of, read_chain, read_imu_file, write_chain, write_imu_file
from vical.io.sample_checks import FormatWarning
from vical.io.yamlfile import dump_yaml

# A rig of four cameras on a bar, 11 cm apart, each slightly turned; the IMU behind cam0.
T_CAM_IMU = [
    make_transform(euler_to_matrix([0.01 * k, -0.02 + 0.01 * k, 1.57 + 0.005 * k]), [0.07 - 0.11 * k, -0.018, 0.004])
    for k in range(4)
]


def _rows(T: np.ndarray, decimals: int | None) -> str:
    values = T if decimals is None else np.round(T, decimals)
    return "\n".join(f"  - [{', '.join(repr(float(v)) for v in row)}]" for row in values)


def kalibr_camchain(n: int, imu: bool = True, decimals: int | None = None) -> str:
    """A Kalibr camchain(-imucam) of ``n`` cameras as kalibr_calibrate_imu_camera writes it."""
    parts = []
    for k in range(n):
        overlaps = [j for j in (k - 1, k + 1) if 0 <= j < n]
        text = (
            f"cam{k}:\n  camera_model: pinhole\n  intrinsics: [{461.6 + k}, {460.2 + k}, {362.7 - k}, {246.0 + k}]\n"
            f"  distortion_model: radtan\n  distortion_coeffs: [-0.27695, 0.06712, 0.000875, 0.000116]\n"
            f"  resolution: [752, 480]\n  rostopic: /cam{k}/image_raw\n  cam_overlaps: {overlaps}\n"
        )
        if k > 0:
            text += "  T_cn_cnm1:\n" + _rows(T_CAM_IMU[k] @ invert_transform(T_CAM_IMU[k - 1]), decimals) + "\n"
        if imu:
            text += "  T_cam_imu:\n" + _rows(T_CAM_IMU[k], decimals) + f"\n  timeshift_cam_imu: {-8.1e-05 - k * 1e-6}\n"
        parts.append(text)
    return "".join(parts)


OPENVINS_IMUCAM_CHAIN = """\
%YAML:1.0

cam0:
  T_imu_cam: #rotation from camera to IMU R_CtoI, position of camera in IMU p_CinI
{T0}
  cam_overlaps: [1]
  camera_model: pinhole
  distortion_coeffs: [-0.28340811, 0.07395907, 0.00019359, 1.76187114e-05]
  distortion_model: radtan
  intrinsics: [458.654, 457.296, 367.215, 248.375] #fu, fv, cu, cv
  resolution: [752, 480]
  rostopic: /cam0/image_raw
cam1:
  T_imu_cam:
{T1}
  cam_overlaps: [0]
  camera_model: pinhole
  distortion_coeffs: [-0.28368365, 0.07451284, -0.00010473, -3.55590700e-05]
  distortion_model: radtan
  intrinsics: [457.587, 456.134, 379.999, 255.238]
  resolution: [752, 480]
  rostopic: /cam1/image_raw
"""

KALIBR_IMU_RESULT = """\
imu0:
  T_i_b:
  - [1.0, 0.0, 0.0, 0.0]
  - [0.0, 1.0, 0.0, 0.0]
  - [0.0, 0.0, 1.0, 0.0]
  - [0.0, 0.0, 0.0, 1.0]
  accelerometer_noise_density: 0.006
  accelerometer_random_walk: 0.0002
  accelerometers:
    M:
    - [1.00206, 0.0, 0.0]
    - [0.00123, 0.99871, 0.0]
    - [-0.00045, 0.00231, 1.00412]
  gyroscope_noise_density: 0.0004
  gyroscope_random_walk: 4.0e-06
  gyroscopes:
    A:
    - [-0.00075, 0.00162, 0.00020]
    - [-0.00346, -0.00024, -0.00694]
    - [-0.00217, 0.00254, 0.00037]
    C_gyro_i:
    - [1.0, 0.0, 0.0]
    - [0.0, 1.0, 0.0]
    - [0.0, 0.0, 1.0]
    M:
    - [0.99845, 0.0, 0.0]
    - [0.00211, 1.00123, 0.0]
    - [0.00056, -0.00102, 0.99966]
  model: scale-misalignment
  rostopic: /imu0
  time_offset: 0.0
  update_rate: 200.0
"""

OPENVINS_IMU_CHAIN = """\
%YAML:1.0

imu0:
  T_i_b:
    - [1.0, 0.0, 0.0, 0.0]
    - [0.0, 1.0, 0.0, 0.0]
    - [0.0, 0.0, 1.0, 0.0]
    - [0.0, 0.0, 0.0, 1.0]
  accelerometer_noise_density: 2.0000e-3  # [ m / s^2 / sqrt(Hz) ]
  accelerometer_random_walk: 3.0000e-3
  gyroscope_noise_density: 1.6968e-04
  gyroscope_random_walk: 1.9393e-05
  rostopic: /imu0
  time_offset: 0.0
  update_rate: 200.0
  model: "kalibr"
  Tw:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  R_IMUtoGYRO:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  Ta:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  R_IMUtoACC:
    - [ 1.0, 0.0, 0.0 ]
    - [ 0.0, 1.0, 0.0 ]
    - [ 0.0, 0.0, 1.0 ]
  Tg:
    - [ 0.0, 0.0, 0.0 ]
    - [ 0.0, 0.0, 0.0 ]
    - [ 0.0, 0.0, 0.0 ]
"""


def load(path) -> dict:
    text = path.read_text()
    return yaml.safe_load(text.split("\n", 1)[1] if text.startswith("%YAML:1.0") else text)


def assert_same(a, b, where="") -> None:
    """Equal YAML trees (same keys in the same order); numbers equal within 1e-12."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), f"{where}: keys {list(a)} != {list(b)}"
        for k in a:
            assert_same(a[k], b[k], f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{where}[{i}]")
    elif isinstance(a, float | int) and not isinstance(a, bool):
        assert type(a) is type(b) and abs(a - b) <= 1e-12, f"{where}: {a!r} != {b!r}"
    else:
        assert a == b, f"{where}: {a!r} != {b!r}"


@pytest.mark.parametrize("n", [2, 3, 4])
def test_kalibr_camchain_imucam_of_n_cameras_round_trips_every_key(tmp_path, n):
    source = tmp_path / "camchain-imucam.yaml"
    source.write_text(kalibr_camchain(n) + "imu_note: kept as written\n")
    chain = read_chain(source)
    assert chain.names == [f"cam{k}" for k in range(n)]
    for k, camera in enumerate(chain.cameras):
        np.testing.assert_array_equal(camera.T_cam_imu, T_CAM_IMU[k])
        assert camera.rostopic == f"/cam{k}/image_raw" and camera.camera.fx == 461.6 + k
        assert camera.cam_overlaps == tuple(j for j in (k - 1, k + 1) if 0 <= j < n)
        if k:  # T_c1_c0 takes cam0 points to cam1: the baseline of 11 cm along the bar
            np.testing.assert_allclose(chain.relative_pose(camera.name), camera.T_cn_cnm1, atol=1e-15)
            assert np.linalg.norm(camera.T_cn_cnm1[:3, 3]) == pytest.approx(0.11, abs=1e-3)
    assert chain.top == {"imu_note": "kept as written"}
    out = tmp_path / "out.yaml"
    write_chain(out, chain)
    assert_same(load(source), load(out))
    assert read_chain(out).cameras[n - 1].T_cam_imu.tolist() == T_CAM_IMU[n - 1].tolist()


def test_kalibr_camchain_of_cameras_alone_keeps_its_relative_poses(tmp_path):
    source = tmp_path / "camchain.yaml"  # kalibr_calibrate_cameras: no IMU, the chain's T_cn_cnm1 only
    source.write_text(kalibr_camchain(4, imu=False))
    chain = read_chain(source)
    assert all(c.T_cam_imu is None and c.timeshift_cam_imu is None for c in chain.cameras)
    np.testing.assert_array_equal(chain.relative_pose("cam3"), chain["cam3"].T_cn_cnm1)
    out = tmp_path / "out.yaml"
    write_chain(out, chain)
    assert load(out) == load(source)  # nothing recomputed: bit-exact


def test_published_camchain_rounded_to_5_decimals_is_read_with_warnings(tmp_path):
    source = tmp_path / "camchain-imucam.yaml"
    source.write_text(kalibr_camchain(2, decimals=5))
    with pytest.warns(FormatWarning, match=r"\[cam1\]: T_cn_cnm1 is .* from orthonormal"):
        chain = read_chain(source)
    np.testing.assert_allclose(chain["cam1"].T_cam_imu, T_CAM_IMU[1], atol=2e-5)


def test_openvins_imucam_chain_keeps_its_header_and_t_imu_cam(tmp_path):
    source = tmp_path / "kalibr_imucam_chain.yaml"
    rows = [_rows(invert_transform(T), None).replace("  - ", "    - ") for T in T_CAM_IMU[:2]]
    source.write_text(OPENVINS_IMUCAM_CHAIN.format(T0=rows[0], T1=rows[1]))
    chain = read_chain(source)
    np.testing.assert_allclose(chain["cam1"].T_cam_imu, T_CAM_IMU[1], atol=1e-15)
    assert chain.opencv_header
    out = tmp_path / "out.yaml"
    write_chain(out, chain)
    assert out.read_text().startswith("%YAML:1.0\n")  # cv::FileStorage needs it
    written = load(out)
    assert "T_cam_imu" not in written["cam0"] and "T_cn_cnm1" in written["cam1"]
    # Everything OpenVINS wrote comes back in its order; vical adds cam1's T_cn_cnm1 at the end.
    original = load(source)
    del written["cam1"]["T_cn_cnm1"]
    assert_same(original, written)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda t: t.replace("cam1:", "cam2:"), r"has cam0, cam2 but no cam1; Kalibr numbers"),
        (lambda t: t.replace("cam_overlaps: [0]", "cam_overlaps: [3]"), r"\[cam1\]: cam_overlaps names camera 3"),
        (lambda t: t.replace("cam_overlaps: [1]", "cam_overlaps: [0]"), r"\[cam0\]: cam_overlaps names camera 0"),
    ],
)
def test_chains_that_cannot_be_kept_are_refused_naming_the_key(tmp_path, edit, message):
    path = tmp_path / "camchain.yaml"
    path.write_text(edit(kalibr_camchain(2)))
    with pytest.raises(KalibrFormatError, match=message) as info:
        read_chain(path)
    assert str(path) in str(info.value)


def test_a_relative_pose_contradicting_the_imu_extrinsics_is_refused(tmp_path):
    path = tmp_path / "camchain-imucam.yaml"
    data = yaml.safe_load(kalibr_camchain(2))
    turned = make_transform(euler_to_matrix([0.0, 0.0, np.radians(0.5)]), [0.0, 0.0, 0.0])
    data["cam1"]["T_cn_cnm1"] = (turned @ np.array(data["cam1"]["T_cn_cnm1"])).tolist()
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(
        KalibrFormatError, match=r"\[cam1\]: T_cn_cnm1 disagrees with T_cam_imu of cam1 and cam0 by 0\.500 deg"
    ):
        read_chain(path)
    data["cam0"]["T_cn_cnm1"] = data["cam1"].pop("T_cn_cnm1")
    path.write_text(yaml.safe_dump(data))
    with pytest.raises(KalibrFormatError, match=r"\[cam0\]: T_cn_cnm1 relates a camera to the one before it"):
        read_chain(path)


@pytest.mark.parametrize("text", [KALIBR_IMU_RESULT, OPENVINS_IMU_CHAIN])
def test_imu_files_round_trip_every_key(tmp_path, text):
    source = tmp_path / "imu.yaml"
    source.write_text(text)
    imu = read_imu_file(source)
    assert imu.in_section and imu.rostopic == "/imu0" and imu.noise.rate_hz == 200.0
    out = tmp_path / "out.yaml"
    write_imu_file(out, imu)
    assert load(out) == load(source)
    assert out.read_text().startswith("%YAML:1.0") == text.startswith("%YAML:1.0")
    louder = ImuNoise(0.01, 0.001, 0.001, 1e-5, 200.0)
    write_imu_file(out, type(imu)(louder, imu.rostopic, imu.section, imu.top, True, imu.opencv_header))
    assert read_imu_file(out).noise == louder
    assert {k: v for k, v in load(out)["imu0"].items() if "noise" not in k and "walk" not in k} == {
        k: v for k, v in load(source)["imu0"].items() if "noise" not in k and "walk" not in k
    }


def test_plain_kalibr_imu_yaml_round_trips(tmp_path):
    source = tmp_path / "imu.yaml"  # Kalibr's input: noise, rostopic, update_rate
    source.write_text(
        "#Accelerometers\naccelerometer_noise_density: 1.86e-03\naccelerometer_random_walk: 4.33e-04\n"
        "gyroscope_noise_density: 1.87e-04\ngyroscope_random_walk: 2.66e-05\nrostopic: /imu0\nupdate_rate: 200.0\n"
    )
    out = tmp_path / "out.yaml"
    write_imu_file(out, read_imu_file(source))
    assert_same(load(source), load(out))
    assert read_imu_yaml(out) == ImuNoise(1.86e-03, 4.33e-04, 1.87e-04, 2.66e-05, 200.0)


@pytest.mark.parametrize("model", ["kalibr", "rpng"])
def test_ideal_imu_intrinsics_are_accepted_for_calibration(tmp_path, model):
    path = tmp_path / "kalibr_imu_chain.yaml"
    path.write_text(OPENVINS_IMU_CHAIN.replace('model: "kalibr"', f'model: "{model}"'))
    assert read_imu_yaml(path) == ImuNoise(2e-3, 3e-3, 1.6968e-04, 1.9393e-05, 200.0)
    assert read_imu_intrinsics(path) is None  # nothing to correct the samples with (--imu-yaml reads both)


def test_kalibrs_scale_misalignment_intrinsics_are_read_for_calibration(tmp_path):
    path = tmp_path / "imu.yaml"
    path.write_text(KALIBR_IMU_RESULT)
    assert read_imu_yaml(path).gyro_noise_density == 0.0004
    intrinsics = read_imu_intrinsics(path)  # applied by the calibration (--imu-yaml)
    assert intrinsics.M_accel[2, 1] == 0.00231 and intrinsics.A_gyro[1, 2] == -0.00694


@pytest.mark.parametrize(
    ("text", "edit", "key"),
    [
        (
            KALIBR_IMU_RESULT,
            lambda t: t.replace("model: scale-misalignment", "model: scale-misalignment-size-effect"),
            "accelerometers.M",
        ),
        (OPENVINS_IMU_CHAIN, lambda t: t.replace("Ta:\n    - [ 1.0", "Ta:\n    - [ 1.01"), "Ta"),
        (OPENVINS_IMU_CHAIN, lambda t: t.replace("Tg:\n    - [ 0.0", "Tg:\n    - [ 0.002"), "Tg"),
        (OPENVINS_IMU_CHAIN, lambda t: t.replace("time_offset: 0.0", "time_offset: 0.004"), "time_offset"),
        (OPENVINS_IMU_CHAIN, lambda t: t.replace("    - [1.0, 0.0, 0.0, 0.0]", "    - [1.0, 0.0, 0.0, 0.05]"), "T_i_b"),
    ],
)
def test_imu_intrinsics_vical_would_not_apply_are_refused_for_calibration(tmp_path, text, edit, key):
    path = tmp_path / "imu.yaml"
    path.write_text(edit(text))
    with pytest.raises(KalibrFormatError, match=rf"\[imu0\]: {key} differs from .*correct the samples with {key}"):
        read_imu_yaml(path)
    read_imu_file(path)  # kept whole when only carried through


def test_an_unknown_imu_model_is_refused(tmp_path):
    path = tmp_path / "imu.yaml"
    path.write_text(OPENVINS_IMU_CHAIN.replace('model: "kalibr"', 'model: "bosch"'))
    with pytest.raises(KalibrFormatError, match=r"model 'bosch' is not a Kalibr or OpenVINS IMU model"):
        read_imu_yaml(path)


# ------------------------------------------------------------------------------- digits
def _published_rows(T: np.ndarray, indent: str) -> str:
    """Rows as published camchains print them: 9 decimals, fixed point."""
    return "\n".join(f"{indent}- [{', '.join(f'{v:.9f}' for v in row)}]" for row in T)


def published_camchain(n: int, openvins: bool) -> str:
    """A camchain-imucam whose matrices carry 9 decimals: Kalibr's ``T_cam_imu`` and ``T_cn_cnm1`` rows flush with
    the key, or OpenVINS's ``%YAML:1.0`` file with ``T_imu_cam`` rows indented under it."""
    text = "%YAML:1.0\n" if openvins else ""
    indent = "    " if openvins else "  "
    for k in range(n):
        text += f"cam{k}:\n  camera_model: pinhole\n  intrinsics: [{461.6 + k}, 460.2, 362.7, 246.0]\n"
        text += "  distortion_model: radtan\n  distortion_coeffs: [-0.27695, 0.06712, 0.000875, 0.000116]\n"
        text += f"  resolution: [752, 480]\n  rostopic: /cam{k}/image_raw\n"
        if k > 0:
            text += "  T_cn_cnm1:\n" + _published_rows(T_CAM_IMU[k] @ invert_transform(T_CAM_IMU[k - 1]), indent) + "\n"
        if openvins:
            text += "  T_imu_cam:\n" + _published_rows(invert_transform(T_CAM_IMU[k]), indent) + "\n"
        else:
            text += "  T_cam_imu:\n" + _published_rows(T_CAM_IMU[k], indent) + f"\n  timeshift_cam_imu: {-8.1e-05}\n"
    return text


MATRIX = re.compile(r"^  (T_\w+):\n((?:\s+- \[.*\]\n){4})", re.MULTILINE)


def matrix_digits(text: str) -> dict[tuple[str, str], list[list[Decimal]]]:
    """Each camera's matrices as the decimal numbers their text spells ((camera, key) -> rows)."""
    found = {}
    for section in re.split(r"^(?=cam\d+:)", text, flags=re.MULTILINE):
        camera = section.split(":", 1)[0]
        for key, rows in MATRIX.findall(section):
            numbers = re.findall(r"\[(.*)\]", rows)
            found[camera, key] = [[Decimal(v) for v in row.split(", ")] for row in numbers]
    return found


@pytest.mark.parametrize("openvins", [False, True], ids=["kalibr-T_cam_imu", "openvins-T_imu_cam"])
def test_matrices_passed_through_keep_their_key_and_digits_on_every_rewrite(tmp_path, openvins):
    path = tmp_path / "camchain-imucam.yaml"
    path.write_text(published_camchain(3, openvins))
    original = matrix_digits(path.read_text())
    extrinsic = "T_imu_cam" if openvins else "T_cam_imu"
    assert sorted(original) == sorted(
        [(f"cam{k}", extrinsic) for k in range(3)] + [("cam1", "T_cn_cnm1"), ("cam2", "T_cn_cnm1")]
    )
    for _ in range(5):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FormatWarning)  # the 9-decimal rotations are rounded: read as such
            chain = read_chain(path)
        write_chain(path, chain)
        assert matrix_digits(path.read_text()) == original


def test_computed_matrices_are_written_with_round_trip_digits(tmp_path):
    """Re-estimated extrinsics (numpy float64) come out in Python's shortest round-tripping digits: the written
    numbers read back bit-exact, in the file's key (``T_imu_cam``), and ``T_cn_cnm1`` follows from them."""
    given = tmp_path / "kalibr_imucam_chain.yaml"
    given.write_text(published_camchain(2, openvins=True))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FormatWarning)
        base = read_chain(given)
    turn = make_transform(euler_to_matrix([1e-3, -2e-3, 3e-3]), [1e-4, 2e-4, -3e-4])
    moved = chain_of([replace(c, T_cam_imu=c.T_cam_imu @ turn, section={}) for c in base.cameras], base)
    out = tmp_path / "out.yaml"
    write_chain(out, moved)
    written = load(out)
    for camera in moved.cameras:
        assert written[camera.name]["T_imu_cam"] == invert_transform(camera.T_cam_imu).tolist()
        assert "T_cam_imu" not in written[camera.name]
    assert (
        written["cam1"]["T_cn_cnm1"]
        == (moved.cameras[1].T_cam_imu @ invert_transform(moved.cameras[0].T_cam_imu)).tolist()
    )
    assert "!!" not in out.read_text() and "'" not in out.read_text()  # numbers, not tagged objects or strings


def test_numpy_numbers_are_written_as_python_numbers(tmp_path):
    path = tmp_path / "values.yaml"
    dump_yaml(path, {"sum": np.float64(0.1) + np.float64(0.2), "count": np.int64(3), "row": np.array([1 / 3, 2.0])})
    assert path.read_text() == "sum: 0.30000000000000004\ncount: 3\nrow: [0.3333333333333333, 2.0]\n"
