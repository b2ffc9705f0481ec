"""Benchmark of the calibrator: solve time, memory and errors per task, with OpenCV side by side.

Synthetic recordings (``vical.calib.synthetic``, IMU noise from the paper, 0.3 px corners, 10 ms
time offset, non-zero biases):

1. the standard 20 s and an episode-sized 8 s recording at 10 Hz (the paper's 7 x 6 board): time
   and errors per task;
2. real-size recordings, 20 Hz with 100+ corners per frame, 10, 30, 60 and 120 s long: a 10 x 12
   checkerboard (4 cm) and Kalibr's 6 x 6 aprilgrid (88 mm tags, partial views as the camera comes
   close): time and peak extra memory of each task, and the growth of the joint solve against the
   10 s case per second of data (1.0 = linear);
3. the intrinsic task against ``cv2.calibrateCamera`` (k3 fixed to 0) on the same detections, 20 and
   600 frames, outlier rejection included: both times, their ratio, the largest difference in fx,
   fy, cx, cy.

Times are medians of ``--repeats`` runs (the real-size cases run once each; the machine may be
shared: the load is printed). Peak memory is the process's high-water mark above its size before
the solve (Linux ``/proc/self/status``, reset through ``/proc/self/clear_refs``).

    .venv/bin/python experiments/bench_calibrator.py [--repeats 5] [--quick]
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import gc
import os
import time

import cv2
import numpy as np

from vical.calib.metrics import calibration_errors
from vical.calib.solve.intrinsics import calibrate_intrinsics
from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.solve.visual_inertial import ViOptions
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Recording, Target
from vical.geometry import so3_log

SIZE = (640, 480)
BIASES = {"gyro_bias": [0.01, -0.02, 0.005], "accel_bias": [0.05, -0.1, 0.08]}  # [rad/s], [m/s^2]


def _interleaved_times(fn_a, fn_b, repeats: int):
    """Median times of two functions run alternately, so both see the same machine load."""
    ta, tb, out_a, out_b = [], [], None, None
    for _ in range(repeats):
        t, out_a = _median_time(fn_a, 1)
        ta.append(t)
        t, out_b = _median_time(fn_b, 1)
        tb.append(t)
    return float(np.median(ta)), out_a, float(np.median(tb)), out_b


def _median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def _opencv(rec: Recording, frames=None):
    """``cv2.calibrateCamera`` on the recording's detections (or those of ``frames``): (fx, fy, cx, cy)."""
    frames = rec.frames if frames is None else frames
    used = [k for k in range(len(frames)) if len(frames.ids[k]) >= 4]
    obj = [rec.target.points[frames.ids[k]].astype(np.float32) for k in used]
    img = [frames.corners[k].astype(np.float32) for k in used]
    _, K, _, _, _ = cv2.calibrateCamera(obj, img, SIZE, None, None, flags=cv2.CALIB_FIX_K3)
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


def _reset_peak() -> int:
    """Reset the process's peak resident size; its present size [kB]."""
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")
    return _status_kb("VmRSS")


def _status_kb(field: str) -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith(field + ":"))


def _time_and_memory(fn, *args):
    """(seconds, peak resident memory above the size before the call [MB], result) of ``fn(*args)``.

    Memory freed by earlier calls goes back to the system first (``malloc_trim``), so that it is not
    reused unseen.
    """
    gc.collect()
    ctypes.CDLL("libc.so.6").malloc_trim(0)
    before = _reset_peak()
    start = time.perf_counter()
    out = fn(*args)
    seconds = time.perf_counter() - start
    return seconds, (_status_kb("VmHWM") - before) / 1024.0, out


def _row(name: str, seconds: float, rec: Recording, result, extra: str = "") -> str:
    e = calibration_errors(result, rec.truth)
    ext = "" if e.rotation_deg is None else f"{e.rotation_deg:8.4f} {e.translation_mm:8.3f} {e.time_offset_ms:8.4f}"
    return f"  {name:<22} {seconds:8.3f} {result.iterations:5d} {e.intrinsic_pct:9.4f} {ext:>26}  {extra}"


