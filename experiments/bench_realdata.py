"""Real-data benchmark: vical-calibrate on a real stereo camera + IMU recording, against its published calibrations
and beside independent implementations measured in the same run.

Data: the first 36 s of EuRoC's ``imu_april`` (``../shared/realdata/euroc_imu_april_0-36s``: YAC's AprilGrid
detections of both cameras and the ADIS16448 IMU), calibrated with the dataset's own published IMU noise and
intrinsics, as a user would type them in. For each camera set (cam0; cam0 + cam1), task (extrinsic with the
published intrinsics; joint) and window (0-10, 10-20, 20-30 and 0-30 s) one ``vical-calibrate`` process runs and
the table gives its errors against EuRoC's and Basalt's published extrinsics, cam1-to-cam0 against EuRoC's, the
time offset, the focal lengths against EuRoC's, the reported 1-sigma, the solve and the whole command's wall time
and its peak memory over the imports' (the 30 s runs: medians of ``--repeats`` processes run one after the
other). The peers, on the same corners and IMU: OpenCV's ``calibrateCamera`` (radtan, k3 fixed) for the
intrinsics and a plain GTSAM graph with the declared noise (``plain_gtsam.py``, which imports nothing from
vical.calib) for the extrinsic.

    python experiments/bench_realdata.py                 # everything (~7 min alone on 2 cores)
    python experiments/bench_realdata.py --quick         # cam0, extrinsic, 0-10 s (what the test runs)

Outputs (the inputs written for vical-calibrate, its result folders) go to ``--out`` (a temporary folder by
default), never into the data folder, which may be read-only.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
DATA = HERE.parents[1] / "shared" / "realdata" / "euroc_imu_april_0-36s"
WINDOWS = ((0.0, 10.0), (10.0, 20.0), (20.0, 30.0), (0.0, 30.0))
TASKS = ("extrinsic", "joint")
CAMERA_SETS = (("cam0",), ("cam0", "cam1"))

# The published calibrations (the data folder's README): EuRoC's sensor.yaml (Kalibr) and Basalt's cam0.
EUROC = {
    "cam0": np.array([[0.014865543, 0.999557249, -0.025774437, 0.065222909],
                      [-0.999880929, 0.014967213, 0.003756188, -0.020706385],
                      [0.004140297, 0.025715530, 0.999660727, -0.008054602], [0, 0, 0, 1]]),
    "cam1": np.array([[0.012555267, 0.999598781, -0.025389801, -0.044901981],
                      [-0.999755100, 0.013011905, 0.017900584, -0.020569771],
                      [0.018223771, 0.025158836, 0.999517347, -0.008638135], [0, 0, 0, 1]]),
}  # fmt: skip
BASALT_CAM0 = np.array([[0.014883170, 0.999670680, -0.020905090, 0.069273334],
                        [-0.999889070, 0.014892081, 0.000270668, -0.015747675],
                        [0.000581899, 0.020898743, 0.999781428, -0.003687501], [0, 0, 0, 1]])  # fmt: skip
EUROC_FOCAL = {"cam0": (458.654, 457.296), "cam1": (457.587, 456.134)}
# The parameters whose 10 s estimates are compared with each other (rotations as the camera-frame rotation
# vector between two windows' R_cam_imu, the others as estimated).
CONSISTENCY_PARAMETERS = ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z", "time_offset", "fx", "fy")


def rotation_deg(R: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))


def pose_error(T: np.ndarray, ref: np.ndarray) -> tuple[float, float]:
    """(deg, mm) between two transforms."""
    return rotation_deg(T[:3, :3] @ ref[:3, :3].T), float(1e3 * np.linalg.norm(T[:3, 3] - ref[:3, 3]))


def write_inputs(data: Path, out: Path) -> dict[str, Path]:
    """target.yaml, imu.yaml and the intrinsics-only camchain from the data's own published values."""
    config = yaml.safe_load((data / "yac_config.yaml").read_text())
    board, imu = config["calib_target"], config["imu0"]
    files = {"target": out / "target.yaml", "imu": out / "imu.yaml", "intrinsics": out / "camchain.yaml"}
    files["target"].write_text(yaml.safe_dump({
        "target_type": "aprilgrid", "tagRows": board["tag_rows"], "tagCols": board["tag_cols"],
        "tagSize": board["tag_size"], "tagSpacing": board["tag_spacing"]}))  # fmt: skip
    files["imu"].write_text(yaml.safe_dump({
        "accelerometer_noise_density": imu["sigma_a_c"], "accelerometer_random_walk": imu["sigma_aw_c"],
        "gyroscope_noise_density": imu["sigma_g_c"], "gyroscope_random_walk": imu["sigma_gw_c"],
        "update_rate": imu["rate"], "rostopic": "/imu0"}))  # fmt: skip
    chain = {
        name: {"camera_model": "pinhole", "intrinsics": config[name]["proj_params"], "distortion_model": "radtan",
               "distortion_coeffs": config[name]["dist_params"], "resolution": config[name]["resolution"]}
        for name in ("cam0", "cam1")
    }  # fmt: skip
    files["intrinsics"].write_text(yaml.safe_dump(chain))
    return files


