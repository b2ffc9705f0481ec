"""Every ``%YAML:1.0`` file vical writes opens with OpenCV's ``cv2.FileStorage`` (OpenVINS reads its
``kalibr_imucam_chain.yaml`` and ``kalibr_imu_chain.yaml`` with ``cv::FileStorage``).

vical writes that header when the file it carries through had it: camchains of cameras alone and
with the IMU (Kalibr's keys or OpenVINS's ``T_imu_cam``), a rig's chain of newly calibrated cameras
(pinhole and wide-angle), and IMU files with and without IMU intrinsics. Each is written with
vical's writer, opened with ``cv2.FileStorage``, and its numbers compared with what was written;
vical and PyYAML read it back too.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from test_io_kalibr_chain import (
    KALIBR_IMU_RESULT,
    OPENVINS_IMU_CHAIN,
    OPENVINS_IMUCAM_CHAIN,
    T_CAM_IMU,
    _rows,
    kalibr_camchain,
)

from vical.data import ImuIntrinsics, ImuNoise
from vical.geometry import CameraModel
from vical.geometry.transforms import invert_transform
from vical.io.kalibr_chain import (
    CameraChain,
    ChainCamera,
    chain_of,
    imu_file_with,
    read_chain,
    read_imu_file,
    write_chain,
    write_imu_file,
)

HEADER = "%YAML:1.0\n"


def opencv_storage(path: Path) -> cv2.FileStorage:
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)  # raises on text OpenCV refuses
    assert storage.isOpened()
    return storage


def opencv_matrix(node: cv2.FileNode) -> np.ndarray:
    """A matrix node as ``cv::FileStorage`` reads it: rows of numbers (Kalibr's layout)."""
    assert node.isSeq(), "not a sequence of rows"
    return np.array([[node.at(i).at(j).real() for j in range(node.at(i).size())] for i in range(node.size())])


def opencv_numbers(node: cv2.FileNode) -> list[float]:
    return [node.at(i).real() for i in range(node.size())]


def pyyaml(path: Path) -> dict:
    text = path.read_text()
    assert text.startswith(HEADER)
    return yaml.safe_load(text[len(HEADER) :])


def openvins_imucam_chain() -> str:
    rows = [_rows(invert_transform(T), None).replace("  - ", "    - ") for T in T_CAM_IMU[:2]]
    return OPENVINS_IMUCAM_CHAIN.format(T0=rows[0], T1=rows[1])


def assert_chain_opens_with_opencv(path: Path, chain: CameraChain) -> None:
    """The written chain's every camera, read by cv::FileStorage, holds the chain's numbers; vical reads it back."""
    storage = opencv_storage(path)
    for camera in chain.cameras:
        node = storage.getNode(camera.name)
        assert opencv_numbers(node.getNode("resolution")) == [camera.camera.width, camera.camera.height]
        intrinsics = opencv_numbers(node.getNode("intrinsics"))
        assert intrinsics[-4:] == camera.camera.intrinsics.tolist()
        if camera.T_cam_imu is not None:
            if node.getNode("T_imu_cam").empty():
                np.testing.assert_array_equal(opencv_matrix(node.getNode("T_cam_imu")), camera.T_cam_imu)
            else:
                np.testing.assert_allclose(
                    opencv_matrix(node.getNode("T_imu_cam")), invert_transform(camera.T_cam_imu), atol=1e-15
                )
        if camera.timeshift_cam_imu is not None:
            assert node.getNode("timeshift_cam_imu").real() == camera.timeshift_cam_imu
        if camera.name != "cam0" and chain.relative_pose(camera.name) is not None:
            np.testing.assert_allclose(
                opencv_matrix(node.getNode("T_cn_cnm1")), chain.relative_pose(camera.name), atol=1e-15
            )
    again = read_chain(path)
    assert again.opencv_header and again.names == chain.names
    for camera, read in zip(chain.cameras, again.cameras, strict=True):
        assert read.camera == camera.camera
        if camera.T_cam_imu is not None:
            np.testing.assert_allclose(read.T_cam_imu, camera.T_cam_imu, atol=1e-15)
    assert list(pyyaml(path)) == chain.names + list(chain.top)


@pytest.mark.parametrize(
    "source",
    [
        pytest.param(HEADER + kalibr_camchain(3, imu=False), id="camchain"),
        pytest.param(HEADER + kalibr_camchain(3), id="camchain-imucam"),
        pytest.param(openvins_imucam_chain(), id="openvins-kalibr_imucam_chain"),
    ],
)
def test_chains_with_opencvs_header_open_with_file_storage(tmp_path, source):
    given = tmp_path / "given.yaml"
    given.write_text(source)
    chain = read_chain(given)
    out = tmp_path / "written.yaml"
    write_chain(out, chain)
    assert out.read_text().startswith(HEADER)
    assert_chain_opens_with_opencv(out, chain)


def test_a_rigs_chain_of_calibrated_cameras_opens_with_file_storage(tmp_path):
    """New values (numpy floats, a wide-angle camera with no coefficients) in a given file's layout and header."""
    given = tmp_path / "kalibr_imucam_chain.yaml"
    given.write_text(openvins_imucam_chain())
    base = read_chain(given)
    pinhole = CameraModel("radtan", 752, 480, 459.1, 458.2, 366.3, 249.4, np.array([-0.28, 0.07, 2e-4, 1e-5]))
    ds = CameraModel("ds", 752, 480, 350.5, 349.5, 376.0, 240.0, np.array([-0.2, 0.57]))
    nudge = np.eye(4)
    nudge[:3, 3] = [1e-4, -2e-4, 3e-4]
    cameras = [
        ChainCamera("cam0", pinhole, T_CAM_IMU[0] @ nudge, np.float64(-8.3e-5), cam_overlaps=(1,)),
        ChainCamera("cam1", ds, T_CAM_IMU[1] @ nudge, np.float64(-8.4e-5), cam_overlaps=(0,)),
    ]
    chain = chain_of(cameras, base)
    out = tmp_path / "written.yaml"
    write_chain(out, chain)
    assert_chain_opens_with_opencv(out, chain)
    storage = opencv_storage(out)  # held: its nodes point into it
    node = storage.getNode("cam1")
    assert node.getNode("camera_model").string() == "ds" and node.getNode("distortion_coeffs").size() == 0
    assert opencv_numbers(node.getNode("intrinsics"))[:2] == [-0.2, 0.57]


INTRINSICS = ImuIntrinsics(
    M_accel=np.array([[1.002, 0.0, 0.0], [0.0012, 0.9987, 0.0], [-0.0004, 0.0023, 1.0041]]),
    M_gyro=np.array([[0.9984, 0.0, 0.0], [0.0021, 1.0012, 0.0], [0.0005, -0.001, 0.9997]]),
    C_gyro_i=np.eye(3),
    A_gyro=np.full((3, 3), 1e-4),
)


FLAT_KALIBR_IMU = (
    "accelerometer_noise_density: 1.86e-03\naccelerometer_random_walk: 4.33e-04\ngyroscope_noise_density: 1.87e-04\n"
    "gyroscope_random_walk: 2.66e-05\nrostopic: /imu0\nupdate_rate: 200.0\n"
)


@pytest.mark.parametrize("intrinsics", [None, INTRINSICS], ids=["noise", "noise-and-intrinsics"])
@pytest.mark.parametrize(
    "source",
    [OPENVINS_IMU_CHAIN, HEADER + KALIBR_IMU_RESULT, HEADER + FLAT_KALIBR_IMU],
    ids=["openvins-imu0", "kalibr-result-imu0", "kalibr-flat-imu.yaml"],
)
def test_imu_files_with_opencvs_header_open_with_file_storage(tmp_path, source, intrinsics):
    given = tmp_path / "kalibr_imu_chain.yaml"
    given.write_text(source)
    noise = ImuNoise(np.float64(0.0021), 3.1e-3, 1.7e-4, 1.9e-5, 200.0)
    out = tmp_path / "imu.yaml"
    write_imu_file(out, imu_file_with(read_imu_file(given), noise, intrinsics))
    storage = opencv_storage(out)  # held: its nodes point into it
    imu = storage.getNode("imu0") if "imu0:" in source else storage.root()
    assert imu.getNode("accelerometer_noise_density").real() == 0.0021
    assert imu.getNode("gyroscope_random_walk").real() == 1.9e-5
    assert imu.getNode("rostopic").string() == "/imu0"
    if "T_i_b" in source:
        np.testing.assert_array_equal(opencv_matrix(imu.getNode("T_i_b")), np.eye(4))
    if intrinsics is not None:
        assert imu.getNode("model").string() == "scale-misalignment"
        np.testing.assert_array_equal(opencv_matrix(imu.getNode("accelerometers").getNode("M")), INTRINSICS.M_accel)
        np.testing.assert_array_equal(opencv_matrix(imu.getNode("gyroscopes").getNode("A")), INTRINSICS.A_gyro)
    again = read_imu_file(out)
    assert again.opencv_header and again.noise == noise
    written = pyyaml(out)
    assert (written["imu0"] if "imu0:" in source else written)["update_rate"] == 200.0
