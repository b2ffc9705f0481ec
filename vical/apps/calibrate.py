"""``vical-calibrate``: calibrate a saved recording and write Kalibr-compatible files and a report.

Examples::

    vical-calibrate runs/rec0 --task intrinsic --model radtan
    vical-calibrate runs/rec0 --task extrinsic --intrinsics camchain.yaml --imu-yaml imu.yaml
    vical-calibrate runs/rec0 --task joint --out calib/
    vical-calibrate stereo.bag --image-topic /left/image_raw,/right/image_raw --target target.yaml --out rig/
    vical-calibrate euroc/ --cameras cam1 --target target.yaml --out cam1/

Sources: a vical recording directory, an EuRoC folder, a ROS1 bag or a ROS 2 bag (its folder, or its
``.db3`` / ``.mcap`` file; corners detected in the images with the detector of the target's kind, with a
progress bar), a folder of images (intrinsic task only) or a corner CSV (+ ``--imu-csv``). Every source
except a recording directory needs ``--target`` (Kalibr target YAML).

Camera rigs: every camera the recording has (EuRoC ``camN`` folders, one bag image topic per
camera, a recording directory's other cameras) is calibrated, all in one graph with the IMU, or
those ``--cameras cam0,cam1`` names (``vical.apps.calibrate_rig``). A bag's image topics come from
``--image-topic`` (several times or comma-separated, cam0's first), else from the ``rostopic`` of
each camera of an ``--intrinsics`` camchain. The camchain written has a section per camera
(``T_cn_cnm1``, ``cam_overlaps``; every key of an ``--intrinsics`` camchain kept), ``results.txt`` a
section per camera and the relative poses, and each camera has a folder with its ``frames.csv`` and plots
(``cam0/frames.csv``, ``cam0/report.pdf``, ...).

Outputs in ``--out``: ``camchain.yaml`` (intrinsic) or ``camchain-imucam.yaml`` + ``imu.yaml`` (an
``--imu-yaml`` file kept whole, the calibration's noise and IMU intrinsics put in), ``results.txt``,
``frames.csv``, ``reprojection.png`` / ``imu.png`` / ``report.pdf``, written as one directory
atomically; an existing ``--out`` that holds files is refused unless ``--overwrite`` (which
replaces it whole). A summary table goes to the terminal, with the errors against the truth when
the recording carries it.

A result the data do not support (a setting the data prove wrong, a solve that never left its initial
guess: ``vical.calib.solve.plausibility``) fails with its likely cause; its files are kept for diagnosis,
marked as failed (``results.txt`` starts with ``FAILED:``, the camchain is named ``*.failed.yaml``). A
failure never replaces a good result: with ``--overwrite`` over one, the failed outputs go to
``<out>.failed`` and ``--out`` keeps what it held. User errors and failed calibrations print one line
``vical-calibrate: error: ...`` and exit with status 2.
"""

from __future__ import annotations

import argparse
import math
import sys
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from vical.apps.calibrate_outputs import one_camera_layout, write_outputs
from vical.apps.calibrate_rig import (
    camera_list,
    check_chain_topics,
    image_topics,
    rig_image_size,
    rig_problems,
    select_cameras,
    topic_list,
)
from vical.apps.cli import ArgumentParser, OutputError, argparse_main, check_creatable
from vical.apps.entry import run as run_command
from vical.calib.detection.aprilgrid import detect_aprilgrid, make_aprilgrid_detector
from vical.calib.detection.board_size import MAX_SAMPLE, board_size_hint
from vical.calib.detection.checkerboard import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.result import CalibrationResult
from vical.calib.solve.intrinsics import MIN_VIEWS, best_model, calibrate_intrinsics
from vical.calib.solve.nominal import nominal_T_cam_imu
from vical.calib.solve.pipeline import (
    RigCalibration,
    calibrate_rig,
)
from vical.calib.solve.plausibility import (
    accel_scale,
    board_scale,
    gyro_scale,
    implausibilities,
    likely_accel_unit,
    likely_gyro_unit,
    posed_frames,
    wrong_board_scale,
)
from vical.calib.solve.visual_inertial import GRAVITY_MAGNITUDE, ViOptions
from vical.data import DataError, ImuNoise, Recording, Target, median_rate_hz
from vical.data.imu_grade import GRADES, REAL_DATA_GRADE, ImuGrade, imu_grade
from vical.data.target import TargetError
from vical.geometry import CAMERA_MODELS, CameraModel, CameraModelError
from vical.io.atomic import remove_stale_temporaries
from vical.io.errors import FormatError, KalibrFormatError
from vical.io.kalibr import (
    LINE_DELAY_KEY,
    read_camchain,
    read_imu_grade,
    read_imu_intrinsics,
    read_imu_yaml,
    read_line_delay,
    read_target_yaml,
)
from vical.io.kalibr_chain import CAMERA_SECTION, CameraChain, check_chain_fits, read_chain
from vical.io.sources import detect_source, open_recording
from vical.io.vio_exports import VIO_FORMATS, check_exportable
from vical.io.yamlfile import load_mapping