# ---------------------------------------------------------------------------------------- one vical run (child)
def run_one(spec: dict) -> dict:
    """One vical-calibrate in this process (spawned fresh per run): its results, times and peak memory."""
    start = float(spec["process_start"])
    from vical.apps.calibrate import build_parser, run

    base_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    argv = [spec["data"], "--task", spec["task"], "--target", spec["target"], "--imu-yaml", spec["imu"],
            "--cameras", ",".join(spec["cameras"]), "--start", str(spec["window"][0]),
            "--duration", str(spec["window"][1] - spec["window"][0]), "--out", spec["out"], "--overwrite",
            "--no-report"]  # fmt: skip
    if spec["task"] == "extrinsic":
        argv += ["--intrinsics", spec["intrinsics"]]
    else:  # corners without images: the size comes from the command line, as a user gives it
        argv += ["--image-size", "752", "480"]
    argv += spec.get("flags", [])  # e.g. --rolling-shutter (experiments/rolling_shutter.py)
    with open(os.devnull, "w") as quiet:
        stdout, sys.stdout = sys.stdout, quiet
        try:
            out = run(build_parser().parse_args(argv))
        finally:
            sys.stdout = stdout
    results = out.results if hasattr(out, "results") else {"cam0": out}
    cameras = {}
    for name, r in results.items():
        sigma = np.sqrt(np.abs(np.diag(r.covariance)))
        at = {n: i for i, n in enumerate(r.parameter_names)}
        cameras[name] = {
            "T_cam_imu": r.T_cam_imu.tolist(), "time_offset": r.time_offset, "fx": r.camera.fx, "fy": r.camera.fy,
            "sigma_rot_deg": float(np.degrees(np.linalg.norm(sigma[[at["rot_x"], at["rot_y"], at["rot_z"]]]))),
            "sigma_t_mm": float(1e3 * np.linalg.norm(sigma[[at["t_x"], at["t_y"], at["t_z"]]])),
            "sigma_offset_ms": float(1e3 * sigma[at["time_offset"]]), "solve_time": r.solve_time,
            "noise_scale": r.imu_noise_scale, "pixel_sigma": r.pixel_sigma, "iterations": r.iterations,
            "sigmas": {n: float(sigma[at[n]]) for n in CONSISTENCY_PARAMETERS if n in at},
            "imu_terms": [{"effect": {n: t.effect[at[n]].tolist() for n in CONSISTENCY_PARAMETERS if n in at},
                           "spread": t.spread.tolist()} for t in r.unmodelled_imu],
            "line_delay": r.line_delay, "warnings": list(r.warnings), "camera": r.camera.to_dict(),
            "sigma_line_delay": float(sigma[at["line_delay"]]) if "line_delay" in at else None,
        }  # fmt: skip
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"cameras": cameras, "command_s": time.time() - start, "extra_mb": peak_mb - base_mb}


def timed(spec: dict, repeats: int) -> dict:
    """``spawn`` ``repeats`` times: the first run's results with the median solve, command time and memory."""
    runs = [spawn(spec) for _ in range(repeats)]
    if any("error" in r for r in runs):
        return next(r for r in runs if "error" in r)
    first = runs[0]
    for name, camera in first["cameras"].items():
        camera["solve_time"] = float(np.median([r["cameras"][name]["solve_time"] for r in runs]))
    first["command_s"] = float(np.median([r["command_s"] for r in runs]))
    first["extra_mb"] = float(np.median([r["extra_mb"] for r in runs]))
    return first


