"""A camera-IMU calibration as the files two VIO systems read: VINS-Fusion and basalt.

OpenVINS reads Kalibr's ``camchain-imucam.yaml`` and ``imu.yaml`` as they are (``vical.io.kalibr_chain``); these two
have files of their own, each with its own conventions (``docs/formats.md``):

* **VINS-Fusion** (``vins-fusion/``): ``config.yaml``, the estimator's settings with the calibration in them, and
  ``cam0.yaml`` (``cam1.yaml``), camodocal's camera files, all OpenCV ``FileStorage`` YAML (``%YAML:1.0``), which
  VINS-Fusion reads with ``cv::FileStorage``. ``body_T_cam0`` is camera -> IMU (the inverse of Kalibr's
  ``T_cam_imu``); ``td`` is Kalibr's ``timeshift_cam_imu`` (image time + td = IMU time). Lens models: ``PINHOLE``
  (radtan), ``KANNALA_BRANDT`` (equidistant), ``MEI`` (omni, omni-radtan); one or two cameras of one image size.
* **basalt** (``basalt/calibration.json``): cereal's JSON of basalt's ``Calibration``. ``T_imu_cam`` is camera ->
  IMU as ``px py pz qx qy qz qw``; ``cam_time_offset_ns`` is Kalibr's ``timeshift_cam_imu`` in ns (basalt adds it
  to each image's timestamp). Lens models: ``kb4`` (equidistant), ``ds``, ``eucm``, and ``pinhole`` for a radtan
  camera whose coefficients are all zero; basalt has no radial-tangential model.

The IMU noise is written as vical holds it, Kalibr's continuous-time densities and random walks, which is what both
read (VINS-Fusion's ``acc_n`` / ``gyr_n`` / ``acc_w`` / ``gyr_w``, basalt's ``*_noise_std`` / ``*_bias_std``); both
estimate the IMU's biases online, so their calibrated biases and basalt's scale terms are written as an ideal IMU's.
A format that cannot hold the calibration is refused before anything is solved (``refusal``), in one line.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from vical.data import ImuNoise
from vical.geometry import CameraModel, invert_transform
from vical.geometry.transforms import matrix_to_quat
from vical.io.atomic import write_text_atomic
from vical.io.errors import FormatError
from vical.io.kalibr_chain import CameraChain

VIO_FORMATS = ("vins-fusion", "basalt")
VINS_MODELS = {"radtan": "PINHOLE", "equidistant": "KANNALA_BRANDT", "omni": "MEI", "omni-radtan": "MEI"}
BASALT_MODELS = {"equidistant": "kb4", "ds": "ds", "eucm": "eucm", "radtan": "pinhole"}  # radtan: without distortion
RADTAN, PINHOLE, MEI = ("k1", "k2", "p1", "p2"), ("fx", "fy", "cx", "cy"), ("gamma1", "gamma2", "u0", "v0")
GRAVITY = 9.81  # [m/s^2] VINS-Fusion's g_norm where the calibration did not estimate gravity
# VINS-Fusion's estimator and front-end settings (its EuRoC examples' values): not calibration, to be tuned for the
# camera and the platform.
VINS_SETTINGS = {
    "multiple_thread": 1,
    "max_cnt": 150,
    "min_dist": 30,
    "freq": 10,
    "F_threshold": 1.0,
    "show_track": 1,
    "flow_back": 1,
    "max_solver_time": 0.04,
    "max_num_iterations": 8,
    "keyframe_parallax": 10.0,
}


class ExportError(FormatError):
    """A VIO format that cannot hold the calibration (its lens model, its number of cameras)."""


def refusal(
    vio_format: str, camera: CameraModel | str, num_cameras: int, task: str, sizes: set[tuple[int, int]] = frozenset()
) -> str | None:
    """Why ``vio_format`` cannot hold a ``task`` calibration of ``num_cameras`` cameras whose images have ``sizes``
    (W, H), or None; ``camera``: the lens model to estimate, or the known camera (the extrinsic task). Known before
    the solve."""
    model = camera if isinstance(camera, str) else camera.distortion
    if task == "intrinsic":
        return f"{vio_format} needs the camera-IMU calibration: --task joint, extrinsic or two_stage"
    if vio_format == "vins-fusion":
        if model not in VINS_MODELS:
            return f"VINS-Fusion has no {model} model (its camodocal lenses: radtan, equidistant, omni, omni-radtan)"
        if num_cameras > 2:
            return f"VINS-Fusion takes one or two cameras, not {num_cameras}: choose them with --cameras"
        if len(sizes) > 1:
            return f"VINS-Fusion's config holds one image size, the cameras' are {sorted(sizes)}"
        return None
    lens_free = model == "radtan" and not isinstance(camera, str) and not np.any(camera.dist)
    if model not in BASALT_MODELS or (model == "radtan" and not lens_free):
        return (
            f"basalt has no {model} model: calibrate with --model equidistant (basalt's kb4), ds or eucm (a radtan "
            "camera only as basalt's pinhole, a known one without distortion)"
        )
    return None


def check_exportable(
    vio_format: str, camera: CameraModel | str, num_cameras: int, task: str, sizes: set[tuple[int, int]] = frozenset()
) -> None:
    if (reason := refusal(vio_format, camera, num_cameras, task, sizes)) is not None:
        raise ExportError(f"--export {vio_format}: {reason}")


def write_vio_files(folder: str | os.PathLike, vio_format: str, chain: CameraChain, noise: ImuNoise,
                    imu_topic: str, gravity: float | None) -> list[Path]:  # fmt: skip
    """Write ``chain`` (every camera with its ``T_cam_imu`` and time shift) and ``noise`` as ``vio_format``'s files
    into ``folder``; the paths written."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if vio_format == "vins-fusion":
        return write_vins_fusion(folder, chain, noise, imu_topic, gravity)
    return [write_basalt(folder / "calibration.json", chain, noise)]


