"""Kalibr and OpenVINS files kept whole: N-camera chains and IMU files, every key carried through.

``read_chain`` reads every ``camN`` section of a Kalibr ``camchain(-imucam).yaml`` or an OpenVINS
``kalibr_imucam_chain.yaml``; ``write_chain`` writes it back. What vical interprets (camera model,
``T_cam_imu`` or its variants, ``timeshift_cam_imu``, ``line_delay_nanoseconds``, ``T_cn_cnm1``, ``cam_overlaps``,
``rostopic``, ``resolution``) is written from the values, in the spelling the file used (``T_imu_cam`` stays
``T_imu_cam``, ``distortion_coefficients`` stays so; a matrix whose value is the one read is written as
read, digit for digit); every other key, per camera and at the top,
is written back as read, in the file's order. OpenCV's ``%YAML:1.0`` header (OpenVINS reads its
files with ``cv::FileStorage``) is kept. YAML comments are not kept.

``read_imu_file`` / ``write_imu_file`` do the same for Kalibr's ``imu.yaml``, Kalibr's IMU result
(``imu0:`` with ``T_i_b``, ``model``, ``time_offset``, ``accelerometers: {M}``,
``gyroscopes: {M, A, C_gyro_i}``) and OpenVINS's ``kalibr_imu_chain.yaml`` (``Tw``, ``Ta``, ``Tg``,
``R_IMUtoGYRO``, ``R_IMUtoACC``); ``imu_file_with`` puts a calibration's noise and IMU intrinsics into such
a file, the rest kept.

Refused, with the key and the reason: camera sections that skip a number (``cam0``, ``cam2``),
``cam_overlaps`` naming a camera the chain lacks, and a ``T_cn_cnm1`` that disagrees with the two
cameras' ``T_cam_imu`` beyond rounding.
"""

from __future__ import annotations

import os
import re
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from vical.data import ImuNoise, Recording
from vical.data.imu_model import ImuIntrinsics
from vical.geometry import CameraModel
from vical.geometry.transforms import invert_transform
from vical.io.errors import FormatError, KalibrFormatError, read_text_file
from vical.io.kalibr import (
    DISTORTION_ALIASES,
    EXTRINSIC_KEYS,
    LINE_DELAY_KEY,
    TIMESHIFT_KEYS,
    _camera_model,
    _extrinsic,
    _timeshift,
    camera_entry,
    imu_noise_of,
    line_delay_of,
    parse_transform,
)
from vical.io.sample_checks import FormatWarning
from vical.io.yamlfile import dump_yaml, load_mapping

OPENCV_HEADER = "%YAML:1.0"
CAMERA_SECTION = re.compile(r"cam(\d+)")
# A T_cn_cnm1 that differs from the one the cameras' T_cam_imu give by more than this is another rig.
CHAIN_ROTATION_TOLERANCE = 1e-3  # [rad] (rounding to 5 decimals gives ~1e-5)
CHAIN_TRANSLATION_TOLERANCE = 1e-3  # [m]


# ------------------------------------------------------------------------------- cameras
@dataclass(frozen=True)
class ChainCamera:
    """One ``camN`` section: what vical interprets, and the section as read (its other keys kept).

    Attributes:
        name: ``cam0``, ``cam1``, ...
        camera: the camera model (intrinsics, distortion, resolution).
        T_cam_imu: (4, 4) maps IMU points into this camera's frame, or None.
        timeshift_cam_imu: [s] ``t_imu = t_cam + shift``, or None.
        T_cn_cnm1: (4, 4) maps the previous camera's points into this camera's frame (Kalibr's
            ``T_cn_cnm1``; None for ``cam0`` or when the file has none).
        rostopic: the camera's image topic, or None.
        cam_overlaps: indices of the cameras whose views overlap this one's.
        line_delay: [s/row] its rolling shutter's line delay (``line_delay_nanoseconds``), or None.
        section: the mapping as read (empty for a camera vical made); its keys' order and spelling
            and every key vical does not interpret are written back.
    """

    name: str
    camera: CameraModel
    T_cam_imu: np.ndarray | None = None
    timeshift_cam_imu: float | None = None
    T_cn_cnm1: np.ndarray | None = None
    rostopic: str | None = None
    cam_overlaps: tuple[int, ...] = ()
    section: dict[str, Any] = field(default_factory=dict)
    line_delay: float | None = None

    @property
    def kept(self) -> dict[str, Any]:
        """The section's keys that vical does not interpret, as read."""
        return {k: v for k, v in self.section.items() if k not in _interpreted_camera_keys()}

    @property
    def extrinsic_as_read(self) -> bool:
        """``T_cam_imu`` is the one the section's extrinsic reads as (not re-estimated since)."""
        key, inverted = extrinsic_key(self.section)
        return _same_matrix(self.T_cam_imu, matrix_as_read(self.section, key, inverted))


