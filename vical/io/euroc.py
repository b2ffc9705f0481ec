"""EuRoC / ASL dataset folders.

Layout (as the EuRoC MAV dataset ships it; ``<root>/mav0`` or the ``mav0`` folder itself)::

    mav0/cam0/data/<t_ns>.png   8-bit grey images
    mav0/cam0/data.csv          #timestamp [ns],filename
    mav0/cam0/sensor.yaml       camera: T_BS (camera -> body = IMU), intrinsics, distortion, rate_hz
    mav0/cam0/corners.csv       (vical) detections as a corner CSV, see ``vical.io.csvfiles``
    mav0/imu0/data.csv          #timestamp [ns],w_RS_S_x [rad s^-1],...,a_RS_S_z [m s^-2]
    mav0/imu0/sensor.yaml       IMU noise densities, random walks, rate_hz

A rig's other cameras lie beside ``cam0`` as ``cam1``, ``cam2``, ... with the same layout (EuRoC
ships cam0 + cam1); they become the recording's ``other_frames``. vical writes
``timeshift_cam_imu`` [s] (Kalibr's sign) into ``camN/sensor.yaml`` when the time offset is known.
The reference calibration in the ``sensor.yaml`` files, when complete, becomes the recording's
``truth`` (``other_truths`` for the other cameras).
"""

from __future__ import annotations

import errno
import os
import re
import shutil
import warnings
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from vical.data import CameraFrames, ImuNoise, ImuSamples, Recording, SensorTruth, Target, median_rate_hz
from vical.geometry.transforms import invert_transform
from vical.io.atomic import atomic_directory, atomic_file, check_can_write_dir, write_text_atomic
from vical.io.board_points import chosen_cameras
from vical.io.csvfiles import (
    CORNER_HEADER,
    IMU_HEADER,
    corner_rows,
    imu_rows,
    parse_times,
    read_corners_csv,
    read_imu_csv,
    read_rows,
    write_corners_csv,
    write_imu_csv,
)
from vical.io.errors import CsvFormatError, EmptyCsvError, FormatError, KalibrFormatError, RecordingWriteError
from vical.io.images import ImageDetector, frames_from_images, read_gray, write_png
from vical.io.kalibr import (
    LINE_DELAY_KEY,
    camera_entry,
    kalibr_intrinsics,
    read_camchain,
    read_imu_yaml,
    read_line_delay,
)
from vical.io.sample_checks import check_camera_rates, check_sampling, sort_and_dedupe, warn
from vical.io.yamlfile import as_floats, dump_yaml, load_mapping

EUROC_DISTORTION_NAMES = {"radtan": "radial-tangential", "equidistant": "equidistant"}
CAMERA_FOLDER = re.compile(r"cam\d+")


def find_euroc_root(path: str | os.PathLike) -> Path | None:
    """The folder holding ``cam0/data.csv`` (``path`` or ``path/mav0``), or None."""
    for root in (Path(path) / "mav0", Path(path)):
        if (root / "cam0" / "data.csv").is_file():
            return root
    return None


# ------------------------------------------------------------------------------------ write
def write_euroc(recording: Recording, path: str | os.PathLike, overwrite: bool = False) -> Path:
    """Write ``recording`` as an EuRoC folder ``path/mav0/...`` atomically (every camera); return ``path``.

    The frames must carry images. Detections go to ``camN/corners.csv``; the truth (if any) to
    the ``sensor.yaml`` files.
    """
    for name in recording.camera_names:
        if recording.frames_of(name).images is None:
            raise FormatError(
                f"an EuRoC folder holds images, but the recording's {name} has none; record it with images"
            )
    with atomic_directory(path, overwrite=overwrite) as tmp:
        imu = tmp / "mav0" / "imu0"
        imu.mkdir(parents=True)
        for name in recording.camera_names:
            cam = tmp / "mav0" / name
            (cam / "data").mkdir(parents=True)
            frames = recording.frames_of(name)
            _write_images(frames, cam)
            write_corners_csv(frames, cam / "corners.csv")
            dump_yaml(cam / "sensor.yaml", _camera_sensor_yaml(frames, recording.truth_of(name)))
        write_imu_csv(recording.imu, imu / "data.csv")
        dump_yaml(imu / "sensor.yaml", _imu_sensor_yaml(recording))
    return Path(path)


