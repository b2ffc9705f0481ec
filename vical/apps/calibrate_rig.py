"""Camera rigs in ``vical-calibrate``: which cameras, their bag topics and image sizes, the N-camera outputs.

The recording's cameras (``cam0``, ``cam1``, ...: EuRoC ``camN`` folders, one bag image topic per
camera, ``frames_camN.npz`` of a recording directory) are calibrated together, or those ``--cameras``
names. The camchain written numbers the calibrated cameras ``cam0``, ``cam1``, ... in order, as
Kalibr numbers the topics it is given: ``--cameras cam1`` alone writes one ``cam0`` section whose
``rostopic`` names the recording's ``cam1`` (its bag topic, else ``/cam1/image_raw``).
"""

from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np

from vical.apps.cli import OutputError, cannot_write
from vical.calib.errors import CalibrationError
from vical.calib.metrics import CalibrationErrors, calibration_errors
from vical.calib.nominal import nominal_T_cam_imu
from vical.calib.plausibility import implausibilities
from vical.calib.report import results_text, summary_table, weak_sigma_text, write_frames_csv, write_report
from vical.calib.result import CalibrationResult
from vical.calib.rig import pair
from vical.data import CameraFrames, ImuIntrinsics, ImuNoise, Recording, seconds_since
from vical.geometry import invert_transform, matrix_to_euler, transform_error
from vical.io.atomic import atomic_directory, write_text_atomic
from vical.io.bag import bag_image_topics
from vical.io.kalibr import write_imu_yaml
from vical.io.kalibr_chain import CameraChain, ChainCamera, imu_file_with, read_imu_file, write_chain, write_imu_file

CAMERA_NAME = re.compile(r"cam(\d+)")
FRAMES_CSV = "frames.csv"  # each camera's, in its folder of the outputs
# Where each source's cameras come from, for the message that lists them.
CAMERAS_OF = {
    "euroc": "its camN folders",
    "corner_folder": "its camN folders of per-frame corner files",
    "bag": "one per image topic (--image-topic, or the rostopic of each camera of --intrinsics)",
    "recording": "cam0 and its frames_camN.npz",
    "corners_csv": "a corner CSV holds one camera",
    "image_folder": "an image folder holds one camera",
}


def camera_list(text: str) -> list[str]:
    """An argparse type: ``cam0,cam1`` -> the names in the rig's order (``cam0`` first)."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    if not names or not all(CAMERA_NAME.fullmatch(n) for n in names):
        raise argparse.ArgumentTypeError(f"must name cameras as Kalibr does, e.g. cam0,cam1; got {text!r}")
    if len(set(names)) != len(names):
        raise argparse.ArgumentTypeError(f"names a camera twice: {text!r}")
    return sorted(names, key=camera_index)


def camera_index(name: str) -> int:
    return int(CAMERA_NAME.fullmatch(name).group(1))


def topic_list(given: list[str] | None) -> list[str]:
    """The topics of ``--image-topic`` given several times and/or comma-separated, in order."""
    return [t.strip() for value in given or [] for t in value.split(",") if t.strip()]


def image_topics(given: list[str], chain: CameraChain | None, cameras: list[str] | None) -> list[str]:
    """A bag's image topics, cam0's first: ``--image-topic``'s; else each ``--intrinsics`` camera's ``rostopic``;
    else Kalibr's ``/camN/image_raw`` up to the highest camera ``--cameras`` names (``cam0`` alone by default)."""
    if given:
        return given
    if chain is not None:
        return [c.rostopic or f"/{c.name}/image_raw" for c in chain.cameras]
    count = 1 + max((camera_index(n) for n in cameras or []), default=0)
    return [f"/cam{n}/image_raw" for n in range(count)]


def check_chain_topics(bag: str, chain: CameraChain, intrinsics: str) -> None:
    """Refuse a camchain whose camera's ``rostopic`` is not an image topic of the bag (topics taken from it)."""
    present = bag_image_topics(bag)
    for camera in chain.cameras:
        topic = camera.rostopic or f"/{camera.name}/image_raw"
        if topic not in present:
            raise CalibrationError(
                f"--intrinsics {intrinsics} [{camera.name}]: rostopic {topic} is not an image topic of {bag} (it has "
                f"{', '.join(present) or 'none'}); give the bag's image topics with --image-topic, one per camera"
            )