def bench(label: str, rec: Recording, repeats: int) -> list[str]:
    noise = rec.truth.imu_noise
    f, imu, tgt = rec.frames, rec.imu, rec.target
    t_cv, K_cv, t_in, r_in = _interleaved_times(
        lambda: _opencv(rec), lambda: calibrate_intrinsics(f, tgt, "radtan", SIZE), repeats
    )
    t_ex, r_ex = _median_time(lambda: calibrate_extrinsics(f, imu, tgt, rec.truth.camera, noise), repeats)
    t_jo, r_jo = _median_time(lambda: calibrate_joint(f, imu, tgt, "radtan", SIZE, noise), repeats)
    t_ts, r_ts = _median_time(lambda: calibrate_two_stage(f, imu, tgt, "radtan", SIZE, noise), repeats)
    diff = np.abs(r_in.camera.intrinsics - K_cv).max()
    frames = int(np.sum(rec.frames.num_detections > 0))
    return [
        f"{label}: {rec.duration:.0f} s, {frames} frames with the board, {len(rec.imu)} IMU samples",
        f"  {'task':<22} {'time[s]':>8} {'iter':>5} {'intr[%]':>9} {'rot[deg] trans[mm] dt[ms]':>26}",
        f"  {'cv2.calibrateCamera':<22} {t_cv:8.3f} {'':5} {'':9} {'':>26}",
        _row("intrinsic (GTSAM)", t_in, rec, r_in, f"ratio to OpenCV {t_in / t_cv:.2f}x, max |dK| {diff:.4f} px"),
        _row("extrinsic (known K)", t_ex, rec, r_ex),
        _row("joint (one graph)", t_jo, rec, r_jo),
        _row("two-stage", t_ts, rec, r_ts),
    ]


REAL_DURATIONS = (10.0, 30.0, 60.0, 120.0)  # [s] at 20 Hz
REAL_TARGETS = {"checkerboard 10x12": Target.checkerboard(10, 12, 0.04), "aprilgrid 6x6": Target.aprilgrid()}


def _common() -> dict:
    return {"time_offset": 0.01, "imu_noise": ImuNoise(), "pixel_sigma": 0.3, **BIASES}


def real_size(durations: tuple[float, ...]) -> list[str]:
    """Time and peak extra memory per task on real-size recordings, and the joint solve's growth."""
    lines = [
        "real size (20 Hz): time [s] and peak extra memory [MB] per task; growth = joint time per second of "
        "data against the 10 s case (1.00 = linear)",
        f"  {'target':<20} {'length':>6} {'frames':>6} {'corners':>8} {'intrinsic':>14} {'extrinsic':>14} "
        f"{'joint':>14} {'growth':>7} {'joint rot[deg] trans[mm] dt[ms]':>32}",
    ]
    for name, target in REAL_TARGETS.items():
        base = None
        for duration in durations:
            rec = make_recording(duration=duration, camera_rate_hz=20.0, target=target, seed=3, **_common())
            f, imu, noise = rec.frames, rec.imu, rec.truth.imu_noise
            cells = [
                _time_and_memory(calibrate_intrinsics, f, target, "radtan", SIZE),
                _time_and_memory(calibrate_extrinsics, f, imu, target, rec.truth.camera, noise),
                _time_and_memory(calibrate_joint, f, imu, target, "radtan", SIZE, noise),
            ]
            joint_s, joint = cells[2][0], cells[2][2]
            base = base or joint_s / duration
            e = calibration_errors(joint, rec.truth)
            frames = int(np.sum(f.num_detections > 0))
            task_cells = " ".join(f"{t:6.2f} {m:6.0f}MB" for t, m, _ in cells)
            errors = f"{e.rotation_deg:12.4f} {e.translation_mm:10.3f} {e.time_offset_ms:8.4f}"
            corners = int(f.num_detections.sum())
            growth = joint_s / duration / base
            lines.append(f"  {name:<20} {duration:5.0f}s {frames:6d} {corners:8d} {task_cells} {growth:7.2f} {errors}")
    return lines