def write_euroc_imu(
    path: str | os.PathLike,
    chunks: Iterable[ImuSamples],
    noise: ImuNoise | None,
    rate_hz: float,
    comment: str,
    overwrite: bool = False,
) -> Path:
    """An IMU-only EuRoC folder (``mav0/imu0/data.csv`` and ``sensor.yaml``) from IMU samples given chunk by chunk
    (hours of them: each chunk is written and dropped), atomically: nothing at ``path`` until it is whole."""
    with atomic_directory(path, overwrite=overwrite) as tmp:
        imu = tmp / "mav0" / "imu0"
        imu.mkdir(parents=True)
        dump_yaml(imu / "sensor.yaml", _imu_noise_yaml(noise, rate_hz, comment))
        with open(imu / "data.csv", "w", encoding="utf-8") as f:
            f.write(IMU_HEADER + "\n")
            for chunk in chunks:
                f.write(imu_rows(chunk))
    return Path(path)


def _write_images(frames: CameraFrames, cam: Path) -> None:
    lines = ["#timestamp [ns],filename"]
    for t, image in zip(frames.t.tolist(), frames.images, strict=True):
        write_png(cam / "data" / f"{t}.png", image)
        lines.append(f"{t},{t}.png")
    (cam / "data.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _matrix(T: np.ndarray) -> dict[str, Any]:
    return {"cols": 4, "rows": 4, "data": [float(v) for v in np.asarray(T).reshape(-1)]}


def _camera_sensor_yaml(frames: CameraFrames, truth: SensorTruth | None) -> dict[str, Any]:
    height, width = frames.images.shape[1:]
    data: dict[str, Any] = {"sensor_type": "camera", "comment": "written by vical", "rate_hz": median_rate_hz(frames.t)}
    data["resolution"] = [int(width), int(height)]
    if truth is not None:
        cam = truth.camera
        if np.any(cam.distortion_center_offset != 0):
            warnings.warn(
                "EuRoC's pinhole models have the distortion centre at the principal point; the camera's "
                f"distortion_center_offset {cam.distortion_center_offset.tolist()} px is not written",
                stacklevel=3,
            )
        data["T_BS"] = _matrix(invert_transform(truth.T_cam_imu))
        kalibr = kalibr_intrinsics(cam)  # as Kalibr names the models; the distortions in EuRoC's words
        data["camera_model"] = kalibr["camera_model"]
        data["intrinsics"] = kalibr["intrinsics"]
        data["distortion_model"] = EUROC_DISTORTION_NAMES.get(kalibr["distortion_model"], kalibr["distortion_model"])
        data["distortion_coefficients"] = kalibr["distortion_coeffs"]
        data["timeshift_cam_imu"] = float(truth.time_offset)
        if truth.line_delay > 0:
            data[LINE_DELAY_KEY] = camera_entry(cam, line_delay=truth.line_delay)[LINE_DELAY_KEY]
    return data


def _imu_sensor_yaml(rec: Recording) -> dict[str, Any]:
    if rec.truth is None:
        return _imu_noise_yaml(None, median_rate_hz(rec.imu.t), "written by vical")
    return _imu_noise_yaml(rec.truth.imu_noise, rec.truth.imu_noise.rate_hz, "written by vical")


class EurocStreamWriter:
    """Writes an EuRoC folder while the data arrives, so that a kill at any moment leaves a readable one.

    The folder holds every IMU sample and every frame handed over before the kill: an image is
    written to a temporary name and renamed, then listed in ``cam0/data.csv``, then its detections
    go to ``cam0/corners.csv``; each batch of CSV lines is one ``write`` to a file opened for
    appending, so no reader sees half a line, and a write the disk cuts short (full, or a file-size limit) is
    cut back to the lines before it and raises ``RecordingWriteError``. ``read_euroc`` reads it like any EuRoC folder (a
    frame killed between its listing and its detections reads as undetected). Data is flushed to
    the disk every ``sync_every`` frames and by ``close``.

    Args:
        path: the folder to create (``path/mav0/...``); an existing one is refused unless ``overwrite``.
        image_size: (width, height) [px] of the frames, written to ``cam0/sensor.yaml``.
        camera_rate_hz, imu_rate_hz: the streams' nominal rates (``sensor.yaml``).
        imu_noise: the IMU's noise settings for ``imu0/sensor.yaml`` (the calibrator reads them), or None.
        overwrite: replace an existing folder (it is removed first).
        sync_every: frames between flushes to the disk.
    """

    def __init__(
        self,
        path: str | os.PathLike,
        image_size: tuple[int, int],
        camera_rate_hz: float,
        imu_rate_hz: float,
        imu_noise: ImuNoise | None = None,
        overwrite: bool = False,
        sync_every: int = 20,
    ) -> None:
        final = check_can_write_dir(path, overwrite)
        if final.exists():
            shutil.rmtree(final)
        self.path = final
        self.root = final / "mav0"
        cam, imu = self.root / "cam0", self.root / "imu0"
        (cam / "data").mkdir(parents=True)
        imu.mkdir(parents=True)
        width, height = (int(v) for v in image_size)
        self.image_size = (width, height)
        camera = {"sensor_type": "camera", "comment": "written by vical-collect", "rate_hz": float(camera_rate_hz),
                  "resolution": [width, height]}  # fmt: skip
        dump_yaml(cam / "sensor.yaml", camera)
        dump_yaml(imu / "sensor.yaml", _imu_noise_yaml(imu_noise, imu_rate_hz, "written by vical-collect"))
        write_text_atomic(cam / "data.csv", "#timestamp [ns],filename\n")
        write_text_atomic(cam / "corners.csv", CORNER_HEADER + "\n")
        write_text_atomic(imu / "data.csv", IMU_HEADER + "\n")
        csvs = {"images": cam / "data.csv", "corners": cam / "corners.csv", "imu": imu / "data.csv"}
        self._files = {name: os.open(p, os.O_WRONLY | os.O_APPEND) for name, p in csvs.items()}
        self.frames = 0
        self.imu_samples = 0
        self._sync_every = int(sync_every)

    def add_imu(self, imu: ImuSamples) -> None:
        """Append IMU samples (stamp order, after those already written)."""
        if len(imu):
            self._append("imu", imu_rows(imu))
            self.imu_samples += len(imu)

    def add_frame(self, t_ns: int, image: np.ndarray, corners: np.ndarray, ids: np.ndarray) -> None:
        """Append one frame: its grey ``image`` (H, W), its detections (K, 2) [px] and point ids (K,)."""
        height, width = np.shape(image)[:2]
        if (width, height) != self.image_size:
            raise ValueError(f"frame {t_ns}: {width} x {height} px image, but the recording is {self.image_size}")
        t = int(t_ns)
        try:
            with atomic_file(self.root / "cam0" / "data" / f"{t}.png") as tmp:
                write_png(tmp, image)
        except OSError as err:  # the image is not there (atomic), nor listed: the folder stays readable
            raise self._stopped(f"the image of frame {t}", err.strerror) from err
        self._append("images", f"{t},{t}.png\n")
        self._append("corners", corner_rows(t, np.asarray(corners).reshape(-1, 2), np.asarray(ids).reshape(-1)))
        self.frames += 1
        if self.frames % self._sync_every == 0:
            self.sync()

    def _append(self, name: str, text: str) -> None:
        data = text.encode("utf-8")
        fd = self._files[name]
        end = os.lseek(fd, 0, os.SEEK_END)
        written = 0
        try:
            while written < len(data):  # a short write goes on; the next says why the disk stopped
                count = os.write(fd, data[written:])
                if count == 0:
                    raise OSError(errno.EIO, "a write that wrote nothing")
                written += count
        except OSError as err:  # cut back what part of the lines went in: a reader sees whole lines only
            os.ftruncate(fd, end)
            raise self._stopped(f"{len(data)} bytes of {name}", err.strerror) from err

    def _stopped(self, what: str, cause: str | None) -> RecordingWriteError:
        return RecordingWriteError(
            f"{self.path}: the disk took no more ({what}: {cause}; is it full?); the {self.frames} frames and "
            f"{self.imu_samples} IMU samples before are whole"
        )

    def sync(self) -> None:
        """Flush everything written so far to the disk."""
        for fd in self._files.values():
            os.fsync(fd)

    def close(self) -> None:
        """Flush and close the files (the folder is readable at every moment before, too)."""
        if not self._files:
            return
        self.sync()
        for fd in self._files.values():
            os.close(fd)
        self._files = {}

    def __enter__(self) -> EurocStreamWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _imu_noise_yaml(noise: ImuNoise | None, rate_hz: float, comment: str) -> dict[str, Any]:
    data: dict[str, Any] = {"sensor_type": "imu", "comment": comment, "T_BS": _matrix(np.eye(4))}
    data["rate_hz"] = float(rate_hz)
    if noise is not None:
        data["gyroscope_noise_density"] = noise.gyro_noise_density
        data["gyroscope_random_walk"] = noise.gyro_random_walk
        data["accelerometer_noise_density"] = noise.accel_noise_density
        data["accelerometer_random_walk"] = noise.accel_random_walk
    return data


# ------------------------------------------------------------------------------------ read
def read_euroc(
    path: str | os.PathLike,
    target: Target,
    detector: ImageDetector | None = None,
    keep_images: bool = True,
    gyro_unit: str = "rad/s",
    accel_unit: str = "m/s^2",
    cameras: Sequence[str] | None = None,
) -> Recording:
    """Read an EuRoC folder (``path`` or ``path/mav0``) with every camera folder in it (``cam0``, ``cam1``, ...), or
    with cam0 and ``cameras`` (``vical.io.board_points.chosen_cameras``).

    Corners come from ``detector`` when given, else from ``camN/corners.csv`` when present,
    else the frames have no detections. Images are checked against the resolution in their
    ``camN/sensor.yaml`` (or their first image); ``metadata["image_sizes"]`` holds each camera's
    (W, H) [px] and ``metadata["image_size"]`` cam0's. Every image is decoded for that check (and
    for detection). ``keep_images=False`` drops each decoded image after use, bounding memory on
    long sequences. Cameras at different frame rates get a ``FormatWarning`` naming them.
    """
    root = find_euroc_root(path)
    if root is None:
        raise FormatError(f"{path} is not an EuRoC folder: neither it nor its mav0/ holds cam0/data.csv")
    names = chosen_cameras(camera_folders(root), cameras, str(path))
    read = {name: _read_camera(root, name, target, detector, keep_images) for name in names}
    check_camera_rates(str(root), {name: frames.t for name, (frames, _, _) in read.items()})
    frames, truth, size = read.pop("cam0")
    sizes = {"cam0": size} | {name: c[2] for name, c in read.items()}
    return Recording(
        imu=_read_imu(root, gyro_unit, accel_unit),
        frames=frames,
        target=target,
        truth=truth,
        metadata={"source": "euroc", "path": str(Path(path).resolve()), "image_size": size, "image_sizes": sizes},
        other_frames={name: c[0] for name, c in read.items()},
        other_truths={name: c[1] for name, c in read.items() if c[1] is not None},
    )


def camera_folders(root: Path) -> list[str]:
    """The camera folders of an EuRoC ``mav0`` (``cam0``, ``cam1``, ... holding ``data.csv``), in order."""
    numbers = sorted(
        int(d.name[3:]) for d in root.iterdir() if CAMERA_FOLDER.fullmatch(d.name) and (d / "data.csv").is_file()
    )
    missing = sorted(set(range(numbers[-1] + 1)) - set(numbers))
    if missing:
        raise FormatError(
            f"{root}: camera folders {', '.join(f'cam{n}' for n in numbers)} but no cam{missing[0]}/data.csv; "
            "number the cameras cam0, cam1, ... without gaps"
        )
    return [f"cam{n}" for n in numbers]


def _read_camera(
    root: Path, name: str, target: Target, detector: ImageDetector | None, keep_images: bool
) -> tuple[CameraFrames, SensorTruth | None, list[int]]:
    """One camera folder's frames, its reference calibration (or None) and its image size [W, H]."""
    truth, resolution = _read_reference(root, name)
    t, files = _read_image_list(root / name)
    images = ((str(p), read_gray(p)) for p in files)
    frames = frames_from_images(t, images, target, detector, keep_images, resolution, desc=f"EuRoC {name}")
    if detector is None and (root / name / "corners.csv").is_file():
        frames = _attach_corners(frames, read_corners_csv(root / name / "corners.csv", target), root / name)
    # Every image was checked against this size, so the frames' corners belong to it.
    width, height = resolution or read_gray(files[0]).shape[::-1]
    return frames, truth, [int(width), int(height)]


def _read_image_list(cam: Path) -> tuple[np.ndarray, list[Path]]:
    csv = cam / "data.csv"
    rows, lines = read_rows(csv, 2)
    if not rows:
        raise CsvFormatError(f"{csv} lists no images")
    t = parse_times(rows, lines, csv)
    names = np.array([r[1] for r in rows])
    try:
        order = sort_and_dedupe(t, names[:, None], str(csv), np.asarray(lines))
        check_sampling(t[order], str(csv))
    except FormatError as exc:
        raise CsvFormatError(str(exc)) from exc
    return t[order], [cam / "data" / str(n) for n in names[order]]


def _read_imu(root: Path, gyro_unit: str, accel_unit: str) -> ImuSamples:
    csv = root / "imu0" / "data.csv"
    if not csv.is_file():
        warn(f"{csv} is missing: the recording has no IMU data (intrinsic calibration only)")
        return ImuSamples(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))
    try:
        return read_imu_csv(csv, gyro_unit, accel_unit)
    except EmptyCsvError:
        warn(f"{csv} holds no samples: the recording has no IMU data (intrinsic calibration only)")
    return ImuSamples(np.zeros(0, np.int64), np.zeros((0, 3)), np.zeros((0, 3)))


