"""A calibration written for VINS-Fusion and basalt, read back as they read it and checked against their own models.

VINS-Fusion's files are read with OpenCV's ``FileStorage`` (the parser VINS-Fusion and camodocal read them with, on
PyPI as ``opencv-python``), key by key as its ``readParameters`` and camodocal's ``readFromYamlFile`` do; basalt's
``calibration.json`` is checked against the schema of basalt's published calibration files (``data/*_calib.json``
in its repository: the keys, their types and each camera type's intrinsics). The lens parameters are checked by
projecting points with camodocal's and basalt's camera equations, written here from their papers and sources
independently of vical's, against vical's own projection: a parameter put in the wrong place moves the pixels.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from vical.data import ImuNoise
from vical.geometry import CameraModel, invert_transform
from vical.geometry.transforms import make_transform, so3_exp
from vical.io.errors import FormatError
from vical.io.kalibr_chain import CameraChain, ChainCamera
from vical.io.vio_exports import refusal, write_vio_files

NOISE = ImuNoise(0.0021, 0.00031, 0.00017, 0.000021, 200.0)
CAMERAS = {
    "radtan": CameraModel("radtan", 752, 480, 458.7, 457.3, 367.2, 248.4, np.array([-0.283, 0.074, 0.0002, 1.8e-5])),
    "equidistant": CameraModel(
        "equidistant", 752, 480, 350.1, 349.8, 371.5, 245.2, np.array([0.012, -0.004, 0.0021, -0.0007])
    ),
    "omni": CameraModel("omni", 752, 480, 780.2, 779.5, 370.1, 240.7, np.array([1.38])),
    "omni-radtan": CameraModel("omni-radtan", 752, 480, 760.4, 761.0, 372.9, 239.8,
                               np.array([1.31, -0.09, 0.11, 0.0004, -0.0002])),
    "ds": CameraModel("ds", 752, 480, 349.7, 348.7, 365.9, 249.3, np.array([-0.24, 0.567])),
    "eucm": CameraModel("eucm", 752, 480, 460.8, 459.9, 365.8, 249.3, np.array([0.597, 1.11])),
}  # fmt: skip
BASALT_TYPES = {"equidistant": "kb4", "ds": "ds", "eucm": "eucm"}


def chain_of(model: str, n: int = 2) -> CameraChain:
    rng = np.random.default_rng(40000)
    cameras = []
    for k in range(n):
        T = make_transform(so3_exp(rng.normal(0, 0.3, 3)) @ np.diag([1.0, -1.0, -1.0]), rng.normal(0, 0.05, 3))
        cameras.append(ChainCamera(f"cam{k}", CAMERAS[model], T, 0.00734, rostopic=f"/cam{k}/image_raw"))
    return CameraChain(tuple(cameras))


def points_in_view(camera: CameraModel) -> np.ndarray:
    """Camera-frame points whose pixels lie in the image, out to ~60 deg off the axis."""
    rng = np.random.default_rng(1)
    angle, azimuth = rng.uniform(0, np.radians(60), 200), rng.uniform(0, 2 * np.pi, 200)
    p = np.c_[np.sin(angle) * np.cos(azimuth), np.sin(angle) * np.sin(azimuth), np.cos(angle)] * rng.uniform(
        0.3, 3, (200, 1)
    )
    uv, ok = camera.project(p)
    keep = ok & camera.in_image(uv)
    assert keep.sum() > 50
    return p[keep]


# ------------------------------------------------------------------ VINS-Fusion, as OpenCV and camodocal read it
def read_storage(path) -> cv2.FileStorage:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert fs.isOpened(), path
    return fs


def camodocal_project(fs: cv2.FileStorage, p: np.ndarray) -> np.ndarray:
    """camodocal's projection of its PINHOLE, KANNALA_BRANDT and MEI cameras from the file's parameters."""
    kind = fs.getNode("model_type").string()
    proj, dist = fs.getNode("projection_parameters"), fs.getNode("distortion_parameters")

    def radtan(x, y):
        k1, k2, p1, p2 = (dist.getNode(n).real() for n in ("k1", "k2", "p1", "p2"))
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        return x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y

    if kind == "PINHOLE":
        x, y = radtan(p[:, 0] / p[:, 2], p[:, 1] / p[:, 2])
        f = [proj.getNode(n).real() for n in ("fx", "fy", "cx", "cy")]
    elif kind == "KANNALA_BRANDT":
        k2, k3, k4, k5 = (proj.getNode(n).real() for n in ("k2", "k3", "k4", "k5"))
        r = np.hypot(p[:, 0], p[:, 1])
        theta = np.arctan2(r, p[:, 2])
        theta_d = theta + k2 * theta**3 + k3 * theta**5 + k4 * theta**7 + k5 * theta**9
        x, y = theta_d * p[:, 0] / r, theta_d * p[:, 1] / r
        f = [proj.getNode(n).real() for n in ("mu", "mv", "u0", "v0")]
    else:
        assert kind == "MEI"
        xi = fs.getNode("mirror_parameters").getNode("xi").real()
        z = p[:, 2] + xi * np.linalg.norm(p, axis=1)
        x, y = radtan(p[:, 0] / z, p[:, 1] / z)
        f = [proj.getNode(n).real() for n in ("gamma1", "gamma2", "u0", "v0")]
    return np.c_[f[0] * x + f[2], f[1] * y + f[3]]


# The keys VINS-Fusion's estimator reads from its config, as its published configs (config/euroc/*.yaml) hold them.
VINS_NUMBERS = ["imu", "num_of_cam", "image_width", "image_height", "estimate_extrinsic", "multiple_thread", "max_cnt",
                "min_dist", "freq", "F_threshold", "show_track", "flow_back", "max_solver_time", "max_num_iterations",
                "keyframe_parallax", "acc_n", "gyr_n", "acc_w", "gyr_w", "g_norm", "estimate_td", "td",
                "load_previous_pose_graph", "save_image"]  # fmt: skip
VINS_STRINGS = ["imu_topic", "image0_topic", "output_path", "cam0_calib", "pose_graph_save_path"]


@pytest.mark.parametrize("model", ["radtan", "equidistant", "omni", "omni-radtan"])
@pytest.mark.parametrize("n", [1, 2])
def test_vins_fusion_reads_the_calibration_with_its_frames_time_noise_and_lens(model, n, tmp_path):
    chain = chain_of(model, n)
    written = write_vio_files(tmp_path, "vins-fusion", chain, NOISE, "/imu0", 9.8063)
    assert sorted(p.name for p in written) == sorted(["config.yaml", *(f"cam{k}.yaml" for k in range(n))])
    fs = read_storage(tmp_path / "config.yaml")
    assert all(fs.getNode(key).isReal() or fs.getNode(key).isInt() for key in VINS_NUMBERS)
    assert all(fs.getNode(key).isString() for key in VINS_STRINGS)
    assert fs.getNode("num_of_cam").real() == n and fs.getNode("imu_topic").string() == "/imu0"
    assert fs.getNode("td").real() == 0.00734 and fs.getNode("g_norm").real() == 9.8063
    assert [fs.getNode(k).real() for k in ("acc_n", "gyr_n", "acc_w", "gyr_w")] == [0.0021, 0.00017, 0.00031, 0.000021]
    for k, cam in enumerate(chain.cameras):
        body_T_cam = fs.getNode(f"body_T_cam{k}").mat()
        np.testing.assert_allclose(body_T_cam, invert_transform(cam.T_cam_imu), rtol=0, atol=1e-15)
        assert fs.getNode(f"image{k}_topic").string() == f"/cam{k}/image_raw"
        camera = read_storage(tmp_path / fs.getNode(f"cam{k}_calib").string())
        assert (camera.getNode("image_width").real(), camera.getNode("image_height").real()) == (752, 480)
        p = points_in_view(cam.camera)
        np.testing.assert_allclose(camodocal_project(camera, p), cam.camera.project(p)[0], rtol=0, atol=1e-6)


# ------------------------------------------------------------------ basalt, as its calibration files hold it
BASALT_INTRINSICS = {
    "pinhole": ["fx", "fy", "cx", "cy"],
    "kb4": ["fx", "fy", "cx", "cy", "k1", "k2", "k3", "k4"],
    "ds": ["fx", "fy", "cx", "cy", "xi", "alpha"],
    "eucm": ["fx", "fy", "cx", "cy", "alpha", "beta"],
}
POSE_KEYS = ["px", "py", "pz", "qx", "qy", "qz", "qw"]


def check_basalt_schema(calibration: dict, n: int) -> None:
    assert list(calibration) == ["value0"]
    c = calibration["value0"]
    assert len(c["T_imu_cam"]) == len(c["intrinsics"]) == len(c["resolution"]) == n
    assert all(sorted(pose) == sorted(POSE_KEYS) for pose in c["T_imu_cam"])
    for camera in c["intrinsics"]:
        assert sorted(camera) == ["camera_type", "intrinsics"]
        assert sorted(camera["intrinsics"]) == sorted(BASALT_INTRINSICS[camera["camera_type"]])
    assert all(len(r) == 2 and all(isinstance(v, int) for v in r) for r in c["resolution"])
    assert len(c["calib_accel_bias"]) == 9 and len(c["calib_gyro_bias"]) == 12
    assert isinstance(c["imu_update_rate"], float) and isinstance(c["cam_time_offset_ns"], int)
    assert all(len(c[k]) == 3 for k in ("accel_noise_std", "gyro_noise_std", "accel_bias_std", "gyro_bias_std"))
    assert isinstance(c["vignette"], list)


def pose_matrix(pose: dict) -> np.ndarray:
    """Sophus' SE3 from basalt's ``px py pz qx qy qz qw`` (Hamilton quaternion)."""
    x, y, z, w = (pose[k] for k in ("qx", "qy", "qz", "qw"))
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])  # fmt: skip
    return make_transform(R, [pose["px"], pose["py"], pose["pz"]])


def basalt_project(camera: dict, p: np.ndarray) -> np.ndarray:
    """basalt's projection of its pinhole, kb4, ds (Usenko et al. 2018) and eucm (Khomutenko et al. 2016) cameras."""
    i = camera["intrinsics"]
    x, y, z = p.T
    kind = camera["camera_type"]
    if kind == "pinhole":
        mx, my = x / z, y / z
    elif kind == "kb4":
        r = np.hypot(x, y)
        theta = np.arctan2(r, z)
        d = theta * (1 + i["k1"] * theta**2 + i["k2"] * theta**4 + i["k3"] * theta**6 + i["k4"] * theta**8)
        mx, my = d * x / r, d * y / r
    elif kind == "ds":
        d1 = np.sqrt(x * x + y * y + z * z)
        k = i["xi"] * d1 + z
        d2 = np.sqrt(x * x + y * y + k * k)
        den = i["alpha"] * d2 + (1 - i["alpha"]) * k
        mx, my = x / den, y / den
    else:
        d = np.sqrt(i["beta"] * (x * x + y * y) + z * z)
        den = i["alpha"] * d + (1 - i["alpha"]) * z
        mx, my = x / den, y / den
    return np.c_[i["fx"] * mx + i["cx"], i["fy"] * my + i["cy"]]