def select_cameras(rec: Recording, requested: list[str] | None, source: str, kind: str) -> list[str]:
    """The cameras to calibrate: every one of the recording's, or those ``--cameras`` names."""
    if requested is None:
        return rec.camera_names
    missing = [n for n in requested if n not in rec.camera_names]
    if missing:
        raise CalibrationError(
            f"--cameras names {missing[0]}, but {source} has {', '.join(rec.camera_names)} ({CAMERAS_OF[kind]}); "
            "name cameras it has"
        )
    return requested


def view_overlaps(frames: dict[str, CameraFrames]) -> dict[str, list[str]]:
    """The other cameras that saw the target at the same time as each one (frames paired within 5 ms)."""
    t0 = min(int(f.t[0]) for f in frames.values() if len(f))
    seen = {n: seconds_since(f.t[f.num_detections > 0], t0) for n, f in frames.items()}
    return {a: [b for b in frames if b != a and len(pair(seen[a], seen[b])[0])] for a in frames}


def rig_chain(results: dict[str, CalibrationResult], rec: Recording, given: CameraChain | None) -> CameraChain:
    """The camchain of the calibrated cameras (in ``results``' order, numbered ``cam0``, ``cam1``, ...).

    Each keeps its ``--intrinsics`` section (every key vical does not interpret, the file's spelling)
    and ``cam_overlaps`` (else the cameras that saw the target with it); ``T_cn_cnm1`` follows from the
    ``T_cam_imu``. The intrinsic task estimates neither: the given ``T_cam_imu`` and time shift are kept,
    and a given ``T_cn_cnm1`` where the camera before it is the same one.
    """
    names = list(results)
    computed = view_overlaps({n: rec.frames_of(n) for n in names})
    cameras = []
    for k, name in enumerate(names):
        base = given[name] if given is not None and name in given.names else None
        section = dict(base.section) if base is not None else {}
        result = results[name]
        T, shift, T_cn_cnm1 = result.T_cam_imu, result.time_offset, None
        if T is None and base is not None:
            follows = k > 0 and camera_index(names[k - 1]) == camera_index(name) - 1
            T, shift, T_cn_cnm1 = base.T_cam_imu, base.timeshift_cam_imu, base.T_cn_cnm1 if follows else None
        if k == 0 or (T_cn_cnm1 is None and (T is None or cameras[-1].T_cam_imu is None)):
            section.pop("T_cn_cnm1", None)
        if base is not None and "cam_overlaps" in base.section:
            overlaps = [f"cam{i}" for i in base.cam_overlaps]
        else:
            overlaps = computed[name]
        cameras.append(
            ChainCamera(
                name=f"cam{k}",
                camera=result.camera,
                T_cam_imu=T,
                timeshift_cam_imu=shift,
                T_cn_cnm1=T_cn_cnm1,
                rostopic=_rostopic(name, base, rec),
                cam_overlaps=tuple(names.index(o) for o in overlaps if o in names),
                section=section,
            )
        )
    if given is None:
        return CameraChain(tuple(cameras))
    return CameraChain(tuple(cameras), dict(given.top), given.opencv_header)


def _rostopic(name: str, base: ChainCamera | None, rec: Recording) -> str:
    if base is not None and base.rostopic:
        return base.rostopic
    return rec.metadata.get("image_topics", {}).get(name) or f"/{name}/image_raw"


def rig_results_text(
    results: dict[str, CalibrationResult],
    errors: dict[str, CalibrationErrors | None],
    chain: CameraChain,
    rec: Recording,
    task: str,
    failure: str | None,
) -> str:
    """``results.txt`` of a rig: a section per camera (``results_text``'s), then the relative poses."""
    names = list(results)
    head = [f"FAILED: {failure}", "The estimates below are kept for diagnosis; do not use them.", ""] if failure else []
    head.append(f"vical rig calibration results: task {task}, cameras {', '.join(names)}")
    written = [c.name for c in chain.cameras]
    if written != names:
        head.append(f"written to the camchain as {', '.join(written)} (their rostopic names each)")
    sections = ["\n".join(head)]
    for name in names:
        sections.append(
            f"==================== {name} ====================\n" + results_text(results[name], errors[name])
        )
    sections.append("\n".join(_relative_pose_lines(names, chain, rec, results)))
    return "\n\n".join(s.rstrip("\n") for s in sections) + "\n"


