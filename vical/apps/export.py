"""``vical-export``: write a recording with images as Kalibr's inputs (EuRoC folder, ROS1 bag, YAML files).

Examples::

    vical-export recordings/demo --out kalibr_in
    vical-export recordings/demo --out ros2_in --bag mcap        # a ROS 2 bag instead of the ROS1 one

Writes into ``--out``: ``euroc/mav0/...`` (EuRoC/ASL folder), ``data.bag`` (ROS1, Kalibr's topics; with ``--bag
db3`` / ``mcap`` a ROS 2 bag folder ``ros2_db3/`` / ``ros2_mcap/`` with the same topics instead or beside it),
``target.yaml`` (Kalibr target), ``imu.yaml`` (Kalibr IMU noise) and, when the recording carries
its truth (simulator), ``camchain.yaml`` (the true intrinsics, the input of
``kalibr_calibrate_imu_camera --cams``) and ``camchain-imucam-truth.yaml`` (the true extrinsic and
time offset, to compare Kalibr's result with). It prints the Kalibr commands to run on them.

A rig's recording (cameras ``cam0``, ``cam1``, ...) is written whole: every camera's folder, one
bag topic per camera (``--image-topic`` names them, cam0's first; the others default to
``/camN/image_raw``), a camchain section per camera with its ``T_cn_cnm1``, and Kalibr commands that
name every topic. What cannot be written for every camera (a camera without images, too many or
repeated topics) is refused before anything is written; the true camchains are written for every
camera or, when a camera's truth is unknown, not at all (as for a recording without truth).

Every output is written atomically; a killed export leaves at most hidden temporary siblings, which the
next export into the same ``--out`` removes.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from vical.apps.calibrate_outputs import view_overlaps
from vical.apps.cli import AS_IT_WAS, ArgumentParser, cannot_write, one_line_warnings, os_error_reason, report_error
from vical.apps.entry import is_write_fault
from vical.apps.entry import run as run_command
from vical.data import DataError, ImuNoise, Recording
from vical.geometry.transforms import invert_transform
from vical.io.atomic import files_together, remove_stale_temporaries
from vical.io.bag import BAG_FORMATS, camera_topics, write_bag
from vical.io.errors import FormatError
from vical.io.euroc import write_euroc
from vical.io.kalibr import write_imu_yaml, write_target_yaml
from vical.io.kalibr_chain import CameraChain, ChainCamera, write_chain
from vical.io.recording import is_recording_dir, load_recording


def build_parser() -> ArgumentParser:
    p = ArgumentParser(prog="vical-export", description=__doc__.split("\n\n")[0])
    p.add_argument("recording", help="vical recording directory with images (vical-record images=true)")
    p.add_argument("--out", required=True, help="output directory (must not exist unless --overwrite)")
    p.add_argument(
        "--image-topic",
        nargs="+",
        default=["/cam0/image_raw"],
        help="bag image topic of each camera, cam0's first (default: /cam0/image_raw; cam1 ... /camN/image_raw)",
    )
    p.add_argument("--imu-topic", default="/imu0", help="bag IMU topic (default: /imu0)")
    p.add_argument(
        "--bag",
        nargs="+",
        choices=tuple(BAG_FORMATS),
        default=["ros1"],
        help="the bags to write: ros1 (data.bag, which Kalibr reads; the default), db3 or mcap (a ROS 2 bag folder)",
    )
    p.add_argument("--overwrite", action="store_true", help="replace existing outputs in --out")
    return p


def kalibr_result_name(prefix: str, bag: Path) -> str:
    """File name Kalibr gives its result for ``bag``: the path without ``<>:/\\|?*`` and ``.bag``."""
    tag = str(bag).translate({ord(c): None for c in "<>:/\\|?*"}).replace(".bag", "", 1)
    return f"{prefix}-{tag}.yaml"


KALIBR_MODELS = {
    "radtan": "pinhole-radtan",
    "equidistant": "pinhole-equi",
    "ds": "ds-none",
    "eucm": "eucm-none",
    "omni": "omni-none",
    "omni-radtan": "omni-radtan",
}


def kalibr_commands(
    out: Path,
    has_truth: bool,
    image_topics: Sequence[str] = ("/cam0/image_raw",),
    distortions: Sequence[str] = ("radtan",),
    imu_model: str = "calibrated",
) -> list[str]:
    """The Kalibr command lines for the exported files (cameras first, then camera-IMU).

    ``image_topics`` and ``distortions`` (vical's lens model of each camera) name every camera, in order:
    Kalibr's ``--topics t0 t1 --models m0 m1``. Without the truth, the camera-IMU step takes the camera
    calibration Kalibr's first step writes; ``imu_model`` ``scale-misalignment`` (an IMU with intrinsics) has
    Kalibr estimate them.
    """
    imu_models = "" if imu_model == "calibrated" else f" --imu-models {imu_model}"
    cams = out / "camchain.yaml" if has_truth else Path(kalibr_result_name("camchain", out / "data.bag"))
    return [
        f"kalibr_calibrate_cameras --bag {out / 'data.bag'} --topics {' '.join(image_topics)} "
        f"--models {' '.join(KALIBR_MODELS[d] for d in distortions)} --target {out / 'target.yaml'}",
        f"kalibr_calibrate_imu_camera --bag {out / 'data.bag'} --cams {cams} --imu {out / 'imu.yaml'} "
        f"--target {out / 'target.yaml'} --time-calibration{imu_models}",
    ]


def image_topics_of(rec: Recording, given: Sequence[str]) -> list[str]:
    """The bag topic of every camera: ``given`` (cam0's first), ``/camN/image_raw`` for the rest; refuses more
    topics than cameras and a repeated topic."""
    names = rec.camera_names
    if len(given) > len(names):
        raise FormatError(
            f"--image-topic gives {len(given)} topics, but the recording has {len(names)} camera(s) "
            f"({', '.join(names)}); give one topic per camera, cam0's first"
        )
    return camera_topics(list(given), len(names))


def check_images(rec: Recording) -> None:
    """Refuse a recording with a camera without images (an export writes every camera or nothing)."""
    for name in rec.camera_names:
        if rec.frames_of(name).images is None:
            raise FormatError(
                f"the recording has no images of {name}; record it with images (vical-record images=true)"
            )


def knows_every_truth(rec: Recording) -> bool:
    return all(rec.truth_of(name) is not None for name in rec.camera_names)


def truth_chain(rec: Recording, topics: list[str], with_imu: bool) -> CameraChain:
    """The true camchain of every camera: intrinsics, ``rostopic``, ``cam_overlaps`` (the cameras that saw the
    target at the same time) and ``T_cn_cnm1``; with ``with_imu`` also ``T_cam_imu`` and the time shift."""
    names = rec.camera_names
    overlaps = view_overlaps({name: rec.frames_of(name) for name in names})
    cameras = []
    for k, name in enumerate(names):
        truth = rec.truth_of(name)
        before = rec.truth_of(names[k - 1]) if k else None
        cameras.append(
            ChainCamera(
                name=name,
                camera=truth.camera,
                T_cam_imu=truth.T_cam_imu if with_imu else None,
                timeshift_cam_imu=truth.time_offset if with_imu else None,
                T_cn_cnm1=None if before is None else truth.T_cam_imu @ invert_transform(before.T_cam_imu),
                rostopic=topics[k],
                cam_overlaps=tuple(names.index(other) for other in overlaps[name]),
            )
        )
    return CameraChain(tuple(cameras))


def check_out(out: Path, overwrite: bool) -> None:
    """Refuse an ``--out`` that is a file, or that holds files unless ``overwrite`` (after removing what a killed
    export left)."""
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"--out {out} is a file; give a directory")
    remove_stale_temporaries(out)
    if out.exists() and not overwrite and any(out.iterdir()):
        raise FileExistsError(f"--out {out} exists and is not empty; pass --overwrite to replace its files")


def bag_name(bag_format: str) -> str:
    """The name in ``--out`` of the bag of ``bag_format``: ``data.bag`` (ROS1), ``ros2_db3`` / ``ros2_mcap``."""
    return "data.bag" if bag_format == "ros1" else f"ros2_{bag_format}"


def export(
    rec: Recording,
    out: Path,
    image_topics: Sequence[str],
    imu_topic: str,
    overwrite: bool,
    bags: Sequence[str] = ("ros1",),
) -> list[Path]:
    """Write the Kalibr inputs of every camera of ``rec`` into ``out``, with a bag of each of ``bags``
    (``BAG_FORMATS``); return the written paths.

    Refuses (before writing anything) a camera without images and topics that do not name each camera once.
    """
    check_images(rec)
    topics = image_topics_of(rec, image_topics)
    check_out(out, overwrite)
    names = ["euroc", *(bag_name(b) for b in dict.fromkeys(bags)), "target.yaml", "imu.yaml"]
    with files_together(out) as path_of:  # every output or none: the old ones stay until the new ones are whole
        write_euroc(rec, path_of("euroc"))
        for bag_format in dict.fromkeys(bags):
            write_bag(rec, path_of(bag_name(bag_format)), topics, imu_topic, bag_format=bag_format)
        write_target_yaml(path_of("target.yaml"), rec.target)
        noise = rec.truth.imu_noise if rec.truth is not None else ImuNoise()
        grade = rec.truth.imu_grade if rec.truth is not None else None  # the sensor declares it, as its noise
        write_imu_yaml(path_of("imu.yaml"), noise, rostopic=imu_topic, grade=grade)
        if knows_every_truth(rec):
            write_chain(path_of("camchain.yaml"), truth_chain(rec, topics, with_imu=False))
            write_chain(path_of("camchain-imucam-truth.yaml"), truth_chain(rec, topics, with_imu=True))
            names += ["camchain.yaml", "camchain-imucam-truth.yaml"]
        if rec.truth is not None and not rec.truth.imu_intrinsics.is_identity():
            # the truth to compare Kalibr's scale-misalignment result with
            write_imu_yaml(path_of("imu-truth.yaml"), noise, rostopic=imu_topic, intrinsics=rec.truth.imu_intrinsics)
            names.append("imu-truth.yaml")
    return [out / name for name in names]


def truth_note(rec: Recording) -> str | None:
    """What the export could not write for want of the truth, or None."""
    if rec.truth is None:
        return "no truth in the recording: imu.yaml holds the paper's noise densities, no camchain.yaml"
    unknown = [name for name in rec.camera_names if rec.truth_of(name) is None]
    if unknown:
        return (
            f"the recording has no truth of {', '.join(unknown)}: no camchain.yaml (the true chain is written for "
            "every camera or none); Kalibr's camera calibration writes one"
        )
    return None


def print_summary(rec: Recording, out: Path, written: list[Path], topics: list[str]) -> None:
    """What was written (and what not, for want of the truth), then the Kalibr commands for every camera."""
    note = truth_note(rec)
    if note is not None:
        print(f"note: {note}")
    for path in written:
        print(f"wrote {path}")
    if out / "data.bag" not in written:
        print("Kalibr reads ROS1 bags only: add --bag ros1 for its data.bag and commands")
        return
    print("Kalibr, on a machine with Kalibr installed:")
    truths = [rec.truth_of(name) for name in rec.camera_names]
    distortions = [truth.camera.distortion if truth is not None else "radtan" for truth in truths]
    exact = rec.truth is None or rec.truth.imu_intrinsics.is_identity()
    imu_model = "calibrated" if exact else "scale-misalignment"
    for command in kalibr_commands(out, knows_every_truth(rec), topics, distortions, imu_model):
        print(f"  {command}")


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
        written = export(rec, out, args.image_topic, args.imu_topic, args.overwrite, args.bag)
    except (FormatError, DataError) as exc:
        return report_error("vical-export", str(exc))
    except OSError as exc:  # vical's refusals carry their message; the system's name the path and the reason
        if is_write_fault(exc):
            return report_error("vical-export", cannot_write("--out", out, exc, AS_IT_WAS))
        return report_error("vical-export", os_error_reason(exc))
    print_summary(rec, out, written, image_topics_of(rec, args.image_topic))
    return 0


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command("vical-export", main)