def versus_opencv(repeats: int) -> list[str]:
    """The intrinsic task against cv2.calibrateCamera on the same 20 and ~600 frames."""
    lines = [
        "intrinsic calibration against cv2.calibrateCamera on the same detections (outlier rejection included)",
        f"  {'target':<20} {'frames':>6} {'OpenCV[s]':>10} {'vical[s]':>9} {'ratio':>6} {'max |dK| [px]':>14}",
    ]
    for name, target in REAL_TARGETS.items():
        rec = make_recording(duration=30.0, camera_rate_hz=20.0, target=target, seed=4, **_common())
        seen = np.flatnonzero(rec.frames.num_detections > 0)
        for count in (20, 600):
            chosen = seen[np.linspace(0, len(seen) - 1, min(count, len(seen))).round().astype(int)]
            mask = np.zeros(len(rec.frames), dtype=bool)
            mask[chosen] = True
            frames = rec.frames.select(mask)
            t_cv, K_cv, t_vi, r_vi = _interleaved_times(
                functools.partial(_opencv, rec, frames),
                functools.partial(calibrate_intrinsics, frames, target, "radtan", SIZE),
                repeats,
            )
            diff = np.abs(r_vi.camera.intrinsics - K_cv).max()
            lines.append(f"  {name:<20} {len(chosen):6d} {t_cv:10.3f} {t_vi:9.3f} {t_vi / t_cv:6.2f} {diff:14.4f}")
    return lines


def stride_cost() -> list[str]:
    """Every 2nd and 3rd frame against all of them (30 s aprilgrid, 20 Hz): time and shift in units of sigma."""
    rec = make_recording(duration=30.0, camera_rate_hz=20.0, target=REAL_TARGETS["aprilgrid 6x6"], seed=5, **_common())
    f, imu, noise = rec.frames, rec.imu, rec.truth.imu_noise
    lines = [
        "frame stride (joint, 30 s aprilgrid at 20 Hz): time, and the largest shift of an extrinsic, time-offset "
        "or camera estimate from the full solve in its sigma",
        f"  {'stride':>6} {'time[s]':>8} {'max |shift| / sigma':>20} {'worst':>12} {'sigma t_x [mm]':>15}",
    ]
    full = None
    for stride in (1, 2, 3):
        options = ViOptions(frame_stride=stride)
        start = time.perf_counter()
        result = calibrate_joint(f, imu, rec.target, "radtan", SIZE, noise, options=options)
        seconds = time.perf_counter() - start
        full = full or result
        names = full.parameter_names[:15]
        shift = np.abs(_stacked(result) - _stacked(full)) / np.array([full.sigma(n) for n in names])
        worst = names[int(np.argmax(shift))]
        lines.append(f"  {stride:6d} {seconds:8.2f} {shift.max():20.3f} {worst:>12} {1e3 * result.sigma('t_x'):15.3f}")
    return lines


def _stacked(result) -> np.ndarray:
    """Camera parameters, extrinsic rotation (vector w.r.t. the identity), translation, time offset."""
    return np.concatenate(
        [result.camera.parameters, so3_log(result.T_cam_imu[:3, :3]), result.T_cam_imu[:3, 3], [result.time_offset]]
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--quick", action="store_true", help="real-size cases of 10 and 30 s only")
    args = parser.parse_args()
    recordings = {
        "standard": make_recording(duration=20.0, seed=1, **_common()),
        "episode": make_recording(duration=8.0, seed=2, **_common()),
    }
    calibrate_intrinsics(recordings["episode"].frames, recordings["episode"].target, "radtan", SIZE)  # warm-up
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    for label, rec in recordings.items():
        print("\n".join(bench(label, rec, args.repeats)))
    print("\n".join(versus_opencv(args.repeats)))
    print("\n".join(real_size(REAL_DURATIONS[:2] if args.quick else REAL_DURATIONS)))
    print("\n".join(stride_cost()))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print(
        "targets: intrinsic <= 1.5x OpenCV (20 and 600 frames); extrinsic and joint <= 2.5 s and <= 500 MB at "
        "30 s / 20 Hz; growth ~1 (linear in the recording's length)"
    )


if __name__ == "__main__":
    main()
