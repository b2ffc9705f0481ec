"""Why collections do not finish: each group's predicted and true excess at the horizon, and the finish time.

Runs policies of the time-to-tolerance yardstick (``+experiment=time_to_tolerance_<task>``: the same sensors, stop
rule and tolerances) past its horizon, to ``--long`` seconds of recording, and traces every step's predicted
error over tolerance per parameter group (the information state the stop reads). Per run it writes, to
``<out>/<task>.csv``: the sensor's properties (lens family and nominal field of view, board kind and size, IMU
grade, true time offset), the time the goal was first met (none within ``--long``: blank), each group's predicted
ratio at the horizon and the true error ratio of a calibration of the recording cut at the horizon, and the whole
trace (``trace``: JSON of [time, {group: ratio}] per step). Then prints, per policy, the share finished by 45, 60,
90 and 120 s (``--checkpoints``) and the table of the unfinished runs at the horizon.

    .venv/bin/python experiments/why_unfinished.py --tasks joint intrinsic --episodes 20 --seed 40000
    .venv/bin/python experiments/why_unfinished.py --reuse --out evaluations/why_unfinished   # print again
    .venv/bin/python experiments/why_unfinished.py --reuse --warmup 15 25 --margin 2 3 --hold 10 15  # verdicts
    .venv/bin/python experiments/why_unfinished.py --yardstick evaluations/time_to_tolerance  # the yardstick's own
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import itertools
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from vical.apps.evaluate import policy_configs
from vical.calib.errors import CalibrationError
from vical.calib.metrics import group_errors_px
from vical.calib.tasks import CalibrationTask, run_task
from vical.data import NS_PER_S
from vical.env.reachability import ReachForecast, ReachSettings
from vical.evaluation.harness import PolicyEvaluator, PolicySpec, halfway_forecast
from vical.evaluation.results_file import read_results
from vical.io.atomic import atomic_file
from vical.parallel import ParallelConfig, imap_ordered
from vical.policies.stopping import StopRule, information_settings
from vical.rl.envs import make_env

ROOT = Path(__file__).resolve().parents[1]
TRUE_KEYS = {"focal": "focal_px", "principal_point": "principal_point_px", "distortion": "distortion_px",
             "rotation": "rotation_deg", "translation": "translation_mm", "time_offset": "time_offset_ms"}  # fmt: skip
PAPER_ACCEL_NOISE = None  # the paper's accelerometer density, read from conf/sensor/paper.yaml at start


def compose_config(task: str, policies: Sequence[str], long_s: float) -> dict:
    """The yardstick's config of ``task`` with ``policies``, run to ``long_s`` of recording."""
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(
            config_name="evaluate",
            overrides=[
                f"+experiment=time_to_tolerance_{task}",
                f"policies=[{','.join(policies)}]",
                f"stop.horizon_s={long_s}",
                "stop.verify_s=null",
                "stop.max_steps=1000",
            ],
        )
    stop = StopRule.from_config(OmegaConf.to_container(cfg.stop, resolve=True))
    specs = [PolicySpec.from_config(c, "policy") for c in policy_configs(cfg, "learned")]
    return {
        "task": task,
        "specs": [(s, stop) for s in specs],
        "env": OmegaConf.to_container(cfg.env, resolve=True),
        "horizon_s": float(OmegaConf.load(ROOT / "conf/experiment" / f"time_to_tolerance_{task}.yaml").stop.horizon_s),
        "tolerances": information_settings(stop)["information"]["tolerances"],
    }


_CACHE: dict[str, PolicyEvaluator] = {}


