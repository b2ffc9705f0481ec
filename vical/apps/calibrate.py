"""``vical-calibrate``: calibrate a saved recording and write Kalibr-compatible files and a report.

Examples::

    vical-calibrate runs/rec0 --task intrinsic --model radtan
    vical-calibrate runs/rec0 --task extrinsic --intrinsics camchain.yaml --imu-yaml imu.yaml
    vical-calibrate runs/rec0 --task joint --out calib/

Sources: a vical recording directory, an EuRoC folder or a ROS1 bag (corners detected in the
images with the detector of the target's kind, with a progress bar), a folder of images
(intrinsic task only) or a corner CSV (+ ``--imu-csv``). Every source except a recording
directory needs ``--target`` (Kalibr target YAML).

Outputs in ``--out``: ``camchain.yaml`` (intrinsic) or ``camchain-imucam.yaml`` + ``imu.yaml``,
``results.txt``, ``reprojection.png`` / ``imu.png`` / ``report.pdf``, written as one directory
atomically; an existing ``--out`` that holds files is refused unless ``--overwrite`` (which
replaces it whole). A summary table goes to the terminal, with the errors against the truth when
the recording carries it.

A result the data do not support (residuals far above the declared noise, a solve that never left
its initial guess: ``vical.calib.plausibility``) fails with its likely cause; its files are kept
for diagnosis, marked as failed (``results.txt`` starts with ``FAILED:``, the camchain is named
``*.failed.yaml``). User errors and failed calibrations print one line ``vical-calibrate: error:
...`` and exit with status 2.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

from vical.apps.cli import ArgumentParser, OutputError, cannot_write, one_line_warnings, report_error
from vical.calib.aprilgrid import detect_aprilgrid, make_aprilgrid_detector
from vical.calib.calibrate import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.detection import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.metrics import calibration_errors
from vical.calib.nominal import nominal_T_cam_imu
from vical.calib.plausibility import gyro_scale, implausibilities, likely_gyro_unit
from vical.calib.report import summary_table, write_report, write_results_text
from vical.calib.result import CalibrationResult
from vical.calib.visual_inertial import ViOptions
from vical.config import SettingError
from vical.data import DataError, ImuNoise, Recording, Target
from vical.data.target import TargetError
from vical.geometry import CameraModel, CameraModelError
from vical.io.atomic import atomic_directory, remove_stale_temporaries
from vical.io.errors import FormatError
from vical.io.kalibr import (
    read_camchain,
    read_imu_intrinsics,
    read_imu_yaml,
    read_target_yaml,
    write_camchain_imucam,
    write_imu_yaml,
)
from vical.io.sources import detect_source, open_recording

APP = "vical-calibrate"
TASKS = ("intrinsic", "extrinsic", "joint", "two_stage")
# The command line's spelling of the calibrator's and readers' arguments that error messages name.
FLAGS = {"gyro_unit": "--gyro-unit", "accel_unit": "--accel-unit", "image_size_px": "--image-size",
         "imu_model": "--imu-model"}  # fmt: skip


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
    p.add_argument("recording", help="recording directory, EuRoC folder, ROS1 bag, image folder or corner CSV")
    p.add_argument("--task", choices=TASKS, default="joint", help="what to calibrate (default: joint)")
    p.add_argument("--model", choices=("radtan", "equidistant"), default="radtan", help="lens distortion model")
    p.add_argument("--intrinsics", help="Kalibr camchain.yaml with the known intrinsics (extrinsic task)")
    p.add_argument("--imu-yaml", help="Kalibr imu.yaml with the IMU noise densities")
    p.add_argument("--target", help="Kalibr target YAML (needed unless the recording stores its target)")
    p.add_argument("--imu-csv", help="EuRoC-format IMU CSV to pair with a corner CSV")
    p.add_argument("--image-topic", default="/cam0/image_raw", help="bag image topic (default: /cam0/image_raw)")
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
        "--imu-model",
        choices=("calibrated", "scale-misalignment"),
        default="calibrated",
        help="scale-misalignment: also estimate the IMU's scale factors and axis misalignment (Kalibr's model)",
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
    p.add_argument("--out", default="calibration", help="output directory (default: ./calibration)")
    p.add_argument("--overwrite", action="store_true", help="replace an --out that holds files (as a whole)")
    p.add_argument("--no-report", action="store_true", help="skip the PNG/PDF plots")
    return p


class SizedDetector:
    """The corner detector of a target's kind, bound to the target; remembers the image size it saw.

    Checkerboards go to ``detect_checkerboard``, aprilgrids to ``detect_aprilgrid`` (one aruco
    detector reused over the sequence). Sources that decode images without keeping them in
    memory still tell the calibrator the image size this way.
    """

    def __init__(self, target: Target) -> None:
        self.target = target
        self.size: tuple[int, int] | None = None  # (W, H) [px] of the images seen
        self._aruco = make_aprilgrid_detector() if target.kind == "aprilgrid" else None

    def __call__(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Corners (K, 2) [px] and Kalibr point ids (K,) found in a (H, W) uint8 grey image."""
        self.size = (int(image.shape[1]), int(image.shape[0]))
        if self._aruco is not None:
            return detect_aprilgrid(image, self.target, detector=self._aruco)
        return detect_checkerboard(image, self.target)


