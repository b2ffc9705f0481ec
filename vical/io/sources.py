"""One entry point that recognises what a path holds and reads it as a ``Recording``.

Recognised, in this order:

1. a vical recording directory (``recording.yaml``),
2. an EuRoC/ASL folder (``cam0/data.csv`` in it or in its ``mav0/``),
3. a ROS1 bag (a file starting with ``#ROSBAG V2.0``) or a ROS 2 bag (a folder with rosbag2's ``metadata.yaml``, or
   its ``.db3`` / ``.mcap`` storage file: ``vical.io.bag.bag_generation``),
4. a corner folder (``camN/<timestamp ns>.csv`` per frame with board coordinates and ``imu0.csv``:
   ``vical.io.board_points``),
5. a corner CSV (``*.csv``: vical's point ids, or named columns with board coordinates), with the IMU
   from ``imu_csv`` (EuRoC format) when given,
6. a folder of images (intrinsic-only: no IMU; timestamps from file order at ``rate_hz``).

``open_imu`` reads an IMU-only recording (a static one, for ``vical-imu-noise``): an EuRoC folder or
IMU CSV, or a ROS1 or ROS 2 bag's IMU topic.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from vical.data import ImuSamples, Recording, Target
from vical.io.bag import bag_generation, read_bag, read_bag_imu
from vical.io.board_points import (
    camera_folders,
    chosen_cameras,
    corner_folder_imu,
    is_corner_folder,
    names_board_points,
    read_board_point_csv,
    read_camera_folder,
)
from vical.io.csvfiles import read_corners_csv, read_imu_csv
from vical.io.errors import FormatError, SourceSettingError
from vical.io.euroc import find_euroc_root, read_euroc
from vical.io.images import ImageDetector, list_images, read_image_folder
from vical.io.recording import is_recording_dir, load_recording
from vical.io.sample_checks import GYRO_UNITS


def detect_source(path: str | os.PathLike) -> str:
    """``"recording"``, ``"euroc"``, ``"bag"``, ``"corner_folder"``, ``"corners_csv"`` or ``"image_folder"``; raise
    if none fits."""
    path = Path(path)
    if not path.exists():
        raise FormatError(f"{path} does not exist")
    if path.is_dir():
        if is_recording_dir(path):
            return "recording"
        if find_euroc_root(path) is not None:
            return "euroc"
    if bag_generation(path) is not None:
        return "bag"
    if path.is_dir():
        if is_corner_folder(path):
            return "corner_folder"
        if list_images(path):
            return "image_folder"
    elif path.suffix.lower() == ".csv":
        return "corners_csv"
    raise FormatError(
        f"{path} is none of: a vical recording directory (recording.yaml), an EuRoC folder (cam0/data.csv), "
        "a corner folder (cam0/<timestamp>.csv), a ROS1 or ROS 2 bag, a corner CSV (.csv) or a folder of images"
    )


def open_recording(
    path: str | os.PathLike,
    target: Target | None = None,
    detector: ImageDetector | None = None,
    imu_csv: str | os.PathLike | None = None,
    image_topic: str | Sequence[str] = "/cam0/image_raw",
    imu_topic: str | None = "/imu0",
    rate_hz: float = 10.0,
    keep_images: bool = False,
    gyro_unit: str = "rad/s",
    accel_unit: str = "m/s^2",
    cameras: Sequence[str] | None = None,
) -> Recording:
    """Read whatever ``path`` holds (see ``detect_source``) as a ``Recording``.

    Args:
        target: the calibration target; required for every source except a recording directory
            (which stores its own; when given, it must agree).
        detector: ``detector(image) -> (corners (K, 2), ids (K,))`` for sources with images.
            EuRoC folders written by vical fall back to their ``cam0/corners.csv``.
        imu_csv: EuRoC-format IMU CSV to pair with a corner CSV.
        image_topic, imu_topic: bag topics (``imu_topic=None``: images only); several image topics
            for a rig's cameras (cam0's first). An EuRoC folder's camera folders are all read.
        rate_hz: frame rate [Hz] that timestamps an image folder.
        keep_images: keep decoded images in memory (EuRoC, bag, image folder).
        gyro_unit, accel_unit: units of IMU values in CSVs and bags (``"deg/s"``, ``"g"`` convert).
        cameras: the camera folders of an EuRoC or corner folder to read (None: all; cam0 is always read).
    """
    kind = detect_source(path)
    if kind == "recording":
        recording = load_recording(path)
        if target is not None and target != recording.target:
            raise FormatError(f"{path} was recorded with target {recording.target}, not the given {target}")
        return recording
    if target is None:
        raise SourceSettingError(
            f"{path} is a {kind.replace('_', ' ')}: give the calibration target as {{fix}} (a Kalibr target YAML)",
            "target", "read_target_yaml('target.yaml')", "target.yaml",
        )  # fmt: skip
    units = {"gyro_unit": gyro_unit, "accel_unit": accel_unit}
    if kind == "euroc":
        return read_euroc(path, target, detector, keep_images, cameras=cameras, **units)
    if kind == "bag":
        return read_bag(path, target, detector, image_topic, imu_topic, keep_images, **units)
    if kind == "corner_folder":
        return read_corner_folder(path, target, imu_csv, cameras=cameras, **units)
    if kind == "corners_csv":
        imu = read_imu_csv(imu_csv, **units) if imu_csv is not None else _no_imu()
        frames = read_board_point_csv(path, target) if names_board_points(path) else read_corners_csv(path, target)
        return Recording(imu, frames, target, metadata={"source": "corners_csv", "path": str(Path(path).resolve())})
    frames = read_image_folder(path, target, detector, rate_hz, keep_images=keep_images)
    return Recording(_no_imu(), frames, target, metadata={"source": "image_folder", "path": str(Path(path).resolve())})


def read_corner_folder(
    path: str | os.PathLike,
    target: Target,
    imu_csv: str | os.PathLike | None = None,
    gyro_unit: str = "rad/s",
    accel_unit: str = "m/s^2",
    cameras: Sequence[str] | None = None,
) -> Recording:
    """A corner folder's cameras (``camN/``, cam0 first; ``cameras``: those and cam0, ``chosen_cameras``) and its
    IMU (``imu_csv``, else its ``imu0.csv``)."""
    root = Path(path)
    imu_path = imu_csv if imu_csv is not None else corner_folder_imu(root)
    imu = read_imu_csv(imu_path, gyro_unit, accel_unit) if imu_path is not None else _no_imu()
    names = chosen_cameras(camera_folders(root), cameras, str(root), "its camN folders of per-frame corner files")
    read = {name: read_camera_folder(root / name, target) for name in names}
    frames = read.pop("cam0")
    meta = {"source": "corner_folder", "path": str(root.resolve())}
    return Recording(imu, frames, target, metadata=meta, other_frames=read)


def _no_imu() -> ImuSamples:
    return ImuSamples(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


def open_imu(
    path: str | os.PathLike, imu_topic: str = "/imu0", gyro_unit: str = "rad/s", accel_unit: str = "m/s^2"
) -> ImuSamples:
    """The IMU samples of an IMU-only recording: an EuRoC folder (``imu0/data.csv`` in it or in its
    ``mav0/``), an EuRoC IMU CSV, or a ROS1 or ROS 2 bag's ``imu_topic``; no camera needed.

    The gyro is read as rad/s and converted afterwards: the readers' unit check expects a calibration
    motion, which would take a resting gyro logged in deg/s for one logged in rad/s.
    """
    path = Path(path)
    if gyro_unit not in GYRO_UNITS:
        raise FormatError(f"gyro_unit must be one of {list(GYRO_UNITS)}, got {gyro_unit!r}")
    if not path.exists():
        raise FormatError(f"{path} does not exist")
    if bag_generation(path) is not None:
        imu = read_bag_imu(path, imu_topic, "rad/s", accel_unit)
    elif path.is_dir():
        csv = next((c for c in (path / "mav0" / "imu0" / "data.csv", path / "imu0" / "data.csv") if c.is_file()), None)
        if csv is None:
            raise FormatError(f"{path} holds no IMU CSV: neither {path}/imu0/data.csv nor {path}/mav0/imu0/data.csv")
        imu = read_imu_csv(csv, "rad/s", accel_unit)
    elif path.suffix.lower() == ".csv":
        imu = read_imu_csv(path, "rad/s", accel_unit)
    else:
        raise FormatError(
            f"{path} is none of: an EuRoC IMU CSV (.csv), an EuRoC folder, a ROS1 bag or a ROS 2 bag (a folder with "
            "metadata.yaml, a .db3 or .mcap file)"
        )
    return ImuSamples(imu.t, imu.gyro * GYRO_UNITS[gyro_unit], imu.accel)