def _interpreted_camera_keys() -> set[str]:
    keys = {"camera_model", "intrinsics", "distortion_model", "distortion_coeffs", "distortion_coefficients"}
    keys |= {"resolution", "rostopic", "cam_overlaps", "T_cn_cnm1", LINE_DELAY_KEY, *TIMESHIFT_KEYS}
    return keys | {key for key, _ in EXTRINSIC_KEYS}


@dataclass(frozen=True)
class CameraChain:
    """Every camera of a camchain file, in chain order, and the file's other top-level keys.

    Attributes:
        cameras: ``cam0``, ``cam1``, ... in order.
        top: top-level keys other than the camera sections, as read.
        opencv_header: the file started with ``%YAML:1.0`` (written back).
    """

    cameras: tuple[ChainCamera, ...]
    top: dict[str, Any] = field(default_factory=dict)
    opencv_header: bool = False

    @property
    def names(self) -> list[str]:
        return [c.name for c in self.cameras]

    def __getitem__(self, name: str) -> ChainCamera:
        for c in self.cameras:
            if c.name == name:
                return c
        raise KeyError(name)

    def relative_pose(self, name: str) -> np.ndarray | None:
        """(4, 4) ``T_cn_cnm1`` of camera ``name``: from the two cameras' ``T_cam_imu`` when both have one and
        either differs from its file's, else as the file gave it (None for ``cam0``)."""
        index = self.names.index(name)
        if index == 0:
            return None
        previous, camera = self.cameras[index - 1], self.cameras[index]
        if camera.T_cam_imu is None or previous.T_cam_imu is None:
            return camera.T_cn_cnm1
        if camera.T_cn_cnm1 is not None and camera.extrinsic_as_read and previous.extrinsic_as_read:
            return camera.T_cn_cnm1  # the file's (checked against the two on reading): its digits, not a product's
        return camera.T_cam_imu @ invert_transform(previous.T_cam_imu)


def chain_of(cameras: list[ChainCamera], base: CameraChain | None = None) -> CameraChain:
    """A chain of ``cameras``; each keeps the section (kept keys, spelling) of its namesake in ``base``."""
    if base is None:
        return CameraChain(tuple(cameras))
    known = {c.name: c.section for c in base.cameras}
    kept = tuple(replace(c, section=c.section or known.get(c.name, {})) for c in cameras)
    return CameraChain(kept, dict(base.top), base.opencv_header)


def has_opencv_header(path: str | os.PathLike) -> bool:
    return read_text_file(Path(path), KalibrFormatError).startswith(OPENCV_HEADER)


def read_chain(path: str | os.PathLike) -> CameraChain:
    """Every ``camN`` section of a Kalibr / OpenVINS camchain file (see the module docstring)."""
    data = load_mapping(path, KalibrFormatError)
    numbers = sorted(int(m.group(1)) for k in data if isinstance(k, str) and (m := CAMERA_SECTION.fullmatch(k)))
    if not numbers:
        raise KalibrFormatError(f"{path}: no camera section (cam0, cam1, ...); the file has {sorted(map(str, data))}")
    missing = sorted(set(range(numbers[-1] + 1)) - set(numbers))
    if missing:
        raise KalibrFormatError(
            f"{path}: the chain has {', '.join(f'cam{n}' for n in numbers)} but no cam{missing[0]}; Kalibr numbers "
            "the cameras of a chain cam0, cam1, ... without gaps (T_cn_cnm1 links each to the one before)"
        )
    cameras = tuple(_read_camera(data[f"cam{n}"], f"cam{n}", f"{path} [cam{n}]", len(numbers)) for n in numbers)
    chain = CameraChain(cameras, {k: v for k, v in data.items() if k not in {c.name for c in cameras}})
    chain = replace(chain, opencv_header=has_opencv_header(path))
    _check_chain(chain, str(path))
    return chain


