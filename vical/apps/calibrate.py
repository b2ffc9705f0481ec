"""``vical-calibrate``: calibrate a saved recording and write Kalibr-compatible files and a report.

Examples::

    vical-calibrate runs/rec0 --task intrinsic --model radtan
    vical-calibrate runs/rec0 --task extrinsic --intrinsics camchain.yaml --imu-yaml imu.yaml
    vical-calibrate runs/rec0 --task joint --out calib/

Outputs in ``--out``: ``camchain.yaml`` (intrinsic) or ``camchain-imucam.yaml`` + ``imu.yaml``,
``results.txt``, ``reprojection.png`` / ``imu.png`` / ``report.pdf``. A summary table goes to
the terminal, with the errors against the truth when the recording carries it.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from vical.calib.calibrate import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.errors import CalibrationError
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.metrics import calibration_errors
from vical.calib.report import summary_table, write_report, write_results_text
from vical.calib.result import CalibrationResult
from vical.calib.visual_inertial import ViOptions
from vical.data import DataError, ImuNoise, Recording
from vical.geometry import CameraModel
from vical.io.errors import FormatError
from vical.io.kalibr import read_camchain, read_imu_yaml, read_target_yaml, write_camchain_imucam, write_imu_yaml
from vical.io.sources import open_recording

TASKS = ("intrinsic", "extrinsic", "joint", "two_stage")


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vical-calibrate", description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="recording directory, EuRoC folder, ROS1 bag or corner CSV")
    p.add_argument("--task", choices=TASKS, default="joint", help="what to calibrate (default: joint)")
    p.add_argument("--model", choices=("radtan", "equidistant"), default="radtan", help="lens distortion model")
    p.add_argument("--intrinsics", help="Kalibr camchain.yaml with the known intrinsics (extrinsic task)")
    p.add_argument("--imu-yaml", help="Kalibr imu.yaml with the IMU noise densities")
    p.add_argument("--target", help="Kalibr target YAML (needed unless the recording stores its target)")
    p.add_argument("--imu-csv", help="EuRoC-format IMU CSV to pair with a corner CSV")
    p.add_argument("--image-size", nargs=2, type=int, metavar=("W", "H"), help="image size [px]")
    p.add_argument("--huber", type=float, default=None, help="Huber kernel width in sigmas (robust to outliers)")
    p.add_argument("--max-time-offset", type=float, default=0.1, help="time-offset search half-width [s]")
    p.add_argument("--fixed-time-offset", action="store_true", help="do not estimate the time offset")
    p.add_argument("--out", default="calibration", help="output directory (default: ./calibration)")
    p.add_argument("--no-report", action="store_true", help="skip the PNG/PDF plots")
    return p


def _image_size(args, rec: Recording, camera: CameraModel | None) -> tuple[int, int] | None:
    if args.image_size:
        return tuple(args.image_size)
    if rec.frames.images is not None:
        return None  # taken from the images
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
    target = read_target_yaml(args.target) if args.target else None
    rec = open_recording(args.recording, target, imu_csv=args.imu_csv)
    camera, T_guess, shift = _known_intrinsics(args)
    size = _image_size(args, rec, camera)
    options = ViOptions(
        estimate_time_offset=not args.fixed_time_offset, max_time_offset=args.max_time_offset, huber_k=args.huber
    )
    common = {"initial_T_cam_imu": T_guess, "initial_time_offset": shift or 0.0, "options": options}
    if args.task == "intrinsic":
        result = calibrate_intrinsics(rec.frames, rec.target, args.model, size, camera, huber_k=args.huber)
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
    for w in result.weak_parameters[:3]:
        print(f"weak: {w.name} (1-sigma {w.sigma:.3g}): {w.hint}")
    print(f"outputs written to {out}")


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input or failed calibration)."""
    args = build_parser().parse_args(argv)
    try:
        run(args)
    except (CalibrationError, FormatError, DataError, FileNotFoundError) as exc:
        print(f"vical-calibrate: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