def load_source(args: argparse.Namespace) -> tuple[Recording, tuple[int, int] | None]:
    """Open ``args.recording`` (detecting corners in its images) and return it with the image size seen."""
    target = read_target_yaml(args.target) if args.target else None
    kind = detect_source(args.recording)
    if args.task != "intrinsic" and (kind == "image_folder" or (kind == "corners_csv" and not args.imu_csv)):
        raise CalibrationError(_no_imu_message(kind, args))  # before decoding a single image
    detect = kind in ("euroc", "bag", "image_folder") and not (kind == "euroc" and args.stored_corners)
    detector = SizedDetector(target) if detect and target is not None else None
    rec = open_recording(
        args.recording,
        target,
        detector=detector,
        imu_csv=args.imu_csv,
        image_topic=args.image_topic,
        imu_topic=None if kind == "bag" and args.task == "intrinsic" else args.imu_topic,
        rate_hz=args.rate,
        gyro_unit=args.gyro_unit,
        accel_unit=args.accel_unit,
    )
    if args.task != "intrinsic" and len(rec.imu) < 2:
        raise CalibrationError(_no_imu_message(kind, args))
    return rec, None if detector is None else detector.size


def _no_imu_message(kind: str, args: argparse.Namespace) -> str:
    fixes = {
        "image_folder": "an image folder holds no IMU data",
        "corners_csv": "a corner CSV holds no IMU data: pass the IMU as --imu-csv imu.csv (EuRoC format)",
        "euroc": "its imu0/data.csv is missing or empty",
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


def _known_intrinsics(args) -> tuple[CameraModel | None, np.ndarray | None, float | None]:
    """Camera, T_cam_imu and time shift from ``--intrinsics`` (each may be None)."""
    if args.intrinsics:
        return read_camchain(args.intrinsics)
    return None, None, None


def _imu_noise(args, rec: Recording) -> ImuNoise:
    if args.imu_yaml:
        return read_imu_yaml(args.imu_yaml)
    if rec.truth is not None:
        return rec.truth.imu_noise
    print("note: no --imu-yaml given; using the paper's IMU noise densities", file=sys.stderr)
    return ImuNoise()


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
    existing = next(d for d in (out, *out.parents) if d.exists())
    if not existing.is_dir():
        raise OutputError(f"--out {out} cannot be created: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise OutputError(f"--out {out} cannot be created: {existing} is not writable; choose another directory")


def run(args: argparse.Namespace) -> CalibrationResult:
    """Calibrate as the parsed arguments say, write the outputs and print the summary.

    Raises ``CalibrationFailed`` after writing the outputs (marked as failed) when the data do not
    support the result.
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
    )
    out = Path(args.out)
    inputs = [args.recording, args.target, args.intrinsics, args.imu_yaml, args.imu_csv]
    check_out(out, args.overwrite, inputs)
    rec, seen = load_source(args)
    camera, T_guess, shift = _known_intrinsics(args)
    size = _image_size(args, rec, camera, seen)
    common = {"initial_T_cam_imu": T_guess, "initial_time_offset": shift or 0.0, "options": options}
    noise = None
    if args.task == "intrinsic":
        result = calibrate_intrinsics(
            rec.frames, rec.target, args.model, size, camera, huber_k=args.huber, frame_stride=args.frame_stride
        )
    elif args.task == "extrinsic" and camera is None:
        raise CalibrationError("the extrinsic task needs the intrinsics: pass --intrinsics camchain.yaml")
    else:
        noise = _imu_noise(args, rec)
        if args.task == "extrinsic":
            result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, camera, noise, **common)
        elif args.task == "joint":
            result = calibrate_joint(rec.frames, rec.imu, rec.target, args.model, size, noise, **common)
        else:
            result = calibrate_two_stage(rec.frames, rec.imu, rec.target, args.model, size, noise, **common)
    problems = implausibilities(result, nominal_T_cam_imu() if T_guess is None else T_guess)
    failure = _failure_message(problems, result, rec, args) if problems else None
    _write_outputs(out, result, rec, args, noise, failure)
    if failure:
        raise CalibrationFailed(f"{failure}; the outputs in {out} are marked as failed")
    return result


def _failure_message(problems: list[str], result: CalibrationResult, rec: Recording, args) -> str:
    """The calibration failed: what shows it, and the likely cause with the option that fixes it."""
    scale = gyro_scale(rec.frames, rec.imu, rec.target, result.camera) if result.imu_residuals is not None else None
    unit = likely_gyro_unit(scale, args.gyro_unit)
    if unit == "deg/s":
        cause = f"the gyro reads {scale:.1f}x the rotation the camera sees: it logs deg/s; pass --gyro-unit deg/s"
    elif unit == "rad/s":
        cause = (
            f"the gyro reads 1/{1 / scale:.1f} of the rotation the camera sees: it logs rad/s; "
            "leave out --gyro-unit deg/s"
        )
    elif result.imu_noise_scale is not None:
        cause = (
            "likely causes: the IMU's units (--gyro-unit, --accel-unit), its noise densities (--imu-yaml), a time "
            "offset beyond --max-time-offset, or a --target file that does not describe the board"
        )
    else:
        cause = "likely causes: the lens model (--model), or a --target file that does not describe the board"
    return f"the calibration failed: {'; '.join(problems)}; {cause}"


def _write_outputs(
    out: Path, result: CalibrationResult, rec: Recording, args, noise: ImuNoise | None, failure: str | None
) -> None:
    """Write every output into ``out`` at once (replacing it whole), then print the summary."""
    errors = calibration_errors(result, rec.truth) if rec.truth is not None else None
    name = "camchain.yaml" if noise is None else "camchain-imucam.yaml"
    if failure:  # kept for diagnosis under a name no tool reads as a result
        name = name.replace(".yaml", ".failed.yaml")
    try:
        with atomic_directory(out, overwrite=out.exists()) as tmp:
            if noise is None:
                write_camchain_imucam(tmp / name, result.camera, None, None)
            else:
                write_camchain_imucam(tmp / name, result.camera, result.T_cam_imu, result.time_offset)
                write_imu_yaml(tmp / "imu.yaml", noise, intrinsics=result.imu_intrinsics)
            write_results_text(tmp / "results.txt", result, errors, failure)
            if not args.no_report:
                write_report(tmp, result)
    except OSError as err:
        raise OutputError(cannot_write("--out", out, err)) from None
    print(summary_table(result, errors))
    for w in result.warnings:
        print(f"warning: {w}")
    for w in result.weak_parameters[:3]:
        print(f"weak: {w.name} (1-sigma {w.sigma:.3g}): {w.hint}")
    print(f"outputs written to {out}")


def _message(err: Exception) -> str:
    """The error's message, with a fix it names spelled as this command line's flag."""
    if isinstance(err, SettingError) and err.setting in FLAGS:
        return err.spelled(f"{FLAGS[err.setting]} {err.cli_value}")
    return str(err)


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input or failed calibration)."""
    one_line_warnings()
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as done:  # --help (0), or a bad argument whose line argparse printed (2)
        return int(done.code or 0)
    try:
        run(args)
    except (CalibrationError, FormatError, DataError, TargetError, CameraModelError, OutputError) as exc:
        return report_error(APP, _message(exc))
    except OSError as exc:  # a file the readers could not open: the path and the reason, without [Errno N]
        return report_error(APP, f"{exc.filename}: {(exc.strerror or str(exc)).lower()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