def spawn(spec: dict) -> dict:
    """``run_one`` in a fresh Python process (its imports and memory are the command's own)."""
    spec = {**spec, "process_start": time.time()}
    done = subprocess.run([sys.executable, __file__, "--one", json.dumps(spec)], capture_output=True, text=True,
                          check=False)  # fmt: skip
    if done.returncode != 0:
        return {"error": (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]}
    return json.loads(done.stdout.strip().splitlines()[-1])


# ---------------------------------------------------------------------------------------- peers (this process)
def window_recording(data: Path, target_yaml: Path, window: tuple[float, float]):
    from vical.apps.calibrate import time_window
    from vical.io.kalibr import read_target_yaml
    from vical.io.sources import open_recording

    rec = open_recording(data, read_target_yaml(target_yaml))
    return time_window(rec, window[0], window[1] - window[0])


def opencv_intrinsics(frames, target, max_views: int = 60) -> tuple[float, float, float, float]:
    """(fx, fy, rms px, seconds) of ``cv2.calibrateCamera`` (radtan, k3 fixed) on at most ``max_views`` views
    spread over the window."""
    import cv2

    seen = [k for k in range(len(frames)) if len(frames.ids[k]) >= 12]
    chosen = [seen[int(i)] for i in np.linspace(0, len(seen) - 1, min(max_views, len(seen)))]
    objects = [target.points[frames.ids[k]].astype(np.float32) for k in chosen]
    images = [frames.corners[k].astype(np.float32) for k in chosen]
    start = time.perf_counter()
    rms, K, *_ = cv2.calibrateCamera(objects, images, (752, 480), None, None, flags=cv2.CALIB_FIX_K3)
    return float(K[0, 0]), float(K[1, 1]), float(rms), time.perf_counter() - start


def plain_extrinsic(rec, name: str, intrinsics_yaml: Path, imu_yaml: Path) -> tuple[np.ndarray, float]:
    """T_cam_imu of the plain GTSAM graph for camera ``name`` and its wall time."""
    sys.path.insert(0, str(HERE))
    import plain_gtsam

    config = yaml.safe_load(intrinsics_yaml.read_text())[name]
    fx, fy, cx, cy = config["intrinsics"]
    K = np.array([[fx, 0, cx], [0, fy, cy], [0, 0, 1.0]])
    noise = yaml.safe_load(imu_yaml.read_text())
    frames = rec.frames_of(name)
    views = plain_gtsam.Frames(frames.t, frames.corners, [rec.target.points[i] for i in frames.ids])
    start = time.perf_counter()
    result = plain_gtsam.calibrate(views, rec.imu.t, rec.imu.gyro, rec.imu.accel, K,
                                   np.array(config["distortion_coeffs"]), noise)  # fmt: skip
    return result.T_cam_imu, time.perf_counter() - start


# ---------------------------------------------------------------------------------------- table
def vical_rows(cameras: tuple[str, ...], task: str, window, found: dict) -> list[str]:
    label = f"{'+'.join(cameras):9} {task:9} {window[0]:4.0f}-{window[1]:<3.0f}"
    if "error" in found:
        return [f"{label} vical  FAILED: {found['error']}"]
    rows = []
    for name, c in found["cameras"].items():
        T = np.array(c["T_cam_imu"])
        deg, mm = pose_error(T, EUROC[name])
        basalt = " ".join(f"{v:6.3f}" for v in pose_error(T, BASALT_CAM0)) if name == "cam0" else "     -      -"
        fx, fy = EUROC_FOCAL[name]
        focal = (
            f"{100 * (c['fx'] / fx - 1):+5.2f} {100 * (c['fy'] / fy - 1):+5.2f}" if task == "joint" else "    -     -"
        )
        rows.append(
            f"{label} {name:5} {deg:6.3f} {mm:6.2f} {basalt} {1e3 * c['time_offset']:+6.3f} {focal} "
            f"{c['sigma_rot_deg']:6.3f} {c['sigma_t_mm']:5.2f} {c['noise_scale']:5.2f} {c['solve_time']:6.2f} "
            f"{found['command_s']:6.2f} {found['extra_mb']:6.0f}"
        )
    if len(found["cameras"]) == 2:
        T0, T1 = (np.array(found["cameras"][n]["T_cam_imu"]) for n in ("cam0", "cam1"))
        deg, mm = pose_error(T1 @ np.linalg.inv(T0), EUROC["cam1"] @ np.linalg.inv(EUROC["cam0"]))
        rows.append(f"{label} T_c1_c0 vs EuRoC: {deg:.3f} deg, {mm:.2f} mm")
    return rows