def trace_run(job: tuple) -> dict:
    """One run of a policy on one sensor, traced past the horizon (module doc)."""
    spec, stop, env_cfg, seed, horizon_s, tolerances = job
    key = json.dumps([spec.name, env_cfg], sort_keys=True, default=str)
    if key not in _CACHE:
        _CACHE[key] = PolicyEvaluator(dataclasses.replace(spec, stop=stop), env_cfg)
    evaluator = _CACHE[key]
    env, policy = evaluator.envs[0], evaluator.policies[0]
    obs, _ = env.reset(seed=seed)
    policy.reset(env, np.random.default_rng(seed))
    trace, finished_s = [], None
    long_ns = stop.horizon_s * NS_PER_S
    for _ in range(env.config.max_steps):
        action = policy.act(obs, env)
        if policy.finished:
            break
        obs, _, _, truncated, _ = env.step(action)
        t = env.sim.time_ns / NS_PER_S
        trace.append([round(t, 3), {g: round(float(r), 4) for g, r in env.state.ratios.items()}])
        if env.goal_reached:
            finished_s = t
            break
        if truncated or env.sim.time_ns >= long_ns:
            break
    recording = env.recording()
    goal = list(env.state.goal_ratios)
    at_horizon = next((ratios for t, ratios in reversed(trace) if t <= horizon_s), {})
    cut = recording.until(recording.t0 + int(horizon_s * NS_PER_S))
    true = true_ratios(evaluator.task, cut, tolerances)
    return {
        "policy": spec.name, "seed": seed, "goal": goal, "finished_s": finished_s,
        "end_s": trace[-1][0] if trace else 0.0, **sensor_properties(env),
        "predicted": at_horizon, "true": true, "trace": trace,
    }  # fmt: skip


def sensor_properties(env) -> dict:
    """The properties of the sensor ``env`` drew at its last reset that the unfinished runs are tabled by."""
    camera = env.product.sampling.camera
    board = env.product.board or {}
    return {
        "lens": camera.distortion, "hfov_deg": round(math.degrees(camera.hfov.mean), 1),
        "board": board.get("kind", ""), "square_mm": round(1e3 * float(board.get("square", math.nan)), 1),
        "imu_grade": env.product.sampling.imu.accel_noise,
        "time_offset_ms": round(1e3 * float(env.recording().truth.time_offset), 2),
    }  # fmt: skip


def true_ratios(task: CalibrationTask, recording, tolerances: dict) -> dict:
    """Each group's true error over its tolerance of ``task``'s calibration of ``recording`` (empty: failed)."""
    try:
        outcome = run_task(task, recording)
    except CalibrationError:
        return {}
    errors = dict(group_errors_px(outcome.result.camera, recording.truth.camera))
    e = outcome.errors
    errors.update(rotation=e.rotation_deg, translation=e.translation_mm, time_offset=e.time_offset_ms)
    return {g: round(float(v) / tolerances[TRUE_KEYS[g]], 4) for g, v in errors.items() if v is not None}


def run(task: str, policies: Sequence[str], seeds: Sequence[int], long_s: float, workers: int) -> list[dict]:
    c = compose_config(task, policies, long_s)
    jobs = [(s, stop, c["env"], seed, c["horizon_s"], c["tolerances"]) for s, stop in c["specs"] for seed in seeds]
    rows = []
    for row in imap_ordered(trace_run, jobs, ParallelConfig(workers=workers)):
        done = "-" if row["finished_s"] is None else f"{row['finished_s']:.1f} s"
        print(f"{task} {row['policy']} sensor {row['seed']}: finished {done}", file=sys.stderr, flush=True)
        rows.append(row)
    return rows


FIELDS = ("policy", "seed", "goal", "finished_s", "end_s", "lens", "hfov_deg", "board", "square_mm", "imu_grade",
          "time_offset_ms", "predicted", "true", "trace")  # fmt: skip


def write_rows(path: Path, rows: Sequence[dict]) -> None:
    import io

    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, FIELDS)
    writer.writeheader()
    for row in rows:
        writer.writerow({k: json.dumps(v) if isinstance(v, dict | list) else v for k, v in row.items()})
    with atomic_file(path) as tmp:
        tmp.write_text(buffer.getvalue())


