"""Rolling shutters: the line delay estimated with the camera-IMU extrinsic and time offset, against the truth and
against a global-shutter model of the same data; the first-order error of the model; the cost; the real recording.

Sections (each prints a table; ``docs/calibration.md``, "Rolling shutter", holds the results):

- ``synthetic``: corner-level recordings (``vical.calib.synthetic``: 20 s, 20 Hz, Kalibr's aprilgrid, 0.3 px,
  the paper's IMU noise and biases) with line delays 0, 10, 20, 40 us/row at 480 rows, ``--seeds`` each (time offsets
  drawn from +-20 ms), extrinsic and joint tasks: the rolling-shutter model's errors against the acceptance
  tolerances (line delay 5 % or 0.5 us/row, 0.1 deg, 2 mm, 0.5 ms), its sigmas' honesty (|error| within 1 and 3
  reported sigma, pooled over rot_x..t_z, time_offset, line_delay), and the global-shutter model's errors and its
  rolling-shutter warning on the same recordings.
- ``first-order``: noise-free recordings at 40 us/row: the errors that remain are the model's (each corner's pose
  taken to first order in its time from the state).
- ``cost``: the joint solve with and without the line delay on the same recording (a 40 us/row one and a global-
  shutter one), medians of ``--repeats`` runs one after the other.
- ``rendered``: ``vical-record sensor=rolling_shutter sensor.backend=render`` (MuJoCo images in bands of rows, the
  checkerboard detector) at 0, 10, 20, 40 us/row, 3 seeds each, 8 pose steps (4 s at 20 Hz): the extrinsic and
  joint tasks with and without the line delay, against the recording's truth.
- ``realdata``: the real global-shutter recording (``../shared/realdata``, 0-30 s; ``bench_realdata.py``'s inputs):
  the estimated line delay, its sigma, how far the extrinsic moves from the global-shutter solve, the warnings.

    python experiments/rolling_shutter.py                  # everything (~25 min alone on 2 cores)
    python experiments/rolling_shutter.py --only cost --repeats 5
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from vical.calib.solve.pipeline import calibrate_extrinsics, calibrate_joint
from vical.calib.solve.vi_problem import ViOptions
from vical.calib.synthetic import make_recording
from vical.data import ImuNoise, Target
from vical.geometry import so3_log
from vical.io.recording import load_recording

HERE = Path(__file__).resolve().parent
US = 1e-6
DELAYS_US = (0.0, 10.0, 20.0, 40.0)
TOLERANCES = {"rotation_deg": 0.1, "translation_mm": 2.0, "time_offset_ms": 0.5}
Z_PARAMETERS = ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset", "line_delay")
SECTIONS = ("synthetic", "first-order", "cost", "rendered", "realdata")
# vical-record's pose steps for the rendered recordings: [dx, dy, dz, droll, dpitch, dyaw] (conf/record.yaml), the
# default four and four more that pan, tilt and roll both ways.
RENDERED_STEPS = (
    "[[0.0,0.08,0.0,0.0,0.0,0.25],[0.0,-0.16,0.05,0.2,-0.1,-0.5],[0.1,0.08,-0.08,-0.35,0.2,0.25],"
    "[-0.1,0.0,0.03,0.15,-0.1,0.0],[0.0,0.08,0.0,0.2,0.2,0.25],[0.05,-0.16,0.0,-0.3,-0.2,-0.4],"
    "[-0.05,0.08,0.05,0.25,0.1,0.3],[0.0,0.0,-0.05,-0.2,0.0,-0.15]]"
)


def recording(line_delay: float, seed: int, noisy: bool = True):
    rng = np.random.default_rng(seed)
    return make_recording(
        duration=20.0, camera_rate_hz=20.0, target=Target.aprilgrid(), seed=seed,
        time_offset=float(rng.uniform(-0.02, 0.02)), pixel_sigma=0.3 if noisy else 0.0,
        imu_noise=ImuNoise() if noisy else None, gyro_bias=rng.normal(0, 0.01, 3) if noisy else None,
        accel_bias=rng.normal(0, 0.05, 3) if noisy else None, line_delay=line_delay,
    )  # fmt: skip


def calibrate(rec, task: str, rolling: bool, noise: ImuNoise | None = None, pixel_sigma: float | None = None):
    """``task``'s solve of ``rec`` with (``rolling``) or without the line delay, the IMU declared as ``noise`` (the
    paper's densities by default), the corners weighted as ``pixel_sigma`` (None: the noise their residuals show)."""
    options, noise = ViOptions(rolling_shutter=rolling, pixel_sigma=pixel_sigma), noise or ImuNoise()
    if task == "joint":
        return calibrate_joint(rec.frames, rec.imu, rec.target, "radtan", (640, 480), noise, options=options)
    return calibrate_extrinsics(rec.frames, rec.imu, rec.target, rec.truth.camera, noise, options=options)


