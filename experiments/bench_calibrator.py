"""Benchmark of the calibrator: solve time and errors per task, with OpenCV side by side.

Two synthetic recordings (``vical.calib.synthetic``, IMU noise from the paper, 0.3 px corners,
10 ms time offset, non-zero biases): a standard 20 s one and an episode-sized 8 s one. For the
intrinsic task ``cv2.calibrateCamera`` (k3 fixed to 0) runs on the same corners in the same
process; the table shows both times, their ratio and the largest difference in fx, fy, cx, cy.
Times are the median of ``--repeats`` runs (default 5) (the machine may be shared: the load is printed).

    .venv/bin/python experiments/bench_calibrator.py [--repeats 5]
"""

from __future__ import annotations

import argparse
import os
import time

import cv2
import numpy as np

from vical.calib.calibrate import calibrate_extrinsics, calibrate_joint, calibrate_two_stage
from vical.calib.intrinsics import calibrate_intrinsics
from vical.calib.metrics import calibration_errors
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Recording

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


def _opencv(rec: Recording):
    used = [k for k in range(len(rec.frames)) if len(rec.frames.ids[k]) >= 4]
    obj = [rec.target.points[rec.frames.ids[k]].astype(np.float32) for k in used]
    img = [rec.frames.corners[k].astype(np.float32) for k in used]
    _, K, _, _, _ = cv2.calibrateCamera(obj, img, SIZE, None, None, flags=cv2.CALIB_FIX_K3)
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]])


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    common = {"time_offset": 0.01, "imu_noise": ImuNoise(), "pixel_sigma": 0.3, **BIASES}
    recordings = {
        "standard": make_recording(duration=20.0, seed=1, **common),
        "episode": make_recording(duration=8.0, seed=2, **common),
    }
    calibrate_intrinsics(recordings["episode"].frames, recordings["episode"].target, "radtan", SIZE)  # warm-up
    print(f"load average before: {' '.join(f'{v:.2f}' for v in os.getloadavg())} on {os.cpu_count()} cores")
    for label, rec in recordings.items():
        print("\n".join(bench(label, rec, args.repeats)))
    print(f"load average after: {' '.join(f'{v:.2f}' for v in os.getloadavg())}")
    print("targets: intrinsic <= 1.5x OpenCV; joint <= 2 s (20 s recording), <= 1.5 s (episode)")


if __name__ == "__main__":
    main()