def _read_reference(root: Path, name: str) -> tuple[SensorTruth | None, tuple[int, int] | None]:
    """Reference calibration of camera ``name`` from the sensor.yaml files (None unless complete) and its resolution."""
    cam_yaml, imu_yaml = root / name / "sensor.yaml", root / "imu0" / "sensor.yaml"
    if not cam_yaml.is_file():
        return None, None
    data = load_mapping(cam_yaml, KalibrFormatError)
    resolution = None
    if "resolution" in data:
        resolution = tuple(
            int(v) for v in as_floats(data["resolution"], 2, "resolution", str(cam_yaml), KalibrFormatError)
        )
    has_noise = imu_yaml.is_file() and "gyroscope_noise_density" in load_mapping(imu_yaml, KalibrFormatError)
    if "intrinsics" not in data or not has_noise:
        return None, resolution
    camera, T_cam_imu, shift = read_camchain(cam_yaml)
    if T_cam_imu is None:
        return None, resolution
    line_delay = read_line_delay(cam_yaml) or 0.0
    truth = SensorTruth(
        camera, T_cam_imu, 0.0 if shift is None else shift, read_imu_yaml(imu_yaml), line_delay=line_delay
    )
    return truth, (camera.width, camera.height)


def _attach_corners(frames: CameraFrames, detections: CameraFrames, cam: Path) -> CameraFrames:
    """``frames`` with the corner CSV's detections matched by timestamp (frames not listed: none)."""
    index = {t: k for k, t in enumerate(detections.t.tolist())}
    unknown = sorted(set(index) - set(frames.t.tolist()))
    if unknown:
        raise CsvFormatError(f"{cam / 'corners.csv'}: timestamp {unknown[0]} ns matches no image in data.csv")
    empty = (np.zeros((0, 2)), np.zeros(0, np.int64))
    pairs = [
        (detections.corners[index[t]], detections.ids[index[t]]) if t in index else empty for t in frames.t.tolist()
    ]
    return CameraFrames(frames.t, [p[0] for p in pairs], [p[1] for p in pairs], frames.images, frames.names)