# ------------------------------------------------------------------------------------ VINS-Fusion
def _number(x: float) -> str:
    return repr(float(x))


def _opencv_matrix(T: np.ndarray) -> str:
    rows = [", ".join(_number(v) for v in row) for row in np.asarray(T, dtype=float)]
    data = (",\n" + " " * 10).join(rows)
    return f"!!opencv-matrix\n   rows: 4\n   cols: 4\n   dt: d\n   data: [{data}]"


def _block(title: str, names: tuple[str, ...], values: list[str]) -> list[str]:
    return [f"{title}:", *(f"   {n}: {v}" for n, v in zip(names, values, strict=True))]


def _camodocal_parameters(camera: CameraModel) -> list[str]:
    """camodocal's parameter blocks of ``camera`` (``VINS_MODELS``' model types)."""
    k = [_number(v) for v in camera.dist]
    f = [_number(v) for v in (camera.fx, camera.fy, camera.cx, camera.cy)]
    if camera.distortion == "radtan":
        return [*_block("distortion_parameters", RADTAN, k), *_block("projection_parameters", PINHOLE, f)]
    if camera.distortion == "equidistant":  # camodocal numbers OpenCV's k1..k4 as k2..k5, all under projection
        return _block("projection_parameters", ("k2", "k3", "k4", "k5", "mu", "mv", "u0", "v0"), [*k, *f])
    lens = k[1:] if camera.distortion == "omni-radtan" else [_number(0.0)] * 4
    mirror = _block("mirror_parameters", ("xi",), k[:1])
    return [*mirror, *_block("distortion_parameters", RADTAN, lens), *_block("projection_parameters", MEI, f)]


def vins_camera_text(name: str, camera: CameraModel) -> str:
    lines = [
        "%YAML:1.0",
        "---",
        f"# vical's {camera.distortion} calibration of {name}, as camodocal reads it",
        f"model_type: {VINS_MODELS[camera.distortion]}",
        f"camera_name: {name}",
        f"image_width: {camera.width}",
        f"image_height: {camera.height}",
        *_camodocal_parameters(camera),
    ]
    return "\n".join(lines) + "\n"