def _read_camera(entry: Any, name: str, where: str, count: int) -> ChainCamera:
    if not isinstance(entry, dict):
        raise KalibrFormatError(f"{where} is not a mapping")
    T_cn_cnm1 = parse_transform(entry["T_cn_cnm1"], "T_cn_cnm1", where) if "T_cn_cnm1" in entry else None
    if T_cn_cnm1 is not None and name == "cam0":
        raise KalibrFormatError(f"{where}: T_cn_cnm1 relates a camera to the one before it, and cam0 has none")
    rostopic = entry.get("rostopic")
    if rostopic is not None and not isinstance(rostopic, str):
        raise KalibrFormatError(f"{where}: rostopic must be a topic name, got {rostopic!r}")
    return ChainCamera(
        name=name,
        camera=_camera_model(entry, where),
        T_cam_imu=_extrinsic(entry, where),
        timeshift_cam_imu=_timeshift(entry, where),
        T_cn_cnm1=T_cn_cnm1,
        rostopic=rostopic,
        cam_overlaps=_overlaps(entry.get("cam_overlaps", []), name, where, count),
        section=dict(entry),
        line_delay=line_delay_of(entry, where),
    )


def _overlaps(value: Any, name: str, where: str, count: int) -> tuple[int, ...]:
    if not isinstance(value, list) or not all(isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise KalibrFormatError(f"{where}: cam_overlaps must be a list of camera indices, got {value!r}")
    unknown = [v for v in value if not 0 <= v < count or f"cam{v}" == name]
    if unknown:
        raise KalibrFormatError(
            f"{where}: cam_overlaps names camera {unknown[0]}, but the chain has cam0..cam{count - 1} "
            "(and a camera does not overlap itself)"
        )
    return tuple(value)


def _check_chain(chain: CameraChain, path: str) -> None:
    """Refuse a ``T_cn_cnm1`` that contradicts the cameras' ``T_cam_imu`` beyond rounding."""
    for previous, camera in zip(chain.cameras, chain.cameras[1:], strict=False):
        if camera.T_cn_cnm1 is None or camera.T_cam_imu is None or previous.T_cam_imu is None:
            continue
        implied = camera.T_cam_imu @ invert_transform(previous.T_cam_imu)
        delta = implied @ invert_transform(camera.T_cn_cnm1)
        angle = float(np.arccos(np.clip((np.trace(delta[:3, :3]) - 1) / 2, -1.0, 1.0)))
        shift = float(np.linalg.norm(delta[:3, 3]))
        if angle > CHAIN_ROTATION_TOLERANCE or shift > CHAIN_TRANSLATION_TOLERANCE:
            raise KalibrFormatError(
                f"{path} [{camera.name}]: T_cn_cnm1 disagrees with T_cam_imu of {camera.name} and {previous.name} "
                f"by {np.degrees(angle):.3f} deg and {shift * 1e3:.2f} mm (more than rounding); the file mixes two "
                "calibrations: keep the one Kalibr wrote, or delete T_cn_cnm1 (it follows from the T_cam_imu)"
            )


def check_chain_fits(
    chain: CameraChain, path: str | os.PathLike, recording: Recording, chosen: Sequence[str] | None = None
) -> None:
    """Refuse a camchain whose cameras the recording lacks, or whose resolution differs from their images'.

    ``chosen``: the cameras a user chose to calibrate (the recording was read for those alone); the chain's
    others are then not looked for. Image sizes come from ``recording.metadata["image_sizes"]`` (EuRoC folders
    and bags) or the stored images.
    """
    looked_for = [name for name in chain.names if chosen is None or name in chosen]
    missing = [name for name in looked_for if name not in recording.camera_names]
    if missing:
        raise FormatError(
            f"{path} names {missing[0]}, but the recording has only {', '.join(recording.camera_names)}; give the "
            "recording every camera of the chain (EuRoC camN folders, one bag topic per camera) or a camchain of these"
        )
    sizes = recording.metadata.get("image_sizes", {})
    for camera in (c for c in chain.cameras if c.name in looked_for):
        images = recording.frames_of(camera.name).images
        size = sizes.get(camera.name) or (None if images is None else [images.shape[2], images.shape[1]])
        expected = [camera.camera.width, camera.camera.height]
        if size is not None and list(size) != expected:
            raise FormatError(
                f"{path} [{camera.name}]: resolution {expected[0]} x {expected[1]} px, but {camera.name}'s images are "
                f"{size[0]} x {size[1]} px; give the camchain of this camera at this resolution"
            )


def write_chain(path: str | os.PathLike, chain: CameraChain) -> None:
    """Write ``chain`` atomically: interpreted keys from the values (``T_cn_cnm1`` from the cameras'
    ``T_cam_imu`` when both have one), every kept key as read, in the file's order."""
    data: dict[str, Any] = {}
    for camera in chain.cameras:
        data[camera.name] = _camera_section(camera, chain.relative_pose(camera.name))
    data.update(chain.top)
    dump_yaml(path, data, header=OPENCV_HEADER if chain.opencv_header else None)


def _camera_section(camera: ChainCamera, T_cn_cnm1: np.ndarray | None) -> dict[str, Any]:
    old = camera.section
    new = camera_entry(camera.camera, None, None, camera.rostopic or f"/{camera.name}/image_raw", camera.line_delay)
    if camera.rostopic is None and "rostopic" not in old:
        del new["rostopic"]
    new["cam_overlaps"] = list(camera.cam_overlaps)
    if T_cn_cnm1 is not None:
        new["T_cn_cnm1"] = _matrix_entry(old, "T_cn_cnm1", T_cn_cnm1)
    if camera.T_cam_imu is not None:
        key, inverted = extrinsic_key(old)
        new[key] = _matrix_entry(old, key, camera.T_cam_imu, inverted)
    if camera.timeshift_cam_imu is not None:
        key = next((k for k in TIMESHIFT_KEYS if k in old), TIMESHIFT_KEYS[0])
        new[key] = float(camera.timeshift_cam_imu)
    if LINE_DELAY_KEY in new and LINE_DELAY_KEY in old and line_delay_of(old, camera.name) == camera.line_delay:
        new[LINE_DELAY_KEY] = old[LINE_DELAY_KEY]  # as read, digit for digit (not through seconds and back)
    _keep_spelling(old, new)
    section = {k: new.pop(k) if k in new else v for k, v in old.items()}
    return section | new


def _keep_spelling(old: dict[str, Any], new: dict[str, Any]) -> None:
    """Write the distortion model and its coefficients' key the way the file spelled them."""
    if DISTORTION_ALIASES.get(str(old.get("distortion_model"))) == new["distortion_model"]:
        new["distortion_model"] = old["distortion_model"]
    if "distortion_coefficients" in old and "distortion_coeffs" not in old:
        new["distortion_coefficients"] = new.pop("distortion_coeffs")


def extrinsic_key(section: dict[str, Any]) -> tuple[str, bool]:
    """The section's extrinsic key and whether it holds ``T_imu_cam`` (inverted); Kalibr's ``T_cam_imu`` without one."""
    return next(((k, inverted) for k, inverted in EXTRINSIC_KEYS if k in section), ("T_cam_imu", False))


def matrix_as_read(section: dict[str, Any], key: str, inverted: bool = False) -> np.ndarray | None:
    """The (4, 4) matrix vical reads from ``section[key]`` (inverted when ``inverted``), None without the key.

    The reader's warnings (a rounded rotation) were given when the file was read and are not repeated."""
    if key not in section:
        return None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FormatWarning)
        T = parse_transform(section[key], key, key)
    return invert_transform(T) if inverted else T