def relative_poses(names: list[str], chain: CameraChain) -> list[tuple[str, str, np.ndarray]]:
    """(camera, previous camera, ``T_cn_cnm1`` (4, 4)) of each written camera after the first that has one."""
    poses = []
    for k in range(1, len(names)):
        T = chain.relative_pose(f"cam{k}")
        if T is not None:
            poses.append((names[k], names[k - 1], T))
    return poses


def _relative_pose_lines(names, chain, rec, results) -> list[str]:
    poses = relative_poses(names, chain)
    if not poses:
        return ["relative poses (T_cn_cnm1): none (the intrinsic task estimates none, and none was given)"]
    lines = ["relative poses (Kalibr's T_cn_cnm1: maps the previous camera's points into this camera's frame):"]
    for name, previous, T in poses:
        lines.append(f"  {name} <- {previous}:")
        lines += ["    [" + ", ".join(f"{v: .8f}" for v in row) + "]" for row in T]
        rpy = np.rad2deg(matrix_to_euler(T[:3, :3]))
        t = T[:3, 3] * 1e3
        lines.append(f"    roll/pitch/yaw [deg]: {rpy[0]:.4f} {rpy[1]:.4f} {rpy[2]:.4f}")
        lines.append(f"    translation [mm]: {t[0]:.3f} {t[1]:.3f} {t[2]:.3f} (baseline {np.linalg.norm(t):.3f} mm)")
        offsets = results[name].time_offset, results[previous].time_offset
        if None not in offsets:
            lines.append(f"    time offset {name} - {previous} [ms]: {(offsets[0] - offsets[1]) * 1e3:.4f}")
        truth, truth_previous = rec.truth_of(name), rec.truth_of(previous)
        if truth is not None and truth_previous is not None:
            rotation, translation = transform_error(T, truth.T_cam_imu @ invert_transform(truth_previous.T_cam_imu))
            lines.append(
                f"    error against the truth: rotation {np.rad2deg(rotation):.4f} deg, "
                f"translation {translation * 1e3:.3f} mm"
            )
    return lines


def rig_summary(
    results: dict[str, CalibrationResult],
    errors: dict[str, CalibrationErrors | None],
    chain: CameraChain,
    out: Path,
) -> list[str]:
    """The terminal's lines: each camera's summary table and frame counts, the relative poses, each camera's
    warnings and weak parameters."""
    lines = []
    for name, result in results.items():
        lines += [f"== {name} ==", summary_table(result, errors[name])]
        if result.frame_log is not None:
            where = out / name / FRAMES_CSV
            lines.append(f"frames: {result.frame_log.summary()} (every frame with its reason: {where})")
    for name, previous, T in relative_poses(list(results), chain):
        t = T[:3, 3] * 1e3
        angle = np.rad2deg(np.arccos(np.clip((np.trace(T[:3, :3]) - 1) / 2, -1.0, 1.0)))
        lines.append(
            f"T_cn_cnm1 {name} <- {previous}: translation {t[0]:.2f} {t[1]:.2f} {t[2]:.2f} mm "
            f"(baseline {np.linalg.norm(t):.2f} mm), rotation {angle:.4f} deg"
        )
    for name, result in results.items():
        lines += [f"warning: {_named(name, w)}" for w in result.warnings]
        lines += [f"weak: {name}: {w.name} ({weak_sigma_text(w)}): {w.hint}" for w in result.weak_parameters[:3]]
    return lines


def _named(name: str, warning: str) -> str:
    """A camera's warning, prefixed with its name unless it starts with it."""
    return warning if warning.startswith(f"{name}:") else f"{name}: {warning}"