@pytest.mark.parametrize("model", ["equidistant", "ds", "eucm", "pinhole"])
def test_basalt_reads_the_calibration_with_its_frames_time_noise_and_lens(model, tmp_path):
    if model == "pinhole":  # a known camera without distortion
        chain = chain_of("radtan")
        lens_free = CameraModel("radtan", 752, 480, 458.7, 457.3, 367.2, 248.4)
        chain = CameraChain(
            tuple(ChainCamera(c.name, lens_free, c.T_cam_imu, c.timeshift_cam_imu) for c in chain.cameras)
        )
    else:
        chain = chain_of(model)
    [path] = write_vio_files(tmp_path, "basalt", chain, NOISE, "/imu0", None)
    assert path.name == "calibration.json"
    calibration = json.loads(path.read_text())
    check_basalt_schema(calibration, 2)
    c = calibration["value0"]
    assert c["cam_time_offset_ns"] == 7_340_000 and c["imu_update_rate"] == 200.0
    assert c["accel_noise_std"] == [0.0021] * 3 and c["gyro_noise_std"] == [0.00017] * 3
    assert c["accel_bias_std"] == [0.00031] * 3 and c["gyro_bias_std"] == [0.000021] * 3
    for k, cam in enumerate(chain.cameras):
        assert c["intrinsics"][k]["camera_type"] == BASALT_TYPES.get(model, "pinhole")
        assert c["resolution"][k] == [752, 480]
        np.testing.assert_allclose(pose_matrix(c["T_imu_cam"][k]), invert_transform(cam.T_cam_imu), atol=1e-12)
        p = points_in_view(cam.camera)
        np.testing.assert_allclose(basalt_project(c["intrinsics"][k], p), cam.camera.project(p)[0], rtol=0, atol=1e-6)