def _same_matrix(a: np.ndarray | None, b: np.ndarray | None) -> bool:
    return a is not None and b is not None and np.array_equal(a, b)


def _matrix_entry(old: dict[str, Any], key: str, T: np.ndarray, inverted: bool = False) -> Any:
    """``T`` under ``key``: the file's entry when it reads as ``T``, so that a matrix passed through keeps its
    digits (re-deriving it would invert twice, whose round-off grows on every pass when the file's rotation is
    rounded), else ``T`` (inverted when ``inverted``) in the file's layout."""
    if _same_matrix(matrix_as_read(old, key, inverted), T):
        return old[key]
    return _matrix_like(old.get(key), invert_transform(T) if inverted else T)


def _matrix_like(old: Any, T: np.ndarray) -> Any:
    """``T`` in the layout ``old`` had: a ``{rows, cols, data}`` mapping, a flat list of 16, or 4 rows."""
    values = np.asarray(T, dtype=np.float64)
    if isinstance(old, dict):
        return {**old, "data": [float(v) for v in values.reshape(-1)]}
    if isinstance(old, list) and len(old) == 16:
        return [float(v) for v in values.reshape(-1)]
    return values.tolist()


# ------------------------------------------------------------------------------- IMU
@dataclass(frozen=True)
class ImuFile:
    """A Kalibr / OpenVINS IMU file: the noise vical reads, and the file as read (kept whole on writing).

    Attributes:
        noise: the noise densities, random walks and rate.
        rostopic: the IMU topic, or None.
        section: the IMU's mapping as read (``imu0``'s, or the whole file when it has no ``imu0``).
        top: the file's other top-level keys (with an ``imu0`` section), as read.
        in_section: the file keeps the IMU under ``imu0:`` (Kalibr's result, OpenVINS).
        opencv_header: the file started with ``%YAML:1.0``.
    """

    noise: ImuNoise
    rostopic: str | None = None
    section: dict[str, Any] = field(default_factory=dict)
    top: dict[str, Any] = field(default_factory=dict)
    in_section: bool = False
    opencv_header: bool = False