def window_values(camera: dict, reference: np.ndarray) -> dict[str, float]:
    """One window's estimates by parameter name; rotations relative to ``reference`` (R_cam_imu) [rad]."""
    T = np.array(camera["T_cam_imu"])
    rotation = Rotation.from_matrix(T[:3, :3] @ reference.T).as_rotvec()
    values = dict(zip(("rot_x", "rot_y", "rot_z"), rotation, strict=True))
    values |= dict(zip(("t_x", "t_y", "t_z"), T[:3, 3], strict=True))
    return values | {"time_offset": camera["time_offset"], "fx": camera["fx"], "fy": camera["fy"]}


def consistency_rows(label: str, windows: list[dict]) -> list[str]:
    """Do the 10 s windows agree within their own sigmas, and do the sigmas explain their spread?

    Each window's 1-sigma holds a part the windows share: the IMU's unmodelled scales and misalignments
    (``UnmodelledImuTerms``), one IMU's, shift every window by ``effect @ delta`` with the same ``delta``. So two
    windows differ with the covariance ``D_a + D_b + (e_a - e_b) S (e_a - e_b)^T`` (``D`` a window's covariance
    without that part, ``S`` the terms' spread, the two windows' mean), and the windows' spread about their mean
    should be ``mean D + sum (e_i - e_mean) S (e_i - e_mean)^T / (n - 1)``: what differs between them. The part
    they share, ``e_mean S e_mean^T``, no spread of windows can show; it is printed beside (against the references,
    which differ by 0.34 deg / 8.0 mm, not against each other).

    Per parameter: the largest difference between two windows over its 1-sigma, and that sigma of the spread over
    the standard deviation of the windows' estimates (honest: near 1; over 2: too wide). Three windows give a
    spread of 2 degrees of freedom, so one parameter's ratio is a weak reading: with honest sigmas it exceeds 2 in
    22 % of parameters (P(chi2_2 / 2 < 1/4)). The last row pools the parameters (``pooled_ratio``)."""
    reference = np.array(windows[0]["T_cam_imu"])[:3, :3]
    values = [window_values(w, reference) for w in windows]
    rows, spreads, sigmas = [], [], []
    for name in windows[0]["sigmas"]:
        x = np.array([v[name] for v in values])
        z, expected, shared = _agreement(x, *_window_parts(windows, name))
        spread = float(np.std(x, ddof=1))
        spreads.append(spread)
        sigmas.append(np.sqrt(expected))
        rows.append(
            f"{label} {name:11} max |diff| / sigma {z:5.2f}   sigma / spread {np.sqrt(expected) / spread:5.2f}   "
            f"shared 1-sigma {_in_units(name, np.sqrt(shared))}"
        )
    ratio, low, high = pooled_ratio(np.array(spreads), np.array(sigmas), len(windows))
    rows.append(f"{label} pooled      sigma / spread {ratio:5.2f}   (honest sigmas: {low:.2f}-{high:.2f}, 95 %)")
    return rows


def _agreement(x: np.ndarray, own: np.ndarray, effects: np.ndarray, spreads: list[np.ndarray]):
    """The largest difference of two windows over its sigma, the windows' expected spread (a variance) and the
    variance they share (``consistency_rows``)."""

    def through_terms(d: np.ndarray) -> float:  # (K, 6) effects' difference: the variance it carries
        return sum(float(d[k] @ S @ d[k]) for k, S in enumerate(spreads))

    pairs = [(a, b) for a in range(len(x)) for b in range(a + 1, len(x))]
    z = max(abs(x[a] - x[b]) / np.sqrt(own[a] + own[b] + through_terms(effects[a] - effects[b])) for a, b in pairs)
    mean = effects.mean(axis=0)
    expected = float(np.mean(own)) + sum(through_terms(e - mean) for e in effects) / (len(x) - 1)
    return z, expected, through_terms(mean)