APP = "vical-calibrate"
TASKS = ("intrinsic", "extrinsic", "joint", "two_stage")
# The command line's spelling of the calibrator's and readers' arguments that error messages name
# (``vical.config_checks.SettingError``): the one place where library parameters become flags.
FLAGS = {
    "gyro_unit": "--gyro-unit",
    "accel_unit": "--accel-unit",
    "image_size_px": "--image-size",
    "frame_stride": "--frame-stride",
    "memory_limit_mb": "--memory-limit",
    "max_time_offset": "--max-time-offset",
    "initial_time_offset": "timeshift_cam_imu in an --intrinsics camchain",
    "target": "--target",
    "image_topic": "--image-topic",
    "imu_topic": "--imu-topic",
    "imu_model": "--imu-model",
    "imu_grade": "--imu-grade",
    "cameras": "--cameras",
}


def _number(low: float, kind: type = float, closed: bool = True):
    """An argparse type: a finite number of ``kind`` >= ``low`` (> ``low`` unless ``closed``)."""
    what = "an integer" if kind is int else "a number"
    allowed = f"{what} {'>=' if closed else '>'} {low:g}"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}") from None
        if not (math.isfinite(value) and (value >= low if closed else value > low)):
            raise argparse.ArgumentTypeError(f"must be {allowed}, got {text!r}")
        return value

    return parse


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog=APP, description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="recording directory, EuRoC folder, ROS1 or ROS 2 bag, image folder or corner CSV")
    p.add_argument("--task", choices=TASKS, default="joint", help="what to calibrate (default: joint)")
    p.add_argument(
        "--model",
        choices=CAMERA_MODELS,
        default="radtan",
        help="lens model: pinhole with radtan or equidistant distortion, or the wide-angle ds (double sphere), "
        "eucm (extended unified), omni (unified, Kalibr's omni-none) or omni-radtan; default radtan",
    )
    p.add_argument(
        "--intrinsics", help="Kalibr camchain.yaml with the known intrinsics (extrinsic task), one section per camera"
    )
    p.add_argument("--imu-yaml", help="Kalibr imu.yaml with the IMU noise densities")
    p.add_argument("--target", help="Kalibr target YAML (needed unless the recording stores its target)")
    p.add_argument("--imu-csv", help="EuRoC-format IMU CSV to pair with a corner CSV")
    p.add_argument(
        "--image-topic",
        action="append",
        help="bag image topic; a rig's: several times or comma-separated, cam0's first (default: each --intrinsics "
        "camera's rostopic, else /cam0/image_raw)",
    )
    p.add_argument(
        "--cameras",
        type=camera_list,
        help="calibrate only these of the recording's cameras, e.g. cam0,cam1 or cam1 (default: every one)",
    )
    p.add_argument("--imu-topic", default="/imu0", help="bag IMU topic (default: /imu0)")
    p.add_argument(
        "--rate", type=_number(0, closed=False), default=10.0, help="frame rate [Hz] that timestamps an image folder"
    )
    p.add_argument("--gyro-unit", choices=("rad/s", "deg/s"), default="rad/s", help="gyro unit in CSVs and bags")
    p.add_argument("--accel-unit", choices=("m/s^2", "g"), default="m/s^2", help="accelerometer unit in CSVs and bags")
    p.add_argument(
        "--stored-corners",
        action="store_true",
        help="EuRoC folder: use its cam0/corners.csv instead of detecting corners in the images",
    )
    p.add_argument("--image-size", nargs=2, type=_number(1, int), metavar=("W", "H"), help="image size [px]")
    p.add_argument(
        "--huber", type=_number(0, closed=False), default=None, help="Huber kernel width in sigmas (robust to outliers)"
    )
    p.add_argument("--max-time-offset", type=_number(0), default=0.1, help="time-offset search half-width [s]")
    p.add_argument("--fixed-time-offset", action="store_true", help="do not estimate the time offset")
    p.add_argument(
        "--rolling-shutter",
        action="store_true",
        help="estimate each camera's rolling-shutter line delay with the time offset (without it: the --intrinsics "
        "camchain's line_delay_nanoseconds, else a global shutter)",
    )
    p.add_argument(
        "--imu-model",
        choices=("calibrated", "scale-misalignment"),
        default="calibrated",
        help="scale-misalignment: also estimate the IMU's scale factors and axis misalignment (Kalibr's model)",
    )
    p.add_argument(
        "--imu-grade",
        choices=tuple(GRADES),
        help="the IMU's scale and misalignment 1-sigma, counted in the uncertainty where the recording does not "
        f"determine them (default: the --imu-yaml's imu_grade keys, else {REAL_DATA_GRADE}; a simulated recording's "
        "own); calibrated: corrected readings",
    )
    p.add_argument("--g-sensitivity", action="store_true", help="with scale-misalignment: the gyro's g-sensitivity too")
    p.add_argument(
        "--frame-stride",
        type=_number(1, int),
        default=1,
        help="use every N-th frame with a target view (thins long recordings)",
    )
    p.add_argument(
        "--memory-limit",
        type=_number(0, closed=False),
        default=4000.0,
        help="[MB] refuse a solve that would need more (default 4000)",
    )
    p.add_argument(
        "--start", type=_number(0), default=0.0, help="[s] calibrate from this time after the recording's start"
    )
    p.add_argument(
        "--duration", type=_number(0, closed=False), help="[s] calibrate this much of the recording (default: all)"
    )
    p.add_argument(
        "--export",
        nargs="+",
        choices=VIO_FORMATS,
        default=[],
        help="also write the calibration as these VIO systems read it: vins-fusion (vins-fusion/config.yaml, "
        "cam0.yaml) and basalt (basalt/calibration.json); OpenVINS reads camchain-imucam.yaml and imu.yaml as they are",
    )
    p.add_argument("--out", default="calibration", help="output directory (default: ./calibration)")
    p.add_argument("--overwrite", action="store_true", help="replace an --out that holds files (as a whole)")
    p.add_argument("--no-report", action="store_true", help="skip the PNG/PDF plots")
    return p


