"""A simulated person, guided or following written instructions: which way reaches the tolerances sooner?

The same simulated person (``person=sim``: 7 cm / 10 deg placement error per pose, 1.5 s minimum-jerk reaches,
1 mm / 0.3 deg tremor at 8-12 Hz; docs/simulation.md) holds each sensor and follows, pose by pose, in
``vical-guide``'s loop (``vical.collection.guide.Guide``, at corner level: nothing rendered, nothing written):

- **guided, rate planner**: ``vical-guide``'s default, the information-rate planner (``policy=rate_planner``,
  ``vical-collect``'s default), a step priced at the person's reach (``conf/guide.yaml``'s ``reach``) and drawn
  from a person's step (``workspace.action_scale``: what one reach covers, where the learned policies below
  step in the arm's box they were trained in);
- **guided, greedy planner**: the information-greedy planner (``policy=greedy_information``), predicting the same
  reaches among as many candidates (``conf/guide.yaml``'s ``policy.samples``);
- **guided, learned (person)**: the policy trained with the simulated person in the arm's place
  (``policy=learned_person``, ``vical-train +experiment=train_person_policy``), "done" by its own rule;
- **guided, learned (arm)**: the collection policy shipped for an arm (``policy=learned``);
- **written routine**: Kalibr's recommended routine as written instructions (``policy=expert_long``: views close
  and far, tilted, rolled, then swings along and about every axis), followed to its end without feedback, each pose
  shown at most a person's step from the last;
- **written routine + done**: the same, with a live "done" from the shared stopping rule (``stop=information``).

Per sensor: the recording time and path at the stop, whether "done" came (within the step limit), the joint
calibration's true errors, and whether a "done" was right (every scored group within its tolerance); the
table is ``vical-evaluate``'s time-to-tolerance table (paired 95 % intervals against the guide's default).

Sensors: reset seeds from 60000 (no training, fitting or test uses them; ``experiments/collect_gap.py`` evaluates
60000-60019 too); ``--sensors`` of them. ``--seed 40000`` measures on the tuning sensors instead (what a change is
tried on before it meets the held-out ones), ``--conditions`` on some of the conditions, ``--set`` with guide
settings changed for every condition, ``--reuse`` with the rows of the other conditions from an earlier run's
``results.csv`` (on the same sensors: what a change does not touch need not run again). ``--out DIR`` keeps the
runs: ``DIR/results.csv`` (``vical-evaluate``'s columns, one row per condition and sensor;
``vical.evaluation.results_file`` reads it back) and ``DIR/summary.md`` (the tables printed).

    python experiments/guided_comparison.py --sensors 30 --out evaluations/guided   # ~60 min on 2 cores
    python experiments/guided_comparison.py --sensors 12 --seed 40000 --conditions "guided, greedy planner"
    python experiments/guided_comparison.py --sensors 12 --seed 40000 --conditions "guided, greedy planner" \
        --set reach.min_s=2.0
"""

from __future__ import annotations

import argparse
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np
from hydra import compose, initialize_config_dir

from vical.apps.cli import plain
from vical.apps.collect import build_robot, configured_policy, nominal_sensor
from vical.apps.evaluate import results_csv, stops_table
from vical.apps.guide import CONF_DIR, build_guide, check_settings, guided_mdp
from vical.calib.tasks import CalibrationTask
from vical.config_checks import from_mapping
from vical.evaluation.harness import EpisodeRow, Evaluation, calibrate_row, summarize
from vical.evaluation.results_file import read_results
from vical.evaluation.time_to_tolerance import summarize_stops
from vical.io.atomic import files_together
from vical.policies.stopping import StopRule, information_settings

FIRST_SEED = 60000
# A person who loses the board from view goes on with the routine (a live vical-guide stops after 60 frames so that
# someone notices; here every condition goes on alike, and the frames without the board are no data).
NEVER_LOST = 1_000_000
REFERENCE = "guided, rate planner"  # vical-guide's default policy
CONDITIONS = {  # name: the guide's settings
    REFERENCE: ["policy=rate_planner"],
    "guided, greedy planner": ["policy=greedy_information"],
    "guided, learned (person)": ["policy=learned_person"],
    "guided, learned (arm)": ["policy=learned"],
    "written routine": ["policy=expert_long"],
    "written routine + done": ["policy=expert_long", "stop=information"],
}


def config(settings: list[str], task: str, seed: int):
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        return compose(config_name="guide", overrides=[
            *settings, f"task={task}", f"seed={seed}", "person.images=false", "page.enabled=false", "progress=false",
            "out=unused", f"limits.lost_frames={NEVER_LOST}"])  # fmt: skip