def _window_parts(windows: list[dict], name: str) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Per window, the parameter's variance without the IMU terms (W,), its effects (W, K, 6) per sensor k, and
    each sensor's spread (6, 6) averaged over the windows."""
    variances = np.array([w["sigmas"][name] ** 2 for w in windows])
    if not windows[0].get("imu_terms"):
        return variances, np.zeros((len(windows), 0, 6)), []
    effects = np.array([[t["effect"][name] for t in w["imu_terms"]] for w in windows])
    spreads = [
        np.mean([np.array(w["imu_terms"][k]["spread"]) for w in windows], axis=0) for k in range(effects.shape[1])
    ]
    own = variances - np.array(
        [sum(float(e @ np.array(t["spread"]) @ e) for e, t in zip(effects[i], w["imu_terms"], strict=True))
         for i, w in enumerate(windows)]
    )  # fmt: skip
    return own, effects, spreads


def _in_units(name: str, sigma: float) -> str:
    if name.startswith("rot"):
        return f"{np.degrees(sigma):.3f} deg"
    if name.startswith("t_"):
        return f"{1e3 * sigma:.2f} mm"
    return f"{1e3 * sigma:.3f} ms" if name == "time_offset" else f"{sigma:.2f} px"


def pooled_ratio(spreads: np.ndarray, sigmas: np.ndarray, windows: int) -> tuple[float, float, float]:
    """The parameters' sigma over their windows' spread, pooled, and the range 95 % of honest sigmas give.

    With honest sigmas each (windows - 1) s^2 / sigma^2 is chi-square with windows - 1 degrees of freedom;
    their sum over P parameters has P (windows - 1) (treating the parameters as independent), and
    sqrt(dof / sum) estimates sigma / spread."""
    from scipy.stats import chi2

    dof = len(spreads) * (windows - 1)
    total = float(np.sum((windows - 1) * spreads**2 / sigmas**2))
    return np.sqrt(dof / total), np.sqrt(dof / chi2.ppf(0.975, dof)), np.sqrt(dof / chi2.ppf(0.025, dof))


HEADER = (
    "cameras   task      window  cam    EuRoC: deg    mm Basalt: deg  mm  dt ms fx %  fy %   1sig deg  mm noise x "
    "solve s  cmd s  +MB"
)


def print_consistency(found: dict) -> None:
    """The three 10 s windows of each camera set and task against each other (``consistency_rows``)."""
    print("\nthe three 10 s windows against each other")
    for cameras in CAMERA_SETS:
        for task in TASKS:
            runs = [found.get((cameras, task, w)) for w in WINDOWS[:3]]
            if any(r is None or "error" in r for r in runs):
                continue
            for name in cameras:
                label = f"{'+'.join(cameras):9} {task:9} {name:5}"
                for row in consistency_rows(label, [r["cameras"][name] for r in runs]):
                    print(row)


def published_frame_rows(found: dict, published: dict) -> list[str]:
    """Each joint run's extrinsic turned into the camera frame of the published intrinsics (``camera_frame_turn``:
    the principal points differ by ~7 px, ~0.9 deg), against the published extrinsics and, per parameter in its
    own 1-sigma, against the extrinsic task's estimate of the same window (which used the published intrinsics).
    The turn is under 1 deg: it changes the sigmas by under 2 %, so they are used as reported."""
    from vical.geometry import CameraModel, camera_frame_turn

    rows = []
    for (cameras, task, window), joint in found.items():
        extrinsic = found.get((cameras, "extrinsic", window))
        if task != "joint" or "error" in joint or extrinsic is None or "error" in extrinsic:
            continue
        for name, c in joint["cameras"].items():
            turn = np.eye(4)
            turn[:3, :3] = camera_frame_turn(CameraModel.from_dict(c["camera"]), published[name])
            T = turn @ np.array(c["T_cam_imu"])
            basalt = " Basalt {:.3f} deg {:.2f} mm".format(*pose_error(T, BASALT_CAM0)) if name == "cam0" else ""
            ratios = _in_sigmas(T, np.array(extrinsic["cameras"][name]["T_cam_imu"]), c["sigmas"])
            euroc = "{:.3f} deg {:.2f} mm".format(*pose_error(T, EUROC[name]))
            worst = max(ratios, key=ratios.get)
            rows.append(
                f"{'+'.join(cameras):9} {window[0]:4.0f}-{window[1]:<3.0f} {name:5} turned "
                f"{rotation_deg(turn[:3, :3]):.3f} deg: EuRoC {euroc}{basalt}; "
                f"vs the extrinsic task max |diff| / sigma {ratios[worst]:.2f} ({worst})"
            )
    return rows