def rig_image_size(args, rec: Recording, name: str, known: ChainCamera | None) -> tuple[int, int] | None:
    """(W, H) [px] of camera ``name``'s images: as read, else ``--image-size``, else its truth's or the
    ``--intrinsics`` camera's; a ``--image-size`` or ``--intrinsics`` resolution that differs is refused."""
    images = rec.frames_of(name).images
    decoded = rec.metadata.get("image_sizes", {}).get(name) or (None if images is None else images.shape[:0:-1])
    decoded = None if decoded is None else (int(decoded[0]), int(decoded[1]))
    given = tuple(args.image_size) if args.image_size else None
    if decoded and given and decoded != given:
        raise CalibrationError(
            f"--image-size {given[0]} {given[1]} differs from {name}'s images' size {decoded[0]} x {decoded[1]} px; "
            "leave --image-size out (the images give the size)"
        )
    truth = rec.truth_of(name)
    size = decoded or given or (None if truth is None else (truth.camera.width, truth.camera.height))
    if known is not None and size is not None and (known.camera.width, known.camera.height) != size:
        raise CalibrationError(
            f"{args.intrinsics} [{name}]: resolution {known.camera.width} x {known.camera.height} px, but {name}'s "
            f"images are {size[0]} x {size[1]} px; give the camchain of this camera at this resolution"
        )
    return size or (None if known is None else (known.camera.width, known.camera.height))


def rig_problems(results: dict[str, CalibrationResult], guesses: dict[str, np.ndarray]) -> tuple[str, str] | None:
    """What makes the rig's results untrustworthy (``implausibilities``: each problem once, with the cameras that
    show it; the IMU's are every camera's) and the first camera that shows one; None when nothing does."""
    first = next(iter(results))
    problems = {
        n: implausibilities(r, guesses.get(n, nominal_T_cam_imu() if n == first else None)) for n, r in results.items()
    }
    failed = [n for n, p in problems.items() if p]
    if not failed:
        return None
    cameras: dict[str, list[str]] = {}
    for n in failed:
        for problem in problems[n]:
            cameras.setdefault(problem, []).append(n)
    return "; ".join(f"{', '.join(names)}: {problem}" for problem, names in cameras.items()), failed[0]


def write_imu_output(path: Path, imu_yaml: str | None, noise: ImuNoise, intrinsics: ImuIntrinsics | None) -> None:
    """``imu.yaml``: the ``--imu-yaml`` file kept whole (its ``rostopic``, ``T_i_b``, ``%YAML:1.0`` header and every
    other key) with the noise and IMU intrinsics of the calibration put in; else Kalibr's ``imu.yaml`` of them."""
    if imu_yaml:
        write_imu_file(path, imu_file_with(read_imu_file(imu_yaml), noise, intrinsics))
    else:
        write_imu_yaml(path, noise, intrinsics=intrinsics)


def write_rig_outputs(
    out: Path,
    results: dict[str, CalibrationResult],
    rec: Recording,
    args,
    noise: ImuNoise | None,
    given: CameraChain | None,
    failure: str | None,
) -> None:
    """Write the rig's camchain, ``imu.yaml``, ``results.txt`` and a folder per camera (its ``frames.csv`` and,
    unless ``--no-report``, its report) into ``out`` at once, then print the summary."""
    errors = {n: calibration_errors(r, rec.truth_of(n)) if rec.truth_of(n) else None for n, r in results.items()}
    name = "camchain.yaml" if noise is None else "camchain-imucam.yaml"
    if failure:
        name = name.replace(".yaml", ".failed.yaml")
    chain = rig_chain(results, rec, given)
    try:
        with atomic_directory(out, overwrite=out.exists()) as tmp:
            write_chain(tmp / name, chain)
            if noise is not None:
                write_imu_output(tmp / "imu.yaml", args.imu_yaml, noise, next(iter(results.values())).imu_intrinsics)
            write_text_atomic(tmp / "results.txt", rig_results_text(results, errors, chain, rec, args.task, failure))
            for camera, result in results.items():
                if result.frame_log is not None:
                    (tmp / camera).mkdir()
                    write_frames_csv(tmp / camera / FRAMES_CSV, result.frame_log)
                if not args.no_report:
                    write_report(tmp / camera, result, errors[camera], failure)
    except OSError as err:
        raise OutputError(cannot_write("--out", out, err)) from None
    print("\n".join(rig_summary(results, errors, chain, out)))
    print(f"outputs written to {out}")
