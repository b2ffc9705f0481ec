"""The runner against the env: one policy on the same sensors, in ``CalibrationEnv`` and through ``vical-collect``.

For each sensor (reset seeds ``--seed``.., used by no fit, training or evaluation) the policy runs
(a) one episode of the evaluation's env (projected corners with pixel noise, the simulator's own
start pose) and (b) one collection of ``vical.collection.runner.Collector`` on the simulated rig
(``vical.sim.adapters``: rendered images through the real detector, the alignment from live
detections with the nominal camera, ``--latency`` of command latency and ``--tracking-mm`` of
pose-tracking noise), whose EuRoC recording is read back as a user would. Both recordings are
calibrated by the same task solve and scored against the sensor's truth (which only this script
reads). Prints a table per sensor and the medians, and the share of episodes whose calibration
meets the policy's tolerances.

    .venv/bin/python experiments/collect_gap.py [--sensors 20] [--latency 0.02] [--tracking-mm 1]
"""

from __future__ import annotations

import argparse
import dataclasses
import tempfile
import time
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.apps.collect import FAULTS, build_collector, check_settings, mdp_config, nominal_sensor
from vical.calib.errors import CalibrationError
from vical.calib.tasks import CalibrationTask, run_task
from vical.evaluation.harness import build_env, instantiate_policy, run_trajectory
from vical.io.euroc import read_euroc
from vical.sim.adapters import RigFaults, SimRig
from vical.sim.sampling import SensorSampling
from vical.sim.settings import SimConfig

CONF = Path(__file__).resolve().parents[1] / "conf"
FIRST_SEED = 60_000


def plain(node):
    return OmegaConf.to_container(node, resolve=True)


def score(task: CalibrationTask, recording) -> dict[str, float]:
    """The task's errors of ``recording`` (its truth attached); NaN when the calibration failed."""
    try:
        e = run_task(task, recording).errors
    except CalibrationError:
        return {"failed": 1.0}
    return {"failed": 0.0, "rotation_deg": e.rotation_deg, "translation_mm": e.translation_mm,
            "time_offset_ms": e.time_offset_ms, "intrinsic_pct": e.intrinsic_pct}  # fmt: skip


def within(errors: dict[str, float], tol: dict[str, float]) -> bool:
    """The calibration met the extrinsic and time-offset tolerances (the task's "good enough")."""
    keys = ("rotation_deg", "translation_mm", "time_offset_ms")
    return not errors["failed"] and all(errors[k] <= tol[k] for k in keys if errors.get(k) is not None)


@dataclasses.dataclass(frozen=True)
class Collected:
    steps: int
    path_length: float
    goal_reached: bool
    stop: str