def vins_config_text(chain: CameraChain, noise: ImuNoise, imu_topic: str, gravity: float | None) -> str:
    cams = chain.cameras
    lines = [
        "%YAML:1.0",
        "# VINS-Fusion's settings with vical's camera-IMU calibration. Frames: body_T_camN maps camera N's points",
        "# into the IMU (body) frame, the inverse of Kalibr's T_cam_imu. Time: td is Kalibr's timeshift_cam_imu",
        "# [s]: image time + td = IMU time. IMU noise: Kalibr's continuous-time densities and random walks, as",
        "# vical estimated or was given them (VINS-Fusion's own examples inflate them several times).",
        "imu: 1",
        f"num_of_cam: {len(cams)}",
        f'imu_topic: "{imu_topic}"',
        *(f'image{k}_topic: "{cam.rostopic or f"/cam{k}/image_raw"}"' for k, cam in enumerate(cams)),
        'output_path: "/tmp/vins_output/"  # where VINS-Fusion writes its trajectory',
        *(f'cam{k}_calib: "{cam.name}.yaml"' for k, cam in enumerate(cams)),
        f"image_width: {cams[0].camera.width}",
        f"image_height: {cams[0].camera.height}",
        "estimate_extrinsic: 0  # 0: trust body_T_camN (calibrated); 1: refine it online",
        *(f"body_T_cam{k}: {_opencv_matrix(invert_transform(cam.T_cam_imu))}" for k, cam in enumerate(cams)),
        *(f"{key}: {value}" for key, value in VINS_SETTINGS.items()),
        f"acc_n: {_number(noise.accel_noise_density)}  # [m/s^2/sqrt(Hz)]",
        f"gyr_n: {_number(noise.gyro_noise_density)}  # [rad/s/sqrt(Hz)]",
        f"acc_w: {_number(noise.accel_random_walk)}  # [m/s^3/sqrt(Hz)]",
        f"gyr_w: {_number(noise.gyro_random_walk)}  # [rad/s^2/sqrt(Hz)]",
        f"g_norm: {_number(GRAVITY if gravity is None else gravity)}",
        "estimate_td: 0  # 0: trust td (calibrated); 1: refine it online",
        f"td: {_number(cams[0].timeshift_cam_imu)}",
        "load_previous_pose_graph: 0",
        'pose_graph_save_path: "/tmp/vins_output/pose_graph/"',
        "save_image: 0",
    ]
    return "\n".join(lines) + "\n"


def write_vins_fusion(folder: Path, chain: CameraChain, noise: ImuNoise, imu_topic: str,
                      gravity: float | None) -> list[Path]:  # fmt: skip
    """VINS-Fusion's ``config.yaml`` and a camodocal file per camera into ``folder``."""
    sizes = {(cam.camera.width, cam.camera.height) for cam in chain.cameras}
    for cam in chain.cameras:
        check_exportable("vins-fusion", cam.camera, len(chain.cameras), "joint", sizes)
    written = []
    for cam in chain.cameras:
        write_text_atomic(folder / f"{cam.name}.yaml", vins_camera_text(cam.name, cam.camera))
        written.append(folder / f"{cam.name}.yaml")
    write_text_atomic(folder / "config.yaml", vins_config_text(chain, noise, imu_topic, gravity))
    return [folder / "config.yaml", *written]


# ------------------------------------------------------------------------------------ basalt
def _basalt_intrinsics(camera: CameraModel) -> dict:
    check_exportable("basalt", camera, 1, "joint")
    projection = {"fx": camera.fx, "fy": camera.fy, "cx": camera.cx, "cy": camera.cy}
    coefficients = (
        {} if camera.distortion == "radtan" else dict(zip(camera.coefficient_names, camera.dist.tolist(), strict=True))
    )
    return {"camera_type": BASALT_MODELS[camera.distortion], "intrinsics": {**projection, **coefficients}}


def _basalt_pose(T_imu_cam: np.ndarray) -> dict:
    w, x, y, z = matrix_to_quat(T_imu_cam[:3, :3])
    px, py, pz = T_imu_cam[:3, 3]
    return {"px": px, "py": py, "pz": pz, "qx": x, "qy": y, "qz": z, "qw": w}


def basalt_calibration(chain: CameraChain, noise: ImuNoise) -> dict:
    """basalt's ``Calibration`` as cereal writes it (under ``value0``)."""
    calibration = {
        "T_imu_cam": [_basalt_pose(invert_transform(cam.T_cam_imu)) for cam in chain.cameras],
        "intrinsics": [_basalt_intrinsics(cam.camera) for cam in chain.cameras],
        "resolution": [[cam.camera.width, cam.camera.height] for cam in chain.cameras],
        "calib_accel_bias": [0.0] * 9,  # bias and scale: an ideal IMU's (basalt estimates the biases online)
        "calib_gyro_bias": [0.0] * 12,
        "imu_update_rate": float(noise.rate_hz),
        "accel_noise_std": [noise.accel_noise_density] * 3,  # per axis
        "gyro_noise_std": [noise.gyro_noise_density] * 3,  # per axis
        "accel_bias_std": [noise.accel_random_walk] * 3,  # per axis
        "gyro_bias_std": [noise.gyro_random_walk] * 3,  # per axis
        "cam_time_offset_ns": round(chain.cameras[0].timeshift_cam_imu * 1e9),
        "vignette": [],
    }
    return {"value0": calibration}


def write_basalt(path: Path, chain: CameraChain, noise: ImuNoise) -> Path:
    write_text_atomic(path, json.dumps(basalt_calibration(chain, noise), indent=4) + "\n")
    return path