# ------------------------------------------------------------------ what a format cannot hold
@pytest.mark.parametrize(
    ("vio_format", "camera", "n", "task", "reason"),
    [
        ("vins-fusion", "ds", 1, "joint", "VINS-Fusion has no ds model"),
        ("vins-fusion", "eucm", 2, "joint", "VINS-Fusion has no eucm model"),
        (
            "vins-fusion",
            "radtan",
            3,
            "joint",
            "VINS-Fusion takes one or two cameras, not 3: choose them with --cameras",
        ),
        ("basalt", "omni", 1, "joint", "basalt has no omni model: calibrate with --model equidistant"),
        ("basalt", "radtan", 1, "joint", "basalt has no radtan model"),
        ("basalt", CAMERAS["radtan"], 1, "extrinsic", "basalt has no radtan model"),
        ("basalt", "ds", 1, "intrinsic", "basalt needs the camera-IMU calibration"),
    ],
)
def test_a_calibration_the_format_cannot_hold_is_refused_saying_what_would(vio_format, camera, n, task, reason):
    assert reason in refusal(vio_format, camera, n, task)


def test_what_the_formats_can_hold_is_not_refused(tmp_path):
    lens_free = CameraModel("radtan", 640, 480, 500.0, 500.0, 320.0, 240.0)
    assert refusal("basalt", lens_free, 4, "extrinsic") is None
    assert refusal("vins-fusion", "omni-radtan", 2, "two_stage", {(752, 480)}) is None
    assert "one image size" in refusal("vins-fusion", "radtan", 2, "joint", {(752, 480), (640, 480)})
    with pytest.raises(FormatError, match="--export basalt: basalt has no radtan model"):
        write_vio_files(tmp_path, "basalt", chain_of("radtan"), NOISE, "/imu0", None)