def collect_episode(cfg, seed: int, faults: RigFaults, policy, mdp, workdir: Path):
    """One collection on the simulated rig of ``seed``; its recording read back, with the truth attached."""
    s = check_settings(cfg)
    rig = SimRig(SimConfig.from_mapping(plain(cfg.sim)), SensorSampling.from_config(plain(cfg.sensor)), seed,
                 bool(cfg.task.asymmetric_distortion), faults)  # fmt: skip
    try:
        c = build_collector(cfg, s, rig, policy, mdp, nominal_sensor(s, rig), workdir / f"rec{seed}", lambda _: None)
        try:
            c.run(seed)
            stop = "done"
        except FAULTS as err:  # the recording so far stays calibratable: score it, and say why it stopped
            stop = f"stopped: {err}"
        truth, profile = rig.truth, rig.recorder.recording().path_profile
    finally:
        rig.close()
    rec = read_euroc(workdir / f"rec{seed}", c.target, keep_images=False)
    # The simulated end effector's path from the recording's start (the runner only sums straight lines).
    path = float(profile.length[-1] - np.interp(rec.imu.t[0], profile.t, profile.length))
    return dataclasses.replace(rec, truth=truth), Collected(c.episode.steps, path, c.state.goal_reached, stop)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--sensors", type=int, default=20)
    p.add_argument("--seed", type=int, default=FIRST_SEED)
    p.add_argument("--latency", type=float, default=0.02, help="[s] command latency")
    p.add_argument("--tracking-mm", type=float, default=1.0, help="[mm] pose-tracking noise per axis")
    p.add_argument("overrides", nargs="*", help="vical-collect overrides (policy.run_dir=..., task=...)")
    args = p.parse_args()
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="collect", overrides=["out=unused", *args.overrides])
        ev = compose(config_name="evaluate", overrides=[f"task={cfg.task.name}", f"workspace={cfg.workspace.name}"])
    policy = instantiate_policy(plain(cfg.policy)[cfg.task.name], "policy")
    mdp = mdp_config(cfg, policy)
    env = build_env(plain(ev.env), policy)
    task = CalibrationTask.from_config(plain(cfg.task))
    tol = dataclasses.asdict(mdp.information.tolerances)
    faults = RigFaults(latency=args.latency, tracking_noise_m=args.tracking_mm / 1e3,
                       tracking_noise_rad=np.radians(0.05) * args.tracking_mm)  # fmt: skip
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(args.seed, args.seed + args.sensors):
            t0 = time.perf_counter()
            traj = run_trajectory(env, policy, seed)
            env_err = score(task, traj.recording)
            rec, result = collect_episode(cfg, seed, faults, policy, mdp, Path(tmp))
            run_err = score(task, rec)
            rows.append((seed, traj, env_err, result, run_err))
            print(f"sensor {seed}: env {traj.steps} steps {traj.recording.path_length:.2f} m {fmt(env_err)} | "
                  f"runner {result.steps} steps {result.path_length:.2f} m {fmt(run_err)} [{result.stop}] "
                  f"({time.perf_counter() - t0:.0f} s)", flush=True)  # fmt: skip
    env.close()
    summarise(rows, tol)


def fmt(e: dict[str, float]) -> str:
    if e["failed"]:
        return "failed"
    return f"{e['rotation_deg']:.3f} deg {e['translation_mm']:.2f} mm {e['time_offset_ms']:.3f} ms"


def summarise(rows, tol) -> None:
    print("\n| | env (projected corners) | runner (rendered images, latency, tracking noise) |\n|---|---|---|")
    for key, unit in (("rotation_deg", "deg"), ("translation_mm", "mm"), ("time_offset_ms", "ms"),
                      ("intrinsic_pct", "%")):  # fmt: skip
        env_v = [r[2][key] for r in rows if not r[2]["failed"] and r[2].get(key) is not None]
        run_v = [r[4][key] for r in rows if not r[4]["failed"] and r[4].get(key) is not None]
        print(f"| median {key.split('_')[0]} error [{unit}] | {np.median(env_v):.3f} | {np.median(run_v):.3f} |")
    steps = [np.median([r[k].steps for r in rows]) for k in (1, 3)]
    print(f"| median steps | {steps[0]:.0f} | {steps[1]:.0f} |")
    print(f"| median path [m] | {np.median([r[1].recording.path_length for r in rows]):.2f} | "
          f"{np.median([r[3].path_length for r in rows]):.2f} |")  # fmt: skip
    print(f"| stopped at the goal | {np.mean([r[1].coverage_reached for r in rows]):.0%} | "
          f"{np.mean([r[3].goal_reached for r in rows]):.0%} |")  # fmt: skip
    print(f"| calibration within tolerance | {np.mean([within(r[2], tol) for r in rows]):.0%} | "
          f"{np.mean([within(r[4], tol) for r in rows]):.0%} |")  # fmt: skip
    print(f"| collection stopped on a fault | 0% | {np.mean([r[3].stop != 'done' for r in rows]):.0%} |")
    print(f"| calibration failed | {np.mean([r[2]['failed'] for r in rows]):.0%} | "
          f"{np.mean([r[4]['failed'] for r in rows]):.0%} |")  # fmt: skip


if __name__ == "__main__":
    main()
