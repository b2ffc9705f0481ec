"""The outputs of ``vical-calibrate``: one writer for every task, one camera or a rig.

Everything goes into ``--out`` at once (``vical.io.atomic.atomic_directory``: replaced whole, never half written). A
one-camera calibration (``cam0`` of a one-camera recording, or ``--cameras cam0`` without a rig camchain) writes its
files side by side: ``camchain.yaml`` (intrinsic task) or ``camchain-imucam.yaml`` + ``imu.yaml``, ``results.txt``,
``frames.csv`` and the report. A rig writes one camchain with a section per camera, ``results.txt`` with a section
per camera and the relative poses, and a folder per camera (its ``frames.csv`` and report). A camera-IMU calibration
adds ``results-imucam.txt`` in Kalibr's layout with "Is this a good result" (``vical.calib.report.kalibr_results``).
``--export`` adds the files VIO systems read (``vins-fusion/``, ``basalt/``: ``vical.io.vio_exports``). A failed
calibration's files are kept for diagnosis, marked as failed, and nothing is exported from it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from vical.apps.calibrate_rig import camera_index
from vical.apps.cli import OutputError, cannot_write
from vical.calib.metrics import CalibrationErrors, calibration_errors
from vical.calib.report.kalibr_results import kalibr_results_text
from vical.calib.report.writers import (
    results_text,
    summary_table,
    weak_sigma_text,
    write_frames_csv,
    write_report,
    write_results_text,
)
from vical.calib.result import CalibrationResult
from vical.calib.solve.rig import pair
from vical.data import CameraFrames, ImuIntrinsics, ImuNoise, Recording, seconds_since
from vical.geometry import invert_transform, matrix_to_euler, transform_error
from vical.io.atomic import atomic_directory, write_text_atomic
from vical.io.kalibr import write_camchain_imucam, write_imu_yaml
from vical.io.kalibr_chain import CameraChain, ChainCamera, imu_file_with, read_imu_file, write_chain, write_imu_file
from vical.io.vio_exports import write_vio_files

FRAMES_CSV = "frames.csv"  # each camera's, in its folder of a rig's outputs


def one_camera_layout(names: list[str], chain: CameraChain | None) -> bool:
    """Whether the outputs are a one-camera calibration's (files side by side) rather than a rig's (a folder per
    camera): ``cam0`` alone, without an ``--intrinsics`` camchain of several cameras."""
    return names == ["cam0"] and (chain is None or len(chain.cameras) <= 1)


def write_outputs(
    out: Path,
    results: dict[str, CalibrationResult],
    rec: Recording,
    args,
    noise: ImuNoise | None,
    given: CameraChain | None,
    failure: str | None,
) -> None:
    """Write every output of the calibration ``results`` into ``out`` at once (replacing it whole), then print the
    summary; ``noise`` is the IMU noise the camera-IMU tasks used (None: the intrinsic task)."""
    if one_camera_layout(list(results), given):
        _write_one_camera(out, results["cam0"], rec, args, noise, failure, given)
    else:
        _write_rig(out, results, rec, args, noise, given, failure)


def camchain_name(noise: ImuNoise | None, failure: str | None) -> str:
    """``camchain.yaml`` (camera only) or ``camchain-imucam.yaml``; a failed result's under a name no tool reads as
    a result."""
    name = "camchain.yaml" if noise is None else "camchain-imucam.yaml"
    return name.replace(".yaml", ".failed.yaml") if failure else name


def _write_one_camera(
    out: Path,
    result: CalibrationResult,
    rec: Recording,
    args,
    noise: ImuNoise | None,
    failure: str | None,
    given: CameraChain | None = None,
) -> None:
    """A one-camera calibration's files side by side in ``out``, then the summary; with an ``--intrinsics``
    camchain ``given``, the written camchain keeps its other keys and spelling."""
    errors = calibration_errors(result, rec.truth) if rec.truth is not None else None
    name = camchain_name(noise, failure)
    try:
        with atomic_directory(out, overwrite=out.exists()) as tmp:
            if given is not None:
                write_chain(tmp / name, rig_chain({"cam0": result}, rec, given))
            elif noise is None:
                write_camchain_imucam(tmp / name, result.camera, None, None)
            if noise is not None:
                if given is None:
                    write_camchain_imucam(
                        tmp / name, result.camera, result.T_cam_imu, result.time_offset, line_delay=result.line_delay
                    )
                write_imu_output(tmp / "imu.yaml", args.imu_yaml, noise, result.imu_intrinsics)
            write_results_text(tmp / "results.txt", result, errors, failure)
            write_frames_csv(tmp / "frames.csv", result.frame_log)
            if not args.no_report:
                write_report(tmp, result, errors, failure)
            write_kalibr_results(tmp, {"cam0": result}, rec, args, failure)
            exported = write_exports(tmp, args, {"cam0": result}, rec, given, noise, failure)
    except OSError as err:
        raise OutputError(cannot_write("--out", out, err)) from None
    print(summary_table(result, errors))
    print(f"frames: {result.frame_log.summary()} (every frame with its reason: {out / 'frames.csv'})")
    for w in result.warnings:
        print(f"warning: {w}")
    for w in result.weak_parameters[:3]:
        print(f"weak: {w.name} ({weak_sigma_text(w)}): {w.hint}")
    print_exports(exported, out)
    print(f"outputs written to {out}")


def _write_rig(
    out: Path,
    results: dict[str, CalibrationResult],
    rec: Recording,
    args,
    noise: ImuNoise | None,
    given: CameraChain | None,
    failure: str | None,
) -> None:
    """The rig's camchain, ``imu.yaml``, ``results.txt`` and a folder per camera (its ``frames.csv`` and, unless
    ``--no-report``, its report), then the summary."""
    errors = {n: calibration_errors(r, rec.truth_of(n)) if rec.truth_of(n) else None for n, r in results.items()}
    name = camchain_name(noise, failure)
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
            write_kalibr_results(tmp, results, rec, args, failure)
            exported = write_exports(tmp, args, results, rec, given, noise, failure)
    except OSError as err:
        raise OutputError(cannot_write("--out", out, err)) from None
    print("\n".join(rig_summary(results, errors, chain, out)))
    print_exports(exported, out)
    print(f"outputs written to {out}")


def write_kalibr_results(tmp: Path, results: dict[str, CalibrationResult], rec: Recording, args, failure: str | None):
    """``results-imucam.txt``, Kalibr's results layout with "Is this a good result", for a camera-IMU calibration
    that did not fail (results.txt says why one failed)."""
    if failure is None and all(r.imu_residuals is not None for r in results.values()):
        write_text_atomic(tmp / "results-imucam.txt", kalibr_results_text(results, rec.target, args.imu_model))


def write_exports(
    tmp: Path,
    args,
    results: dict[str, CalibrationResult],
    rec: Recording,
    given: CameraChain | None,
    noise: ImuNoise | None,
    failure: str | None,
) -> list[Path]:
    """The ``--export`` formats' files of a camera-IMU calibration into ``tmp``, each in its folder (a failed one:
    none); the paths written, relative to ``tmp``."""
    if failure or noise is None or not args.export:
        return []
    chain = rig_chain(results, rec, given)
    gravity = next(iter(results.values())).gravity_target
    magnitude = None if gravity is None else float(np.linalg.norm(gravity))
    written = []
    for vio_format in args.export:
        paths = write_vio_files(tmp / vio_format, vio_format, chain, noise, args.imu_topic, magnitude)
        written += [path.relative_to(tmp) for path in paths]
    return written


def print_exports(exported: list[Path], out: Path) -> None:
    if exported:
        print(f"for VIO systems: {', '.join(str(out / path) for path in exported)} (conventions: docs/formats.md)")


def write_imu_output(path: Path, imu_yaml: str | None, noise: ImuNoise, intrinsics: ImuIntrinsics | None) -> None:
    """``imu.yaml``: the ``--imu-yaml`` file kept whole (its ``rostopic``, ``T_i_b``, ``%YAML:1.0`` header and every
    other key) with the noise and IMU intrinsics of the calibration put in; else Kalibr's ``imu.yaml`` of them."""
    if imu_yaml:
        write_imu_file(path, imu_file_with(read_imu_file(imu_yaml), noise, intrinsics))
    else:
        write_imu_yaml(path, noise, intrinsics=intrinsics)


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
                line_delay=result.line_delay if result.line_delay is not None or base is None else base.line_delay,
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