def _in_sigmas(T: np.ndarray, other: np.ndarray, sigmas: dict[str, float]) -> dict[str, float]:
    """|T - other| per rotation (camera-frame rotation vector) and translation component over ``sigmas``."""
    difference = np.r_[Rotation.from_matrix(T[:3, :3] @ other[:3, :3].T).as_rotvec(), T[:3, 3] - other[:3, 3]]
    names = ("rot_x", "rot_y", "rot_z", "t_x", "t_y", "t_z")
    return {n: float(abs(d) / sigmas[n]) for n, d in zip(names, difference, strict=True)}


def print_published_frame(found: dict, files: dict[str, Path]) -> None:
    from vical.io import read_chain

    rows = published_frame_rows(found, {c.name: c.camera for c in read_chain(files["intrinsics"]).cameras})
    if rows:
        print("\nthe joint task's extrinsic in the published intrinsics' camera frame")
        print("\n".join(rows))


def print_peers(data: Path, files: dict[str, Path], windows, cameras) -> None:
    """The plain GTSAM graph's extrinsic and OpenCV's intrinsics on the same corners and IMU."""
    print("\npeers on the same corners and IMU")
    for window in windows:
        rec = window_recording(data, files["target"], window)
        for name in cameras:
            T, seconds = plain_extrinsic(rec, name, files["intrinsics"], files["imu"])
            deg, mm = pose_error(T, EUROC[name])
            basalt = " Basalt {:.3f} deg {:.2f} mm".format(*pose_error(T, BASALT_CAM0)) if name == "cam0" else ""
            print(f"plain GTSAM {name} {window[0]:.0f}-{window[1]:.0f} s: EuRoC {deg:.3f} deg {mm:.2f} mm{basalt}, "
                  f"{seconds:.2f} s")  # fmt: skip
            fx, fy, rms, seconds = opencv_intrinsics(rec.frames_of(name), rec.target)
            ref = EUROC_FOCAL[name]
            focal = f"fx {100 * (fx / ref[0] - 1):+.2f} % fy {100 * (fy / ref[1] - 1):+.2f} %"
            print(f"OpenCV calibrateCamera {name} {window[0]:.0f}-{window[1]:.0f} s: {focal} rms {rms:.3f} px, "
                  f"{seconds:.2f} s")  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, help=f"the real recording (default: {DATA})")
    p.add_argument("--out", type=Path, help="work folder (default: a temporary one)")
    p.add_argument("--quick", action="store_true", help="cam0, extrinsic, 0-10 s only")
    p.add_argument("--repeats", type=int, default=5, help="runs of each 30 s calibration (medians of the times)")
    p.add_argument("--one", help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.one:
        print(json.dumps(run_one(json.loads(args.one))))
        return 0
    if args.data is None and not DATA.is_dir():  # `make bench` beside a checkout without the dev set
        print(f"bench_realdata: skipped: the real dev set is not at {DATA}; pass --data <its folder>")
        return 0
    args.data = args.data or DATA
    if not args.data.is_dir():
        print(f"bench_realdata: error: no real recording at {args.data}; pass --data <its folder>", file=sys.stderr)
        return 2
    out = args.out or Path(tempfile.mkdtemp(prefix="vical-bench-realdata-"))
    out.mkdir(parents=True, exist_ok=True)
    files = write_inputs(args.data, out)
    plan = [(("cam0",), "extrinsic", WINDOWS[0])] if args.quick else [
        (c, t, w) for c in CAMERA_SETS for t in TASKS for w in WINDOWS]  # fmt: skip
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) at the start; {args.data}")
    print(HEADER)
    found = {}
    for n, (cameras, task, window) in enumerate(plan, start=1):
        spec = {"data": str(args.data), "task": task, "cameras": list(cameras), "window": list(window),
                "out": str(out / f"run{n}"), **{k: str(v) for k, v in files.items()}}  # fmt: skip
        found[cameras, task, window] = timed(spec, args.repeats if window == WINDOWS[-1] else 1)
        for row in vical_rows(cameras, task, window, found[cameras, task, window]):
            print(row, flush=True)
    print_consistency(found)
    print_published_frame(found, files)
    print_peers(
        args.data, files, [WINDOWS[0]] if args.quick else WINDOWS, ("cam0",) if args.quick else ("cam0", "cam1")
    )
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) at the end; work folder {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