def read_rows(path: Path) -> list[dict]:
    rows = []
    with path.open() as f:
        for raw in csv.DictReader(f):
            row = dict(raw)
            for k in ("goal", "predicted", "true", "trace"):
                row[k] = json.loads(row[k])
            row["finished_s"] = float(row["finished_s"]) if row["finished_s"] else None
            for k in ("seed",):
                row[k] = int(row[k])
            for k in ("end_s", "hfov_deg", "square_mm", "imu_grade", "time_offset_ms"):
                row[k] = float(row[k])
            rows.append(row)
    return rows


def shares_table(rows: Sequence[dict], checkpoints: Sequence[float]) -> str:
    lines = ["| policy | sensors | " + " | ".join(f"finished by {c:g} s" for c in checkpoints) + " |",
             "|---|---|" + "---|" * len(checkpoints)]  # fmt: skip
    for name in dict.fromkeys(r["policy"] for r in rows):
        mine = [r for r in rows if r["policy"] == name]
        cells = [f"{np.mean([r['finished_s'] is not None and r['finished_s'] <= c for r in mine]):.0%}"
                 for c in checkpoints]  # fmt: skip
        lines.append(f"| {name} | {len(mine)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def unfinished_table(rows: Sequence[dict], horizon_s: float) -> str:
    head = "| policy | sensor | lens, hfov | board | IMU grade | offset [ms] | short at the horizon: predicted / true "
    lines = [head + "(x tolerance) | finished at [s] |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r["finished_s"] is not None and r["finished_s"] <= horizon_s:
            continue
        short = [f"{g} {r['predicted'].get(g, math.nan):.2f} / {r['true'].get(g, math.nan):.2f}"
                 for g in r["goal"] if r["predicted"].get(g, 0.0) > 1.0]  # fmt: skip
        done = "-" if r["finished_s"] is None else f"{r['finished_s']:.0f}"
        lines.append(f"| {r['policy']} | {r['seed']} | {r['lens']} {r['hfov_deg']:.0f} deg | {r['board']} "
                     f"{r['square_mm']:.0f} mm | {r['imu_grade'] / PAPER_ACCEL_NOISE:.1f}x | "
                     f"{r['time_offset_ms']:+.1f} | {', '.join(short)} | {done} |")  # fmt: skip
    return "\n".join(lines)


def yardstick_rows(task: str, results: Path) -> list[dict]:
    """The yardstick's runs that did not meet the goal (``vical-evaluate``'s ``results`` of ``task``), each with its
    sensor's properties (drawn again from its seed), the goal groups it lacked at its horizon or verdict (predicted,
    ``short_at_horizon``), their true error over tolerance (the calibration of the recording it ended with) and when
    a run stopped as out of reach met the goal when run on (``reached_s``)."""
    c = compose_config(task, ["rate_planner"], 45.0)
    env = make_env(c["env"])
    rows = []
    try:
        for row in read_results(results):
            if row.coverage_reached:
                continue
            env.reset(seed=row.seed)
            words = row.short_at_horizon.split()  # "time_offset 1.64 rotation 1.37"
            predicted = dict(zip(words[::2], map(float, words[1::2]), strict=True))
            true = {g: getattr(row, key) / c["tolerances"][key] for g, key in TRUE_KEYS.items()
                    if g in predicted and getattr(row, key) is not None}  # fmt: skip
            rows.append({"policy": row.policy, "seed": row.seed, **sensor_properties(env), "predicted": predicted,
                         "true": true, "out_of_reach": row.out_of_reach, "verdict_s": row.verdict_s,
                         "reached_s": row.reached_s})  # fmt: skip
    finally:
        env.close()
    return rows


def yardstick_table(rows: Sequence[dict]) -> str:
    """The yardstick's unfinished runs (``yardstick_rows``), one line each."""
    lines = ["| policy | sensor | lens, hfov | board | IMU grade | offset [ms] | ended | short: predicted / true "
             "(x tolerance) | goal met at [s] |", "|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for r in rows:
        short = ", ".join(f"{g} {p:.2f} / {r['true'].get(g, math.nan):.2f}" for g, p in r["predicted"].items())
        ended = f"out of reach ({r['out_of_reach']}) at {r['verdict_s']:.0f} s" if r["out_of_reach"] else "horizon"
        met = "-" if r["reached_s"] is None else f"{r['reached_s']:.0f}"
        lines.append(f"| {r['policy']} | {r['seed']} | {r['lens']} {r['hfov_deg']:.0f} deg | {r['board']} "
                     f"{r['square_mm']:.0f} mm | {r['imu_grade'] / PAPER_ACCEL_NOISE:.1f}x | "
                     f"{r['time_offset_ms']:+.1f} | {ended} | {short} | {met} |")  # fmt: skip
    return "\n".join(lines)


def groups_table(rows: Sequence[dict]) -> str:
    """Per goal group: how many unfinished runs lacked it and the sensor properties those runs share."""
    lines = ["| group short | runs | IMU grade >= 3x | checkerboard | wide lens (hfov >= 100 deg) | offset > 5 ms |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for group in dict.fromkeys(g for r in rows for g in r["predicted"]):
        mine = [r for r in rows if group in r["predicted"]]
        shares = [np.mean([r["imu_grade"] / PAPER_ACCEL_NOISE >= 3.0 for r in mine]),
                  np.mean([r["board"] == "checkerboard" for r in mine]), np.mean([r["hfov_deg"] >= 100 for r in mine]),
                  np.mean([abs(r["time_offset_ms"]) > 5.0 for r in mine])]  # fmt: skip
        lines.append(f"| {group} | {len(mine)} | " + " | ".join(f"{v:.0%}" for v in shares) + " |")
    return "\n".join(lines)


def replay(row: dict, horizon_s: float, settings: ReachSettings) -> dict:
    """The reachability forecast of ``row``'s traced run, step by step as the evaluation makes it
    (``vical.evaluation.harness.run_trajectory``): the verdict's time (None: none within the horizon) and the goal's
    time the forecast predicted halfway to the finish (``halfway_forecast``; None: not finished)."""
    forecast = ReachForecast(dict.fromkeys(row["goal"], 1.0), settings)
    verdict_s, forecasts = None, []
    for t, ratios in row["trace"]:
        forecast.add(t, {g: ratios[g] for g in row["goal"]})
        if row["finished_s"] is not None and t >= row["finished_s"]:
            break
        forecasts.append((t, forecast.needed_s()))
        if forecast.verdict(horizon_s) is not None:
            verdict_s = t
            break
        if t >= horizon_s:
            break
    return {"verdict_s": verdict_s, "predicted_s": halfway_forecast(forecasts, row["finished_s"])}


def reach_table(rows: Sequence[dict], horizon_s: float, grid: Sequence[ReachSettings]) -> str:
    """Per setting of the verdict and policy, how its runs would end with it (``replay``): finished within the
    horizon, stopped as out of reach (and how many of those finished within twice the horizon: wrong verdicts),
    neither; and the share of finished runs whose predicted time is within 1.5x of the measured."""
    lines = ["| warm-up [s] | margin | hold [s] | rate window | policy | runs | finished | out of reach | wrong "
             "verdicts | neither | forecast within 1.5x |", "|---" * 11 + "|"]  # fmt: skip
    for settings in grid:
        for name in dict.fromkeys(r["policy"] for r in rows):
            mine = [(r, replay(r, horizon_s, settings)) for r in rows if r["policy"] == name]
            stopped = [r for r, p in mine if p["verdict_s"] is not None]
            finished = [
                (r, p) for r, p in mine if p["verdict_s"] is None and (r["finished_s"] or math.inf) <= horizon_s
            ]
            wrong = [r for r in stopped if (r["finished_s"] or math.inf) <= 2 * horizon_s]
            good = [p["predicted_s"] is not None and 1 / 1.5 <= p["predicted_s"] / r["finished_s"] <= 1.5
                    for r, p in finished]  # fmt: skip
            within = f"{np.mean(good):.0%}" if good else "-"
            lines.append(f"| {settings.warmup_s:g} | {settings.margin:g} | {settings.hold_s:g} | "
                         f"{settings.rate_fraction:g}, >= {settings.min_window_s:g} s | {name} | {len(mine)} | "
                         f"{len(finished) / len(mine):.0%} | {len(stopped) / len(mine):.0%} | {len(wrong)} of "
                         f"{len(stopped)} | {1 - (len(finished) + len(stopped)) / len(mine):.0%} | "
                         f"{within} |")  # fmt: skip
    return "\n".join(lines)


def main() -> None:
    global PAPER_ACCEL_NOISE
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--tasks", nargs="+", default=["joint", "intrinsic"], choices=["joint", "intrinsic"])
    p.add_argument("--policies", nargs="+", default=["rate_planner", "expert_long"])
    p.add_argument("--episodes", type=int, default=20)
    p.add_argument("--seed", type=int, default=40000)
    p.add_argument("--long", type=float, default=120.0, help="[s] recording each run goes on to")
    p.add_argument("--checkpoints", type=float, nargs="+", default=[45, 60, 90, 120])
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--out", type=Path, default=ROOT / "evaluations" / "why_unfinished")
    d = ReachSettings()
    p.add_argument("--warmup", type=float, nargs="+", default=[d.warmup_s], help="[s] the verdict's warm-ups")
    p.add_argument("--margin", type=float, nargs="+", default=[d.margin], help="its margins on the horizon")
    p.add_argument("--hold", type=float, nargs="+", default=[d.hold_s], help="[s] how long a group stays late")
    p.add_argument("--rate-fraction", type=float, nargs="+", default=[d.rate_fraction], help="the rate's window")
    p.add_argument("--min-window", type=float, nargs="+", default=[d.min_window_s], help="[s] its shortest")
    p.add_argument("--reuse", action="store_true", help="print the tables of the results already written")
    p.add_argument("--yardstick", type=Path, help="table the unfinished runs of the yardstick's results in "
                   "<this>/<task>/**/results.csv (experiments/time_to_tolerance.py's --out) instead")  # fmt: skip
    args = p.parse_args()
    PAPER_ACCEL_NOISE = float(OmegaConf.load(ROOT / "conf/sensor/paper.yaml").imu.accel_noise)
    if args.yardstick is not None:
        for task in args.tasks:
            rows = [r for path in sorted((args.yardstick / task).rglob("results.csv"))
                    for r in yardstick_rows(task, path)]  # fmt: skip
            print(f"\n**{task} task** ({len(rows)} unfinished runs)\n\n{groups_table(rows)}\n\n{yardstick_table(rows)}")
        return
    seeds = range(args.seed, args.seed + args.episodes)
    for task in args.tasks:
        path = args.out / f"{task}.csv"
        if not (args.reuse and path.is_file()):
            path.parent.mkdir(parents=True, exist_ok=True)
            write_rows(path, run(task, args.policies, seeds, args.long, args.workers))
        rows = read_rows(path)
        horizon = float(OmegaConf.load(ROOT / "conf/experiment" / f"time_to_tolerance_{task}.yaml").stop.horizon_s)
        print(f"\n**{task} task** ({len(rows)} runs, {path})\n\n{shares_table(rows, args.checkpoints)}\n")
        print(unfinished_table(rows, horizon))
        print()
        grid = [ReachSettings(warmup_s=w, margin=m, rate_fraction=f, min_window_s=n, hold_s=h)
                for w, m, f, n, h in itertools.product(args.warmup, args.margin, args.rate_fraction, args.min_window,
                                                       args.hold)]  # fmt: skip
        print(reach_table(rows, horizon, grid))


if __name__ == "__main__":
    main()