def guided_row(name: str, settings: list[str], task: str, seed: int) -> EpisodeRow:
    """One sensor (``seed``) held by the simulated person in condition ``name``: the stop and the true errors."""
    cfg = config(settings, task, seed)
    s = check_settings(cfg)
    policy = configured_policy(cfg, task, name)
    mdp = guided_mdp(cfg, policy)
    rig = build_robot(cfg.person, "person")
    try:
        guide = build_guide(cfg, s, rig, policy, mdp, nominal_sensor(s, rig), None, None, lambda line: None)
        result = guide.run(seed)
        recording = rig.recording()
    finally:
        rig.close()
    row = EpisodeRow(policy=name, seed=seed, recording_time_s=result.duration, path_length_m=result.path_length,
                     steps=result.steps, coverage_reached=result.goal_reached,
                     decision_ms=1e3 * result.decision_s / max(result.steps, 1))  # fmt: skip
    return calibrate_row(row, from_mapping(CalibrationTask, plain(cfg.task), "task"), recording)


def _row(run: tuple[str, list[str], str, int]) -> EpisodeRow:
    return guided_row(*run)


def tolerances(task: str) -> dict[str, float]:
    """The shared stopping rule's tolerances (the shipped learned run's information state)."""
    stop = config(["policy=learned", "stop=information"], task, 0).stop
    return information_settings(StopRule.from_config(plain(stop)))["information"]["tolerances"]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sensors", type=int, default=30)
    p.add_argument("--task", default="joint", choices=("intrinsic", "extrinsic", "joint"))
    p.add_argument("--workers", type=int, default=2, help="processes (one run each at a time)")
    p.add_argument("--seed", type=int, default=FIRST_SEED, help="the first sensor's reset seed")
    p.add_argument("--conditions", nargs="+", choices=list(CONDITIONS), default=list(CONDITIONS),
                   help="the conditions run (the reference's is always among them)")  # fmt: skip
    p.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE",
                   help="vical-guide settings for every condition (after each condition's own)")  # fmt: skip
    p.add_argument("--out", type=Path, help="a directory for results.csv and summary.md (written together)")
    p.add_argument("--reuse", type=Path, metavar="RESULTS_CSV",
                   help="an earlier --out's results.csv: the rows of conditions not run now")  # fmt: skip
    args = p.parse_args(argv)
    conditions = {name: [*CONDITIONS[name], *args.set] for name in CONDITIONS
                  if name == REFERENCE or name in args.conditions}  # fmt: skip
    rows: dict[str, list[EpisodeRow]] = {name: [] for name in conditions}
    seeds = range(args.seed, args.seed + args.sensors)
    runs = [(name, settings, args.task, seed) for seed in seeds for name, settings in conditions.items()]
    start = time.perf_counter()
    with ProcessPoolExecutor(args.workers, mp_context=get_context("spawn")) as pool:
        for n, row in enumerate(pool.map(_row, runs), start=1):
            rows[row.policy].append(row)
            errors = "failed" if row.failed else f"{row.rotation_deg:.3f} deg, {row.translation_mm:.2f} mm"
            print(f"{n}/{len(runs)} seed {row.seed} {row.policy}: {row.steps} poses, {row.recording_time_s:.1f} s, "
                  f"{row.path_length_m:.2f} m, done {row.coverage_reached}, {errors} "
                  f"[{time.perf_counter() - start:.0f} s]", file=sys.stderr, flush=True)  # fmt: skip
    if args.reuse is not None:  # what the settings changed here do not touch, from an earlier run on these sensors
        for row in read_results(args.reuse):
            if row.policy not in conditions and row.seed in seeds:
                rows.setdefault(row.policy, []).append(row)
    summary = summary_markdown(rows, args, seeds)
    print(summary, end="")
    if args.out is not None:
        with files_together(args.out) as path_of:
            path_of("results.csv").write_text(results_csv([Evaluation(rs, summarize(n, rs)) for n, rs in rows.items()]))
            path_of("summary.md").write_text(summary)
    return 0


def summary_markdown(rows: dict[str, list[EpisodeRow]], args: argparse.Namespace, seeds: range) -> str:
    """The time-to-tolerance table against the reference and each condition's median true errors."""
    settings = f", with {' '.join(args.set)}" if args.set else ""
    lines = [f"## {args.task} task, {args.sensors} simulated sensors (seeds {seeds[0]}-{seeds[-1]}){settings}",
             stops_table(summarize_stops(rows, args.task, tolerances(args.task), REFERENCE)), "",
             "| condition | true rotation median [deg] | true translation median [mm] | time offset median [ms] | "
             "failed calibrations |", "|---|---|---|---|---|"]  # fmt: skip
    for name, rs in rows.items():
        ok = [r for r in rs if not r.failed]
        rotation, translation, offset = (np.median([getattr(r, k) for r in ok]) if ok else np.nan
                                         for k in ("rotation_deg", "translation_mm", "time_offset_ms"))  # fmt: skip
        lines.append(f"| {name} | {rotation:.3f} | {translation:.2f} | {offset:.3f} | {len(rs) - len(ok)} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
