"""``vical-export``: write a recording with images as Kalibr's inputs (EuRoC folder, ROS1 bag, YAML files).

Example::

    vical-export recordings/demo --out kalibr_in

Writes into ``--out``: ``euroc/mav0/...`` (EuRoC/ASL folder), ``data.bag`` (ROS1, Kalibr's topics),
``target.yaml`` (Kalibr target), ``imu.yaml`` (Kalibr IMU noise) and, when the recording carries
its truth (simulator), ``camchain.yaml`` (the true intrinsics, the input of
``kalibr_calibrate_imu_camera --cams``) and ``camchain-imucam-truth.yaml`` (the true extrinsic and
time offset, to compare Kalibr's result with). It prints the Kalibr commands to run on them.

Every output is written atomically; a killed export leaves at most hidden temporary siblings, which the
next export into the same ``--out`` removes.
"""

from __future__ import annotations

import sys
from pathlib import Path

from vical.apps.cli import ArgumentParser, cannot_write, one_line_warnings, report_error
from vical.data import DataError, ImuNoise, Recording
from vical.io.atomic import remove_stale_temporaries
from vical.io.bag import write_bag
from vical.io.errors import FormatError
from vical.io.euroc import write_euroc
from vical.io.kalibr import write_camchain_imucam, write_imu_yaml, write_target_yaml
from vical.io.recording import is_recording_dir, load_recording


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="vical-export", description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="vical recording directory with images (vical-record images=true)")
    p.add_argument("--out", required=True, help="output directory (must not exist unless --overwrite)")
    p.add_argument("--image-topic", default="/cam0/image_raw", help="bag image topic (default: /cam0/image_raw)")
    p.add_argument("--imu-topic", default="/imu0", help="bag IMU topic (default: /imu0)")
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs in --out")
    return p


def kalibr_result_name(prefix: str, bag: Path) -> str:
    """File name Kalibr gives its result for ``bag``: the path without ``<>:/\\|?*`` and ``.bag``."""
    tag = str(bag).translate({ord(c): None for c in "<>:/\\|?*"}).replace(".bag", "", 1)
    return f"{prefix}-{tag}.yaml"


KALIBR_MODELS = {"radtan": "pinhole-radtan", "equidistant": "pinhole-equi", "ds": "ds-none", "eucm": "eucm-none"}


def kalibr_commands(
    out: Path,
    has_truth: bool,
    image_topic: str = "/cam0/image_raw",
    distortion: str = "radtan",
    imu_model: str = "calibrated",
) -> list[str]:
    """The Kalibr command lines for the exported files (camera first, then camera-IMU).

    Without the truth, the camera-IMU step takes the camera calibration Kalibr's first step writes;
    ``imu_model`` ``scale-misalignment`` (an IMU with intrinsics) has Kalibr estimate them.
    """
    imu_models = "" if imu_model == "calibrated" else f" --imu-models {imu_model}"
    cams = out / "camchain.yaml" if has_truth else Path(kalibr_result_name("camchain", out / "data.bag"))
    return [
        f"kalibr_calibrate_cameras --bag {out / 'data.bag'} --topics {image_topic} "
        f"--models {KALIBR_MODELS[distortion]} --target {out / 'target.yaml'}",
        f"kalibr_calibrate_imu_camera --bag {out / 'data.bag'} --cams {cams} --imu {out / 'imu.yaml'} "
        f"--target {out / 'target.yaml'} --time-calibration{imu_models}",
    ]


def check_out(out: Path, overwrite: bool) -> None:
    """Refuse an ``--out`` that is a file, or that holds files unless ``overwrite`` (after removing what a killed
    export left)."""
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"--out {out} is a file; give a directory")
    remove_stale_temporaries(out)
    if out.exists() and not overwrite and any(out.iterdir()):
        raise FileExistsError(f"--out {out} exists and is not empty; pass --overwrite to replace its files")


def export(rec: Recording, out: Path, image_topic: str, imu_topic: str, overwrite: bool) -> list[Path]:
    """Write the Kalibr inputs of ``rec`` into ``out``; return the written paths."""
    if rec.frames.images is None:
        raise FormatError("the recording has no images; record it with images (vical-record images=true)")
    check_out(out, overwrite)
    out.mkdir(parents=True, exist_ok=True)
    written = [write_euroc(rec, out / "euroc", overwrite=overwrite)]
    written.append(write_bag(rec, out / "data.bag", image_topic, imu_topic, overwrite=overwrite))
    write_target_yaml(out / "target.yaml", rec.target)
    noise = rec.truth.imu_noise if rec.truth is not None else ImuNoise()
    write_imu_yaml(out / "imu.yaml", noise, rostopic=imu_topic)
    written += [out / "target.yaml", out / "imu.yaml"]
    if rec.truth is not None:
        truth = rec.truth
        write_camchain_imucam(out / "camchain.yaml", truth.camera, None, None, rostopic=image_topic)
        path = out / "camchain-imucam-truth.yaml"
        write_camchain_imucam(path, truth.camera, truth.T_cam_imu, truth.time_offset, rostopic=image_topic)
        written += [out / "camchain.yaml", path]
        if not truth.imu_intrinsics.is_identity():  # the truth to compare Kalibr's scale-misalignment result with
            path = out / "imu-truth.yaml"
            write_imu_yaml(path, noise, rostopic=imu_topic, intrinsics=truth.imu_intrinsics)
            written.append(path)
    return written


def main(argv: list[str] | None = None) -> int:
    """Console entry point; returns the exit status (0 ok, 2 bad input)."""
    one_line_warnings()
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as done:  # --help (0), or a bad argument whose line argparse printed (2)
        return int(done.code or 0)
    out = Path(args.out)
    try:
        check_out(out, args.overwrite)  # before reading the recording: a wrong --out fails at once
        if not is_recording_dir(args.recording):
            raise FormatError(f"{args.recording} is not a vical recording directory (no recording.yaml)")
        rec = load_recording(args.recording)
        written = export(rec, out, args.image_topic, args.imu_topic, args.overwrite)
    except (FormatError, DataError) as exc:
        return report_error("vical-export", str(exc))
    except OSError as exc:  # vical's refusals carry their message; the system's name the path and the reason
        return report_error("vical-export", str(exc) if exc.filename is None else cannot_write("--out", out, exc))
    if rec.truth is None:
        print("note: no truth in the recording: imu.yaml holds the paper's noise densities, no camchain.yaml")
    for path in written:
        print(f"wrote {path}")
    print("Kalibr, on a machine with Kalibr installed:")
    distortion = rec.truth.camera.distortion if rec.truth is not None else "radtan"
    exact = rec.truth is None or rec.truth.imu_intrinsics.is_identity()
    imu_model = "calibrated" if exact else "scale-misalignment"
    for command in kalibr_commands(out, rec.truth is not None, args.image_topic, distortion, imu_model):
        print(f"  {command}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