def read_imu_file(path: str | os.PathLike) -> ImuFile:
    """The IMU file ``path`` whole (no key refused: IMU intrinsics are kept, not applied; see
    ``vical.io.kalibr.read_imu_yaml`` for the reading that calibration uses)."""
    data = load_mapping(path, KalibrFormatError)
    in_section = isinstance(data.get("imu0"), dict)
    section, where = (data["imu0"], f"{path} [imu0]") if in_section else (data, str(path))
    rostopic = section.get("rostopic")
    top = {k: v for k, v in data.items() if k != "imu0"} if in_section else {}
    return ImuFile(
        imu_noise_of(section, where),
        rostopic if isinstance(rostopic, str) else None,
        dict(section),
        top,
        in_section,
        has_opencv_header(path),
    )


def write_imu_file(path: str | os.PathLike, imu: ImuFile) -> None:
    """Write ``imu`` atomically: the noise keys from ``imu.noise`` (in the file's spelling of the rate),
    every other key as read."""
    old = imu.section
    rate_key = "rate_hz" if "rate_hz" in old and "update_rate" not in old else "update_rate"
    new = {
        "accelerometer_noise_density": float(imu.noise.accel_noise_density),
        "accelerometer_random_walk": float(imu.noise.accel_random_walk),
        "gyroscope_noise_density": float(imu.noise.gyro_noise_density),
        "gyroscope_random_walk": float(imu.noise.gyro_random_walk),
        rate_key: float(imu.noise.rate_hz),
    }
    if imu.rostopic is not None:
        new["rostopic"] = imu.rostopic
    section = {k: new.pop(k) if k in new else v for k, v in old.items()} | new
    data = ({"imu0": section} | imu.top) if imu.in_section else section
    dump_yaml(path, data, header=OPENCV_HEADER if imu.opencv_header else None)


# OpenVINS's intrinsic matrices: they give way to Kalibr's keys when intrinsics are written (vical reads
# them only when they are an ideal IMU's, so nothing measured is lost).
OPENVINS_INTRINSIC_KEYS = ("Tw", "Ta", "Tg", "R_IMUtoGYRO", "R_IMUtoACC")


def imu_file_with(imu: ImuFile, noise: ImuNoise, intrinsics: ImuIntrinsics | None) -> ImuFile:
    """``imu`` with the noise ``noise`` and, when given, ``intrinsics`` in Kalibr's scale-misalignment keys
    (``model``, ``accelerometers: {M}``, ``gyroscopes: {M, A, C_gyro_i}``; OpenVINS's ``OPENVINS_INTRINSIC_KEYS``
    left out); every other key (``rostopic``, ``T_i_b``, ``time_offset``, ...) as read."""
    section = dict(imu.section)
    if intrinsics is not None:
        for key in OPENVINS_INTRINSIC_KEYS:
            section.pop(key, None)
        accelerometers = section.get("accelerometers")
        gyroscopes = section.get("gyroscopes")
        section["model"] = "scale-misalignment"
        section["accelerometers"] = (accelerometers if isinstance(accelerometers, dict) else {}) | {
            "M": intrinsics.M_accel.tolist()
        }
        section["gyroscopes"] = (gyroscopes if isinstance(gyroscopes, dict) else {}) | {
            "M": intrinsics.M_gyro.tolist(), "A": intrinsics.A_gyro.tolist(), "C_gyro_i": intrinsics.C_gyro_i.tolist()
        }  # fmt: skip
    return replace(imu, noise=noise, section=section)