def errors(result, truth) -> dict[str, float]:
    """Absolute errors, and the signed ones over the reported sigma of ``Z_PARAMETERS`` the result has."""
    rotation = so3_log(result.T_cam_imu[:3, :3] @ truth.T_cam_imu[:3, :3].T)
    translation = result.T_cam_imu[:3, 3] - truth.T_cam_imu[:3, 3]
    signed = dict(zip(("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z"), [*rotation, *translation], strict=True))
    signed["time_offset"] = result.time_offset - truth.time_offset
    out = {
        "rotation_deg": float(np.rad2deg(np.linalg.norm(rotation))),
        "translation_mm": float(np.linalg.norm(translation) * 1e3),
        "time_offset_ms": float(abs(signed["time_offset"]) * 1e3),
    }
    out["kept"] = any("could not be told" in w for w in result.warnings)  # left at its prior: not estimated
    if "line_delay" in result.parameter_names:
        signed["line_delay"] = result.line_delay - truth.line_delay
        out["line_delay_us"] = float(abs(signed["line_delay"]) / US)
        out["line_delay_ok"] = abs(signed["line_delay"]) <= max(0.05 * truth.line_delay, 0.5 * US)
    out["z"] = [signed[n] / result.sigma(n) for n in Z_PARAMETERS if n in signed]
    out["warned"] = any("as a rolling shutter's do" in w for w in result.warnings)
    out["solve_s"] = result.solve_time
    return out