class SizedDetector:
    """The corner detector of a target's kind, bound to the target; remembers the image size it saw
    and keeps a sample of the images spread over the sequence.

    Checkerboards go to ``detect_checkerboard``, aprilgrids to ``detect_aprilgrid`` (one aruco
    detector reused over the sequence). Sources that decode images without keeping them in
    memory still tell the calibrator the image size this way, and the sample lets
    ``board_size_hint`` check the board's size.
    """

    def __init__(self, target: Target) -> None:
        self.target = target
        self.size: tuple[int, int] | None = None  # (W, H) [px] of the images seen
        self.sample: list[np.ndarray] = []  # every ``_step``-th image seen, at most 2 MAX_SAMPLE
        self._seen, self._step = 0, 1
        self._aruco = make_aprilgrid_detector() if target.kind == "aprilgrid" else None

    def _keep(self, image: np.ndarray) -> None:
        if self._seen % self._step == 0:
            self.sample.append(image)
            if len(self.sample) > 2 * MAX_SAMPLE:  # thin to every other one: the sample stays evenly spread
                self.sample, self._step = self.sample[::2], 2 * self._step
        self._seen += 1

    def __call__(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corners (K, 2) [px] and Kalibr point ids (K,) found in a (H, W) uint8 grey image."""
        self.size = (int(image.shape[1]), int(image.shape[0]))
        self._keep(image)
        if self._aruco is not None:
            return detect_aprilgrid(image, self.target, detector=self._aruco)
        return detect_checkerboard(image, self.target)


def load_source(args: argparse.Namespace, chain: CameraChain | None = None) -> tuple[Recording, SizedDetector | None]:
    """Open ``args.recording`` (detecting corners in its images); return it with the detector that saw the
    images (None for sources whose corners were stored).

    A bag's image topics: ``--image-topic``'s, else those of the ``--intrinsics`` camchain ``chain``."""
    target = read_target_yaml(args.target) if args.target else None
    kind = detect_source(args.recording)
    given = topic_list(args.image_topic)
    if kind == "bag" and chain is not None and not given:
        check_chain_topics(args.recording, chain, args.intrinsics)
    if args.task != "intrinsic" and (kind == "image_folder" or (kind == "corners_csv" and not args.imu_csv)):
        raise CalibrationError(_no_imu_message(kind, args))  # before decoding a single image
    detect = kind in ("euroc", "bag", "image_folder") and not (kind == "euroc" and args.stored_corners)
    detector = SizedDetector(target) if detect and target is not None else None
    rec = open_recording(
        args.recording,
        target,
        detector=detector,
        imu_csv=args.imu_csv,
        image_topic=image_topics(given, chain, args.cameras),
        imu_topic=None if kind == "bag" and args.task == "intrinsic" else args.imu_topic,
        rate_hz=args.rate,
        gyro_unit=args.gyro_unit,
        accel_unit=args.accel_unit,
        cameras=args.cameras,
    )
    rec = time_window(rec, args.start, args.duration)
    if args.task != "intrinsic" and len(rec.imu) < 2:
        raise CalibrationError(_no_imu_message(kind, args))
    return rec, detector


def time_window(rec: Recording, start: float, duration: float | None) -> Recording:
    """The part of ``rec`` from ``start`` [s] after its first timestamp, ``duration`` [s] long (None: to its end).

    A window that holds no frame is refused in one line with the recording's span.
    """
    if start == 0 and duration is None:
        return rec
    span = (rec.t_end - rec.t0) / 1e9
    t0 = rec.t0 + round(start * 1e9)
    t1 = rec.t_end if duration is None else t0 + round(duration * 1e9)
    cut = rec.window(t0, t1)
    if not len(cut.frames):
        asked = f"--start {start:g} s" + ("" if duration is None else f" --duration {duration:g} s")
        raise CalibrationError(
            f"{asked} holds no camera frame: the recording spans 0..{span:.2f} s from its first timestamp; "
            "choose a window inside it"
        )
    return cut


def _no_imu_message(kind: str, args: argparse.Namespace) -> str:
    fixes = {
        "image_folder": "an image folder holds no IMU data",
        "corners_csv": "a corner CSV holds no IMU data: pass the IMU as --imu-csv imu.csv (EuRoC format)",
        "euroc": "its imu0/data.csv is missing or empty",
        "corner_folder": "it holds no imu0.csv (or imu0/data.csv): put the IMU there or pass it as --imu-csv",
        "bag": f"its topic {args.imu_topic} has no IMU messages: choose the IMU topic with --imu-topic",
        "recording": "the recording holds no IMU samples",
    }
    return (
        f"{args.recording}: the {args.task} task needs IMU data, but {fixes[kind]}; "
        "run --task intrinsic for the camera alone"
    )


def _image_size(args, rec: Recording, camera: CameraModel | None, seen: tuple[int, int] | None):
    """(W, H) [px] of the images: as decoded, else ``--image-size``, else the recorded camera's or the
    ``--intrinsics`` one's; None if unknown.

    A ``--image-size`` or an ``--intrinsics`` resolution that differs from the images is refused: the
    corners were detected in those images.
    """
    images = rec.frames.images
    decoded = seen or (None if images is None else (int(images.shape[2]), int(images.shape[1])))
    decoded = decoded or (tuple(rec.metadata["image_size"]) if "image_size" in rec.metadata else None)
    given = tuple(args.image_size) if args.image_size else None
    if decoded and given and decoded != given:
        raise CalibrationError(
            f"--image-size {given[0]} {given[1]} differs from the images' size {decoded[0]} x {decoded[1]} px; "
            "leave --image-size out (the images give the size)"
        )
    recorded = None if rec.truth is None else (rec.truth.camera.width, rec.truth.camera.height)
    size = decoded or given or recorded
    if camera is not None:
        _check_resolution(args.intrinsics, camera, size, rec.frames)
    return size or (None if camera is None else (camera.width, camera.height))


def _check_resolution(path: str, camera: CameraModel, size: tuple[int, int] | None, frames) -> None:
    """Refuse ``--intrinsics`` of another resolution than the images' (or than the corners' extent)."""
    resolution = f"--intrinsics {path} calibrates {camera.width} x {camera.height} px images"
    fix = "give the camchain of this camera at this resolution"
    if size is not None and (camera.width, camera.height) != size:
        raise CalibrationError(f"{resolution}, but the images are {size[0]} x {size[1]} px; {fix}")
    corners = [c for c in frames.corners if len(c)]
    u, v = np.concatenate(corners).max(axis=0) if corners else (0.0, 0.0)
    if u > camera.width or v > camera.height:
        raise CalibrationError(f"{resolution}, but corners were detected up to u = {u:.0f} px, v = {v:.0f} px; {fix}")


def _read_chain(path: str | None) -> CameraChain | None:
    """The cameras of an ``--intrinsics`` camchain; None without one or for a flat one-camera file (EuRoC's
    ``sensor.yaml``: ``read_camchain`` reads it)."""
    if not path or not any(
        isinstance(k, str) and CAMERA_SECTION.fullmatch(k) for k in load_mapping(path, KalibrFormatError)
    ):
        return None
    return read_chain(path)


def _known_intrinsics(args) -> tuple[CameraModel | None, np.ndarray | None, float | None]:
    """Camera, T_cam_imu and time shift from ``--intrinsics`` (each may be None)."""
    if args.intrinsics:
        return read_camchain(args.intrinsics)
    return None, None, None


def _declared_grade(args) -> ImuGrade | None:
    """The IMU grade ``--imu-grade`` or the ``--imu-yaml`` declares, or None."""
    if args.imu_grade:
        return imu_grade(args.imu_grade)
    return read_imu_grade(args.imu_yaml) if args.imu_yaml else None


def _imu_noise(args, rec: Recording) -> ImuNoise:
    if args.imu_yaml:
        return read_imu_yaml(args.imu_yaml)
    if rec.truth is not None:
        return rec.truth.imu_noise
    print("note: no --imu-yaml given; using the paper's IMU noise densities", file=sys.stderr)
    return ImuNoise()


def holds_result(out: Path) -> bool:
    """Whether ``out`` holds a calibration that did not fail (its camchain is not ``*.failed.yaml``)."""
    return any((out / name).is_file() for name in ("camchain.yaml", "camchain-imucam.yaml"))


def failed_out(out: Path) -> Path:
    """Where a failed calibration goes when ``out`` holds a good one (``--overwrite`` never replaces it by a
    failure): ``<out>.failed``, replaced whole."""
    return out.with_name(out.name + ".failed")


RATE_TOLERANCE = 0.1  # an imu.yaml rate this far (relative) from the samples' is named


def _at_data_rate(args, noise: ImuNoise, rec: Recording) -> tuple[ImuNoise, str | None]:
    """``noise`` with the samples' rate and a warning when ``--imu-yaml``'s rate is not it (the calibration does
    not read the rate; the output ``imu.yaml`` gets the samples'); ``noise`` as given otherwise."""
    if not args.imu_yaml or len(rec.imu) < 2:
        return noise, None
    rate = median_rate_hz(rec.imu.t)
    if abs(noise.rate_hz - rate) <= RATE_TOLERANCE * rate:
        return noise, None
    return replace(noise, rate_hz=rate), (
        f"--imu-yaml {args.imu_yaml} says update_rate {noise.rate_hz:g} Hz, but the IMU samples come at "
        f"{rate:.4g} Hz; the output imu.yaml says {rate:.4g} Hz"
    )


class CalibrationFailed(CalibrationError):
    """The solve ended, but its data do not support the result; the outputs were written marked as failed."""


def check_out(out: Path, overwrite: bool, inputs: list[str | None]) -> None:
    """Refuse, before any work, an ``--out`` that is a file, holds files (unless ``overwrite``), cannot be
    made, or holds one of the ``inputs`` (``--overwrite`` would replace it)."""
    if out.exists() and not out.is_dir():
        raise OutputError(f"--out {out} is a file; give a directory")
    remove_stale_temporaries(out.parent, out.name)
    if out.is_dir() and any(out.iterdir()) and not overwrite:
        raise OutputError(
            f"--out {out} already holds files; choose another directory or pass --overwrite to replace it whole"
        )
    inside = [p for p in inputs if p and out.resolve() in (Path(p).resolve(), *Path(p).resolve().parents)]
    if inside:
        raise OutputError(f"--out {out} holds the input {inside[0]}, which the outputs would replace; choose another")
    check_creatable("--out", out)


def run(args: argparse.Namespace) -> CalibrationResult | RigCalibration:
    """Calibrate as the parsed arguments say, write the outputs and print the summary.

    Returns the camera's result for a one-camera calibration (``one_camera_layout``), else the rig's. Raises
    ``CalibrationFailed`` after writing the outputs (marked as failed) when the data do not support the result.
    """
    if args.g_sensitivity and args.imu_model == "calibrated":
        raise CalibrationError("--g-sensitivity needs --imu-model scale-misalignment")
    options = ViOptions(  # first: a bad option fails before the recording is read
        estimate_time_offset=not args.fixed_time_offset,
        max_time_offset=args.max_time_offset,
        huber_k=args.huber,
        frame_stride=args.frame_stride,
        memory_limit_mb=args.memory_limit,
        imu_model=args.imu_model,
        g_sensitivity=args.g_sensitivity,
        imu_intrinsics=read_imu_intrinsics(args.imu_yaml) if args.imu_yaml else None,
        imu_grade=_declared_grade(args),
        rolling_shutter=args.rolling_shutter,
    )
    out = Path(args.out)
    inputs = [args.recording, args.target, args.intrinsics, args.imu_yaml, args.imu_csv]
    check_out(out, args.overwrite, inputs)
    chain = _read_chain(args.intrinsics)
    rec, detector = load_source(args, chain)
    hint = _board_size_hint(args, rec, detector)
    names = select_cameras(rec, args.cameras, args.recording, detect_source(args.recording))
    one = one_camera_layout(names, chain)
    setup = _one_camera_setup(args, rec, detector) if one else _rig_setup(args, rec, names, chain)
    _check_known_intrinsics(args, names, chain, setup, one)
    sizes = {s.size for s in setup.values() if s.size is not None}
    for vio_format in args.export:  # before the solve: a format that cannot hold the result
        for s in setup.values():
            lens = s.camera if s.camera is not None else args.model
            check_exportable(vio_format, lens, len(names), args.task, sizes)
    noise = None if args.task == "intrinsic" else _imu_noise(args, rec)
    options = options.with_default_grade(rec.truth.imu_grade if rec.truth is not None else None)
    noise, rate_note = (None, None) if noise is None else _at_data_rate(args, noise, rec)
    known = {n: s.camera for n, s in setup.items() if s.camera is not None}
    guesses = {n: s.T_cam_imu for n, s in setup.items() if s.T_cam_imu is not None}
    offsets = {n: s.time_shift for n, s in setup.items() if s.time_shift is not None}
    delays = {n: s.line_delay for n, s in setup.items() if s.line_delay is not None}
    _check_line_delays(args, delays, setup, rec)
    results = calibrate_rig(
        {n: rec.frames_of(n) for n in names}, rec.imu, rec.target, args.task, args.model,
        {n: s.size for n, s in setup.items()}, noise, known if args.task in ("intrinsic", "extrinsic") else None,
        guesses, offsets, options, line_delays=delays,
    ).results  # fmt: skip
    said = [w for w in (hint, rate_note) if w] + ignored_flags(args, known)  # said once, with the first camera's
    if said:
        results[names[0]] = replace(results[names[0]], warnings=[*said, *results[names[0]].warnings])
    failure = _failure_line(results, guesses, rec, args, one)
    written = failed_out(out) if failure and holds_result(out) else out
    write_outputs(written, results, rec, args, noise, chain, failure)
    if failure:
        kept = "" if written == out else f"; {out} keeps the result it held"
        raise CalibrationFailed(f"{failure}; the outputs in {written} are marked as failed{kept}")
    return results["cam0"] if one else RigCalibration(results)


# What only the camera-IMU tasks read: the intrinsic task calibrates the camera alone.
IMU_FLAGS = ("imu_yaml", "imu_csv", "imu_topic", "gyro_unit", "accel_unit", "max_time_offset", "fixed_time_offset",
             "imu_model", "imu_grade", "g_sensitivity")  # fmt: skip


def ignored_flags(args: argparse.Namespace, known: dict[str, CameraModel]) -> list[str]:
    """A warning per flag the task does not read, or that a given file overrides (the flags left at their
    defaults say nothing)."""
    defaults = build_parser()
    given = [d for d in IMU_FLAGS if getattr(args, d) != defaults.get_default(d)]
    if args.task == "intrinsic":
        return [f"{_spelled(d, getattr(args, d))} is ignored: the intrinsic task calibrates the camera alone"
                for d in given]  # fmt: skip
    models = sorted({c.distortion for c in known.values()})
    if args.task == "extrinsic" and args.model != defaults.get_default("model") and args.model not in models:
        return [
            f"--model {args.model} is ignored: the extrinsic task keeps the --intrinsics camera "
            f"({', '.join(models)}); calibrate it with --task joint to fit another model"
        ]
    return []


def _spelled(dest: str, value) -> str:
    """A flag as typed: ``--max-time-offset 0.05``; a switch alone."""
    flag = "--" + dest.replace("_", "-")
    return flag if value is True else f"{flag} {value}"


@dataclass(frozen=True)
class _CameraSetup:
    """What the command line and ``--intrinsics`` say about one camera: its intrinsics, ``T_cam_imu``, time
    shift and line delay (each None where not given) and its images' size."""

    camera: CameraModel | None
    T_cam_imu: np.ndarray | None
    time_shift: float | None
    size: tuple[int, int] | None
    line_delay: float | None = None


def _one_camera_setup(args, rec: Recording, detector: SizedDetector | None) -> dict[str, _CameraSetup]:
    """``cam0``'s setup from a one-camera ``--intrinsics`` file (EuRoC's ``sensor.yaml``, a camchain of one)."""
    camera, T_guess, shift = _known_intrinsics(args)
    size = _image_size(args, rec, camera, None if detector is None else detector.size)
    line_delay = read_line_delay(args.intrinsics) if args.intrinsics else None
    return {"cam0": _CameraSetup(camera, T_guess, shift, size, line_delay)}


def _rig_setup(args, rec: Recording, names: list[str], chain: CameraChain | None) -> dict[str, _CameraSetup]:
    """Each camera's setup from the ``--intrinsics`` camchain ``chain``, which must fit the recording (its cameras,
    their resolutions)."""
    if args.intrinsics and chain is None:
        raise CalibrationError(
            f"--intrinsics {args.intrinsics} describes one camera without a camN section; calibrating "
            f"{', '.join(names)} needs a Kalibr camchain with a section per camera (cam0, cam1, ...)"
        )
    if chain is not None:
        check_chain_fits(chain, args.intrinsics, rec, args.cameras)
    known = {n: chain[n] for n in names if chain is not None and n in chain.names}
    setup = {}
    for n in names:
        given = known.get(n)
        size = rig_image_size(args, rec, n, given)
        if given is None:
            setup[n] = _CameraSetup(None, None, None, size)
        else:
            setup[n] = _CameraSetup(given.camera, given.T_cam_imu, given.timeshift_cam_imu, size, given.line_delay)
    return setup


def _check_line_delays(args, delays: dict[str, float], setup: dict[str, _CameraSetup], rec: Recording) -> None:
    """A given line delay whose readout (times the image height) lasts longer than the frame interval is no camera's."""
    for name, delay in delays.items():
        frames, size = rec.frames_of(name), setup[name].size
        if size is None or len(frames) < 2:
            continue
        readout, interval = delay * size[1], float(np.median(np.diff(frames.t))) / 1e9
        if readout > interval:
            raise CalibrationError(
                f"--intrinsics {args.intrinsics}: {name}'s {LINE_DELAY_KEY} {delay * 1e9:g} gives a readout of "
                f"{readout * 1e3:.1f} ms over its {size[1]} rows, longer than the {interval * 1e3:.1f} ms between its "
                "frames; give the line delay in nanoseconds per row (e.g. 30000 for a 14 ms readout of 480 rows)"
            )


def _check_known_intrinsics(args, names: list[str], chain, setup: dict[str, _CameraSetup], one: bool) -> None:
    """The extrinsic task needs every camera's intrinsics."""
    unknown = [n for n in names if setup[n].camera is None]
    if args.task != "extrinsic" or not unknown:
        return
    if one:
        raise CalibrationError("the extrinsic task needs the intrinsics: pass --intrinsics camchain.yaml")
    where = f"--intrinsics {args.intrinsics} has no {unknown[0]}" if chain else "no --intrinsics given"
    raise CalibrationError(
        f"the extrinsic task needs the intrinsics of every camera it calibrates ({', '.join(names)}), but "
        f"{where}; pass a camchain with a section per camera, or choose the cameras with --cameras"
    )


def _board_size_hint(args, rec: Recording, detector: SizedDetector | None) -> str | None:
    """A warning when the sampled images show a checkerboard of another size than ``--target``'s; an error
    when the board was then found in too few frames to calibrate."""
    hint = board_size_hint(detector.sample, rec.target) if detector is not None else None
    if hint is None:
        return None
    message = hint.message(f"--target {args.target}")
    seen = np.count_nonzero(rec.frames.num_detections)
    if seen < MIN_VIEWS:
        raise CalibrationError(f"the board was found in {seen} of {len(rec.frames)} images: {message}")
    return message


def _failure_line(results: dict[str, CalibrationResult], guesses: dict, rec: Recording, args, one: bool) -> str | None:
    """Why the calibration failed, or None: what the data prove wrong in the settings, and what makes a result
    untrustworthy (``implausibilities``; in a rig, each problem with the cameras that show it)."""
    first = next(iter(results))
    proven = wrong_settings(results[first], rec.frames_of(first), rec, args)
    if one:
        problems = implausibilities(results[first], guesses.get(first, nominal_T_cam_imu()))
    else:
        found = rig_problems(results, guesses)
        problems = [] if found is None else [found[0]]
    if not problems and not proven:
        return None
    lens = (
        None if proven else next(filter(None, (lens_cause(r, rec.frames_of(n), rec) for n, r in results.items())), None)
    )
    return _failure(problems, proven, lens)


def _failure(problems: list[str], proven: list[str], lens: str | None = None) -> str | None:
    """The failure line: what the data prove wrong, each with its fix, and what makes the result untrustworthy
    (with the likely cause when nothing was proven: ``lens`` where another lens model fits, else the usual ones);
    None when nothing is wrong."""
    if not problems and not proven:
        return None
    if proven:
        return f"the calibration failed: {'; '.join(proven + problems)}"
    causes = (
        f"likely cause: {lens}"
        if lens
        else "likely causes: the lens model (--model), or a --target file that does not describe the board"
    )
    return f"the calibration failed: {'; '.join(problems)}; {causes}"


def lens_cause(result: CalibrationResult, frames, rec: Recording) -> str | None:
    """Where the result's lens model does not fit its corners and another does: which, with both fits and the
    option that uses it; None otherwise. The intrinsic stage compared the models where its model did not fit
    (``CalibrationResult.model_fits``); the extrinsic task, which has none, compares them on its frames now."""
    fits = result.model_fits
    if fits is None and result.task == "extrinsic":
        camera = result.camera
        try:
            fits = calibrate_intrinsics(frames, rec.target, camera.distortion, (camera.width, camera.height)).model_fits
        except (CalibrationError, CameraModelError):
            return None
    if not fits:
        return None
    used, best = result.camera.distortion, best_model(fits)
    if best == used:
        return None
    fix = (
        f"calibrate the intrinsics with --task intrinsic --model {best} and give them as --intrinsics"
        if result.task == "extrinsic"
        else f"pass --model {best}"
    )
    return (
        f"the lens model: {best} fits these corners with {fits[best]:.3g} px rms against {used}'s "
        f"{fits[used]:.3g} px: {fix}"
    )


def wrong_settings(result: CalibrationResult, frames, rec: Recording, args) -> list[str]:
    """What the data prove wrong in the settings of a camera-IMU calibration of the camera of ``frames``, each with
    the option that fixes it (``vical.calib.solve.plausibility``); empty for a camera-only result."""
    if result.imu_residuals is None:
        return []
    found = []
    posed = result.frame_poses or posed_frames(frames, rec.target, result.camera)
    scale = gyro_scale(posed, rec.imu)
    unit = likely_gyro_unit(scale, args.gyro_unit)
    if unit == "deg/s":
        found.append(f"the gyro reads {scale:.1f}x the rotation the camera sees: it logs deg/s; pass --gyro-unit deg/s")
    elif unit == "rad/s":
        found.append(f"the gyro reads 1/{1 / scale:.1f} of the rotation the camera sees: it logs rad/s; leave out "
                     "--gyro-unit deg/s")  # fmt: skip
    accel = accel_scale(rec.imu)
    unit = likely_accel_unit(accel, args.accel_unit)
    if unit == "g":
        found.append(f"the accelerometer reads {accel * GRAVITY_MAGNITUDE:.3g} m/s^2 in the median where gravity "
                     f"alone is {GRAVITY_MAGNITUDE:g}: it logs g; pass --accel-unit g")  # fmt: skip
    elif unit == "m/s^2":
        found.append(f"the accelerometer reads {accel:.3g} g in the median where gravity alone is 1 g: it logs "
                     "m/s^2; leave out --accel-unit g")  # fmt: skip
    offset = result.time_offset
    if result.line_delay is not None:
        # The joint task's start posed the views with a global-shutter camera, which a rolling shutter bends (the
        # board read 3.2x too small from them): the views posed again with the solved camera, timed by their
        # middle rows, as PnP poses of a rolling shutter's views are.
        posed = posed_frames(frames, rec.target, result.camera)
        offset += 0.5 * result.line_delay * result.camera.height
    board = board_scale(posed, rec.imu, result.T_cam_imu[:3, :3], offset)
    if wrong_board_scale(board):
        size, scale = rec.target.row_spacing, board.centre[0]
        suggested = f"{size:g} m; the data suggest {size / scale:.3g} m"
        smaller = f"the board is {scale:.2f}x smaller than --target says ({suggested})"
        readout = result.rolling_shutter_evidence
        if readout is None:
            found.append(f"the camera's accelerations are {scale:.2f}x the IMU's: {smaller}; give the board's true "
                         "size in --target")  # fmt: skip
        else:  # the camera's accelerations come from poses that an unmodelled rolling shutter bends
            found.append(
                f"the camera's accelerations are {scale:.2f}x the IMU's, and the corner residuals show an unmodelled "
                f"rolling shutter (a readout of {readout * 1e3:.1f} ms or more) that bends the poses they come from: "
                f"calibrate with --rolling-shutter; should the ratio stay, {smaller}"
            )
    return found


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input or failed calibration)."""
    errors = (CalibrationError, FormatError, DataError, TargetError, CameraModelError, OutputError)
    return argparse_main(APP, build_parser(), run, errors, FLAGS, argv)


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
