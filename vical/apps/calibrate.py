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
``results.txt``, ``reprojection.png`` / ``imu.png`` / ``report.pdf``. A summary table goes to
the terminal, with the errors against the truth when the recording carries it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from vical.calib.aprilgrid import detect_aprilgrid, make_aprilgrid_detector
from vical.calib.calibrate import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.detection import detect_checkerboard
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.metrics import calibration_errors
from vical.calib.report import summary_table, write_report, write_results_text
from vical.calib.result import CalibrationResult
from vical.calib.visual_inertial import ViOptions
from vical.data import DataError, ImuNoise, Recording, Target
from vical.data.target import TargetError
from vical.geometry import CameraModel, CameraModelError
from vical.io.errors import FormatError
from vical.io.kalibr import read_camchain, read_imu_yaml, read_target_yaml, write_camchain_imucam, write_imu_yaml
from vical.io.sources import detect_source, open_recording

TASKS = ("intrinsic", "extrinsic", "joint", "two_stage")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vical-calibrate", description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="recording directory, EuRoC folder, ROS1 bag, image folder or corner CSV")
    p.add_argument("--task", choices=TASKS, default="joint", help="what to calibrate (default: joint)")
    p.add_argument("--model", choices=("radtan", "equidistant"), default="radtan", help="lens distortion model")
    p.add_argument("--intrinsics", help="Kalibr camchain.yaml with the known intrinsics (extrinsic task)")
    p.add_argument("--imu-yaml", help="Kalibr imu.yaml with the IMU noise densities")
    p.add_argument("--target", help="Kalibr target YAML (needed unless the recording stores its target)")
    p.add_argument("--imu-csv", help="EuRoC-format IMU CSV to pair with a corner CSV")
    p.add_argument("--image-topic", default="/cam0/image_raw", help="bag image topic (default: /cam0/image_raw)")
    p.add_argument("--imu-topic", default="/imu0", help="bag IMU topic (default: /imu0)")
    p.add_argument("--rate", type=float, default=10.0, help="frame rate [Hz] that timestamps an image folder")
    p.add_argument("--gyro-unit", choices=("rad/s", "deg/s"), default="rad/s", help="gyro unit in CSVs and bags")
    p.add_argument("--accel-unit", choices=("m/s^2", "g"), default="m/s^2", help="accelerometer unit in CSVs and bags")
    p.add_argument(
        "--stored-corners",
        action="store_true",
        help="EuRoC folder: use its cam0/corners.csv instead of detecting corners in the images",
    )
    p.add_argument("--image-size", nargs=2, type=int, metavar=("W", "H"), help="image size [px]")
    p.add_argument("--huber", type=float, default=None, help="Huber kernel width in sigmas (robust to outliers)")
    p.add_argument("--max-time-offset", type=float, default=0.1, help="time-offset search half-width [s]")
    p.add_argument("--fixed-time-offset", action="store_true", help="do not estimate the time offset")
    p.add_argument(
        "--frame-stride", type=int, default=1, help="use every N-th frame with a target view (thins long recordings)"
    )
    p.add_argument(
        "--memory-limit", type=float, default=4000.0, help="[MB] refuse a solve that would need more (default 4000)"
    )
    p.add_argument("--out", default="calibration", help="output directory (default: ./calibration)")
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
    if args.image_size:
        return tuple(args.image_size)
    if rec.frames.images is not None:
        return None  # taken from the images
    if seen is not None:
        return seen
    known = camera or (rec.truth.camera if rec.truth is not None else None)
    return None if known is None else (known.width, known.height)


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


def run(args: argparse.Namespace) -> CalibrationResult:
    """Calibrate as the parsed arguments say, write the outputs and print the summary."""
    options = ViOptions(  # first: a bad option fails before the recording is read
        estimate_time_offset=not args.fixed_time_offset,
        max_time_offset=args.max_time_offset,
        huber_k=args.huber,
        frame_stride=args.frame_stride,
        memory_limit_mb=args.memory_limit,
    )
    rec, seen = load_source(args)
    camera, T_guess, shift = _known_intrinsics(args)
    size = _image_size(args, rec, camera, seen)
    common = {"initial_T_cam_imu": T_guess, "initial_time_offset": shift or 0.0, "options": options}
    if args.task == "intrinsic":
        result = calibrate_intrinsics(
            rec.frames, rec.target, args.model, size, camera, huber_k=args.huber, frame_stride=args.frame_stride
        )
        _write_outputs(Path(args.out), result, rec, args, None)
        return result
    if args.task == "extrinsic" and camera is None:
        raise CalibrationError("the extrinsic task needs the intrinsics: pass --intrinsics camchain.yaml")
    noise = _imu_noise(args, rec)
    if args.task == "extrinsic":
        result = calibrate_extrinsics(rec.frames, rec.imu, rec.target, camera, noise, **common)
    elif args.task == "joint":
        result = calibrate_joint(rec.frames, rec.imu, rec.target, args.model, size, noise, **common)
    else:
        result = calibrate_two_stage(rec.frames, rec.imu, rec.target, args.model, size, noise, **common)
    _write_outputs(Path(args.out), result, rec, args, noise)
    return result


def _write_outputs(out: Path, result: CalibrationResult, rec: Recording, args, noise: ImuNoise | None) -> None:
    out.mkdir(parents=True, exist_ok=True)
    errors = calibration_errors(result, rec.truth) if rec.truth is not None else None
    if noise is None:
        write_camchain_imucam(out / "camchain.yaml", result.camera, None, None)
    else:
        write_camchain_imucam(out / "camchain-imucam.yaml", result.camera, result.T_cam_imu, result.time_offset)
        write_imu_yaml(out / "imu.yaml", noise)
    write_results_text(out / "results.txt", result, errors)
    if not args.no_report:
        write_report(out, result)
    print(summary_table(result, errors))
    for w in result.warnings:
        print(f"warning: {w}")
    for w in result.weak_parameters[:3]:
        print(f"weak: {w.name} (1-sigma {w.sigma:.3g}): {w.hint}")
    print(f"outputs written to {out}")


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input or failed calibration)."""
    args = build_parser().parse_args(argv)
    try:
        run(args)
    except (CalibrationError, FormatError, DataError, TargetError, CameraModelError, OSError) as exc:
        print(f"vical-calibrate: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