def synthetic(seeds: int) -> None:
    print(f"\n## synthetic: {seeds} seeds per line delay, 480 rows, 0.3 px, 20 s at 20 Hz")
    print(
        "| line delay [us/row] | task | model | line delay err median / max [us/row] | within 5 % or 0.5 us/row "
        "| rot err median / max [deg] | trans err median / max [mm] | offset err median / max [ms] | all within "
        "tolerance | within 1 / 3 sigma | RS warning | solve [s] |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for delay in DELAYS_US:
        recs = [recording(delay * US, seed) for seed in range(seeds)]
        for task in ("extrinsic", "joint"):
            for rolling in (True, False):
                rows = [errors(calibrate(rec, task, rolling), rec.truth) for rec in recs]
                print(_synthetic_row(delay, task, rolling, rows), flush=True)


def _synthetic_row(delay: float, task: str, rolling: bool, rows: list[dict]) -> str:
    def spread(key: str, fmt: str) -> str:
        values = np.array([r[key] for r in rows if key in r])
        return f"{np.median(values):{fmt}} / {np.max(values):{fmt}}" if len(values) else "-"

    within = np.mean([all(r[k] <= t for k, t in TOLERANCES.items()) for r in rows])
    z = np.abs(np.concatenate([r["z"] for r in rows]))
    line = spread("line_delay_us", ".3f") if rolling else "-"
    ok = f"{np.mean([r.get('line_delay_ok', False) for r in rows]):.0%}" if rolling else "-"
    warned = "-" if rolling else f"{np.mean([r['warned'] for r in rows]):.0%}"
    return (
        f"| {delay:g} | {task} | {'rolling' if rolling else 'global'} | {line} | {ok} | "
        f"{spread('rotation_deg', '.3f')} | {spread('translation_mm', '.2f')} | {spread('time_offset_ms', '.3f')} | "
        f"{within:.0%} | {np.mean(z <= 1):.0%} / {np.mean(z <= 3):.0%} | "
        f"{warned} | "
        f"{np.median([r['solve_s'] for r in rows]):.2f} |"
    )


def first_order() -> None:
    print("\n## first-order: noise-free recordings at 40 us/row (the model's own error)")
    print("| seed | task | corners weighted as [px] | line delay err [us/row] | rot err [deg] | trans err [mm] | "
          "offset err [ms] | rms [px] |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for seed in range(3):
        rec = recording(40 * US, seed, noisy=False)
        for task in ("extrinsic", "joint"):
            # As the noisy recordings' corners (0.3 px), and as noise-free ones (at the noise floor, 0.01 px: the
            # model's error is then all the corners show, against the IMU's declared noise).
            for pixel_sigma in (0.3, None):
                result = calibrate(rec, task, True, pixel_sigma=pixel_sigma)
                e = errors(result, rec.truth)
                print(
                    f"| {seed} | {task} | {pixel_sigma or result.pixel_sigma:.2f} | {e['line_delay_us']:.4f} | "
                    f"{e['rotation_deg']:.4f} | {e['translation_mm']:.3f} | {e['time_offset_ms']:.4f} | "
                    f"{result.reprojection.rms:.4f} |",
                    flush=True,
                )


def cost(repeats: int) -> None:
    print(f"\n## cost: the joint solve, medians of {repeats} runs one after the other (nothing else running)")
    print("| recording | global shutter [s] | rolling shutter [s] | ratio | iterations (global / rolling) |")
    print("|---|---|---|---|---|")
    for delay in (0.0, 40.0):
        rec = recording(delay * US, 100)
        times = {True: [], False: []}
        iterations = {}
        for _ in range(repeats):
            for rolling in (False, True):
                start = time.perf_counter()
                result = calibrate(rec, "joint", rolling)
                times[rolling].append(time.perf_counter() - start)
                iterations[rolling] = result.iterations
        g, r = np.median(times[False]), np.median(times[True])
        print(f"| synthetic, {delay:g} us/row | {g:.2f} | {r:.2f} | {r / g:.2f} | {iterations[False]} / "
              f"{iterations[True]} |", flush=True)  # fmt: skip
    realdata_cost(repeats)


def rendered(seeds: int) -> None:
    print(f"\n## rendered: vical-record sensor=rolling_shutter sensor.backend=render, {seeds} seeds per line delay")
    print(
        "| line delay [us/row] | task | model | line delay err median / max [us/row] | rot err median / max [deg] "
        "| trans err median / max [mm] | offset err median / max [ms] | RS warning |"
    )
    print("|---|---|---|---|---|---|---|---|")
    record = Path(sys.executable).parent / "vical-record"
    with tempfile.TemporaryDirectory(prefix="vical-rolling-shutter-") as work:
        for delay in DELAYS_US:
            recs = []
            for seed in range(seeds):
                out = Path(work) / f"{delay:g}-{seed}"
                args = [str(record), "sensor=rolling_shutter", "sensor.backend=render", f"seed={seed}",
                        f"sensor.camera.line_delay.mean={delay * US}", "sensor.camera.line_delay.std=0",
                        f"out={out}", "progress=false", "settle_time=0", f"steps={RENDERED_STEPS}"]  # fmt: skip
                subprocess.run(args, check=True, capture_output=True, text=True)
                recs.append(load_recording(out))
            for task in ("extrinsic", "joint"):
                for rolling in (True, False):
                    rows = [errors(calibrate(rec, task, rolling, rec.truth.imu_noise), rec.truth) for rec in recs]
                    print(_rendered_row(delay, task, rolling, rows), flush=True)


def _rendered_row(delay: float, task: str, rolling: bool, rows: list[dict]) -> str:
    def spread(key: str, fmt: str) -> str:
        values = np.array([r[key] for r in rows if key in r])
        return f"{np.median(values):{fmt}} / {np.max(values):{fmt}}" if len(values) else "-"

    kept = sum(r["kept"] for r in rows)
    line = spread("line_delay_us", ".3f") + (f" ({kept} kept at 0)" if kept else "") if rolling else "-"
    warned = "-" if rolling else f"{np.mean([r['warned'] for r in rows]):.0%}"
    return (
        f"| {delay:g} | {task} | {'rolling' if rolling else 'global'} | {line} | {spread('rotation_deg', '.3f')} | "
        f"{spread('translation_mm', '.2f')} | {spread('time_offset_ms', '.3f')} | {warned} |"
    )


def _bench():
    sys.path.insert(0, str(HERE))
    import bench_realdata

    return bench_realdata


def _spec(bench, files, out: Path, cameras, task: str, flags: list[str]) -> dict:
    return {
        "data": str(bench.DATA), "task": task, "cameras": list(cameras), "window": [0.0, 30.0],
        "out": str(out / f"{'-'.join(cameras)}-{task}-{len(flags)}"), **{k: str(v) for k, v in files.items()},
        "flags": flags,
    }  # fmt: skip


def realdata_cost(repeats: int) -> None:
    bench = _bench()
    if not bench.DATA.is_dir():
        print(f"| real recording | skipped: no dev set at {bench.DATA} | | | |")
        return
    out = Path(tempfile.mkdtemp(prefix="vical-rolling-shutter-"))
    files = bench.write_inputs(bench.DATA, out)
    found = {len(flags): bench.timed(_spec(bench, files, out, ("cam0",), "joint", flags), repeats)
             for flags in ([], ["--rolling-shutter"])}  # fmt: skip
    g, r = (found[k]["cameras"]["cam0"]["solve_time"] for k in (0, 1))
    print(f"| real (EuRoC cam0, 0-30 s) | {g:.2f} | {r:.2f} | {r / g:.2f} | - |")


def realdata() -> None:
    bench = _bench()
    print("\n## realdata: EuRoC imu_april 0-30 s (global shutter), the published intrinsics and IMU noise")
    if not bench.DATA.is_dir():
        print(f"skipped: the real dev set is not at {bench.DATA}")
        return
    print(
        "| cameras | task | camera | line delay [us/row] | z | extrinsic moves [deg / mm] | vs EuRoC (global / "
        "rolling) [deg / mm] | rolling-shutter warnings (global solve) |"
    )
    print("|---|---|---|---|---|---|---|---|")
    out = Path(tempfile.mkdtemp(prefix="vical-rolling-shutter-"))
    files = bench.write_inputs(bench.DATA, out)
    for cameras in (("cam0",), ("cam0", "cam1")):
        for task in ("extrinsic", "joint"):
            flag_sets = ([], ["--rolling-shutter"])
            runs = [bench.spawn(_spec(bench, files, out, cameras, task, flags)) for flags in flag_sets]
            for name in cameras:
                print(_realdata_row(bench, cameras, task, name, *(r["cameras"][name] for r in runs)), flush=True)


def _realdata_row(bench, cameras, task: str, name: str, plain: dict, rolling: dict) -> str:
    T_plain, T_rolling = np.array(plain["T_cam_imu"]), np.array(rolling["T_cam_imu"])
    moved = bench.pose_error(T_rolling, T_plain)
    euroc = [bench.pose_error(T, bench.EUROC[name]) for T in (T_plain, T_rolling)]
    delay, sigma = rolling["line_delay"], rolling["sigma_line_delay"]
    warned = sum("as a rolling shutter's do" in w for w in plain["warnings"])
    return (
        f"| {'+'.join(cameras)} | {task} | {name} | {delay / US:+.3f} +- {sigma / US:.3f} | {delay / sigma:+.2f} | "
        f"{moved[0]:.4f} / {moved[1]:.3f} | {euroc[0][0]:.3f} / {euroc[0][1]:.2f}, {euroc[1][0]:.3f} / "
        f"{euroc[1][1]:.2f} | {warned} |"
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--only", choices=SECTIONS, action="append", help="run these sections (default: all)")
    p.add_argument("--seeds", type=int, default=20, help="recordings per line delay (synthetic)")
    p.add_argument("--repeats", type=int, default=5, help="runs per timed solve (cost)")
    p.add_argument("--rendered-seeds", type=int, default=3, help="rendered recordings per line delay")
    args = p.parse_args(argv)
    chosen = args.only or SECTIONS
    if "synthetic" in chosen:
        synthetic(args.seeds)
    if "first-order" in chosen:
        first_order()
    if "cost" in chosen:
        cost(args.repeats)
    if "rendered" in chosen:
        rendered(args.rendered_seeds)
    if "realdata" in chosen:
        realdata()
    return 0


if __name__ == "__main__":
    sys.exit(main())
