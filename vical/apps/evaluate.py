"""``vical-evaluate``: run policies on sampled sensors, calibrate every episode, print the tables.

Config: ``conf/evaluate.yaml`` (groups ``sim``, ``sensor``, ``task``, ``env``, ``workspace``, ``policy``;
``policies`` for a table of several; ``budgets`` for error versus path; ``+experiment=table1_intrinsic``
etc. for the paper's tables). Writes ``<out>/results.csv`` (one row per episode and budget),
``<out>/summary.md`` (the tables) and, with budgets, ``<out>/error_vs_effort.png``, together: with
``overwrite=true`` the old files stay until all the new ones are made.

User-facing errors (an unknown policy, a missing run directory of the learned policy, a bad config
value) print one line ``vical-evaluate: error: ...`` and exit with status 2, as ``vical-train`` does.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import hydra
from hydra import compose, initialize_config_dir
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf, open_dict
from omegaconf.errors import OmegaConfBaseException

from vical.apps.cli import (
    OutputError,
    check_composes,
    check_creatable,
    check_launcher,
    fail,
    hydra_start_up_held,
    one_line_warnings,
    override_value,
    plain,
    quiet_library_logs,
    task_begins,
    write_faults_in_one_line,
)
from vical.apps.entry import run as run_command
from vical.calib.tasks import CalibrationTask
from vical.config_checks import ConfigError, require
from vical.evaluation.error_vs_effort import (
    BudgetSummary,
    budget_label,
    significance_lines,
    summarize_effort,
    write_effort_figure,
)
from vical.evaluation.harness import (
    COLUMNS,
    EPISODE_FAILED,
    Evaluation,
    PolicySpec,
    Summary,
    check_budgets,
    evaluate_policies,
    instantiate_policy,
)
from vical.evaluation.intervals import Interval
from vical.evaluation.time_to_tolerance import StopSummary, summarize_stops
from vical.evaluation.yardstick import PROTOCOL_KEYS, fingerprint
from vical.io.atomic import files_together
from vical.parallel import ParallelConfig, WorkerCrashed
from vical.policies.stopping import StopRule, information_settings, with_stop

# An absolute path: the console script imports this module from anywhere.
CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
POLICY_DIR = CONF_DIR / "policy"
USER_ERRORS = (ConfigError, FileNotFoundError, FileExistsError, OutputError, OmegaConfBaseException, WorkerCrashed)
APP = "vical-evaluate"
RESULTS, SUMMARY, FIGURE = "results.csv", "summary.md", "error_vs_effort.png"

# The table: header, Summary attribute, format. Absolute errors read by users follow the paper's columns.
TABLE = (
    ("policy", "policy", "{}"),
    ("mean error [%]", "mean_error_pct", "{:.2f}"),
    ("error std [%]", "error_std_pct", "{:.2f}"),
    ("path length [m]", "path_length_m", "{:.2f}"),
    ("calibration time [s]", "calib_time_s", "{:.2f}"),
    ("intrinsics [px]", "intrinsic_px", "{:.2f}"),
    ("rotation [deg]", "rotation_deg", "{:.3f}"),
    ("translation [mm]", "translation_mm", "{:.2f}"),
    ("time offset [ms]", "time_offset_ms", "{:.3f}"),
    ("coverage", "coverage_rate", "{:.0%}"),
    ("failed", "failed", "{}"),
)


def known_policies() -> list[str]:
    """Names of the policy configs in ``conf/policy/``."""
    return sorted(p.stem for p in POLICY_DIR.glob("*.yaml"))


def check_policy_name(name: Any) -> str:
    """``name`` if ``conf/policy/<name>.yaml`` exists; ``ConfigError`` listing the known policies otherwise."""
    if not isinstance(name, str) or name not in known_policies():
        raise ConfigError(f"unknown policy {name!r}; known policies (conf/policy/): {known_policies()}")
    return name


def policy_configs(cfg: DictConfig, chosen: str | None) -> list[dict]:
    """The resolved configs of the policies to evaluate, in table order.

    ``policies`` lists names; the one equal to the ``policy`` group's choice is ``cfg.policy`` (with its
    command-line overrides), the others are read from ``conf/policy/<name>.yaml`` and resolved in the
    root config (so they may interpolate it, as ``model_based`` does ``${workspace.name}``).
    """
    names = list(cfg.get("policies") or [])
    if not names:
        return [OmegaConf.to_container(cfg.policy, resolve=True)]
    require(len(set(names)) == len(names), "policies", "a list of distinct policy names", names)
    return [OmegaConf.to_container(_policy_node(cfg, name, chosen), resolve=True) for name in names]


def _policy_node(cfg: DictConfig, name: str, chosen: str | None) -> DictConfig:
    if name == chosen:
        return cfg.policy
    root = cfg.copy()
    with open_dict(root):
        root.policy = OmegaConf.load(POLICY_DIR / f"{check_policy_name(name)}.yaml")
    return root.policy


def reference_policy(cfg: DictConfig, specs: Sequence[PolicySpec], configs: Sequence[dict]) -> str | None:
    """The table name of ``reference`` (a conf/policy name) when it is evaluated; None for a single policy."""
    if len(specs) < 2:
        return None
    names = list(cfg.get("policies") or [])
    ref = cfg.get("reference")
    require(ref in names, "reference", f"one of the evaluated policies {names}", ref)
    return specs[names.index(ref)].name


def seeds_of(cfg: DictConfig) -> list[int]:
    """Reset seeds ``seed .. seed + episodes - 1`` (the same sensors for every policy)."""
    episodes, seed = cfg.get("episodes"), cfg.get("seed")
    ok = isinstance(episodes, int) and not isinstance(episodes, bool) and episodes >= 1
    require(ok, "episodes", "an integer >= 1", episodes)
    require(isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0, "seed", "an integer >= 0", seed)
    return list(range(seed, seed + episodes))


def output_dir(cfg: DictConfig) -> Path:
    """``out``, refused when it already holds results and ``overwrite`` is false, or cannot be written.

    Checked before the first episode, so that hours of episodes are never lost to an unwritable ``out``.
    """
    out = Path(str(cfg.out))
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"out={out} exists and is not a directory; choose another directory")
    if not cfg.overwrite and any((out / f).exists() for f in (RESULTS, SUMMARY, FIGURE)):
        raise FileExistsError(f"out={out} already holds results; choose another directory or pass overwrite=true")
    return check_creatable("out=", out)


def _cell(value: Any, fmt: str) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return "-"
    return fmt.format(value)


def summary_table(summaries: Sequence[Summary]) -> str:
    """The paper-style Markdown table, one row per policy."""
    lines = ["| " + " | ".join(h for h, _, _ in TABLE) + " |", "|" + "---|" * len(TABLE)]
    for s in summaries:
        lines.append("| " + " | ".join(_cell(getattr(s, key), fmt) for _, key, fmt in TABLE) + " |")
    return "\n".join(lines)


def results_csv(evaluations: Sequence[Evaluation]) -> str:
    """Every row of every policy as CSV (``vical.evaluation.harness.EpisodeRow`` columns; empty = n/a).

    ``budget_m`` is ``end`` for the whole episode.
    """
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for evaluation in evaluations:
        for row in evaluation.rows:
            cells = {k: "" if v is None else v for k, v in vars(row).items()}
            cells["budget_m"] = "end" if math.isinf(row.budget_m) else row.budget_m
            writer.writerow(cells)
    return buffer.getvalue()


# The error-versus-effort table: header, BudgetSummary attribute, format.
EFFORT_TABLE = (
    ("policy", "policy", "{}"),
    ("budget", "budget_m", None),
    ("reached", "reached", "{:.0%}"),
    ("path [m]", "path_m", "{:.2f}"),
    ("time [s]", "time_s", "{:.1f}"),
    ("mean error [%]", "mean_error_pct", "{:.3f}"),
    ("median error [%]", "median_error_pct", "{:.3f}"),
    ("intrinsics [px]", "intrinsic_px", "{:.2f}"),
    ("rotation [deg]", "rotation_deg", "{:.3f}"),
    ("translation [mm]", "translation_mm", "{:.2f}"),
    ("time offset [ms]", "time_offset_ms", "{:.3f}"),
    ("failed", "failed", "{:.0%}"),
    ("vs reference [%] (95 % CI)", "versus", None),
)


def _effort_cell(summary: BudgetSummary, key: str, fmt: str | None) -> str:
    if key == "budget_m":
        return budget_label(summary.budget_m)
    if key == "versus":
        v = summary.versus
        return "-" if v is None else f"{v.estimate:+.3f} [{v.low:+.3f}, {v.high:+.3f}]"
    return _cell(getattr(summary, key), fmt)


def effort_table(summaries: Sequence[BudgetSummary]) -> str:
    """Markdown table: every policy at every path budget (medians of the absolute errors)."""
    lines = ["| " + " | ".join(h for h, _, _ in EFFORT_TABLE) + " |", "|" + "---|" * len(EFFORT_TABLE)]
    for s in summaries:
        lines.append("| " + " | ".join(_effort_cell(s, key, fmt) for _, key, fmt in EFFORT_TABLE) + " |")
    return "\n".join(lines)


def stop_sentence(rule: StopRule) -> str:
    """How the episodes ended, in the summary's words (``conf/stop/``)."""
    if rule.rule == "policy":
        return "Each policy stops by its own rule (stop=policy)."
    source = rule.run_dir or f"the policy shipped for workspace {rule.workspace}"
    return (
        "Every baseline stops by the learned policy's information state (stop=information: the tolerances, "
        f"confidence and goal groups of {source}); `coverage` counts the episodes it stopped."
    )


def summary_markdown(
    cfg: DictConfig,
    summaries: Sequence[Summary],
    seeds: Sequence[int],
    effort: Sequence[BudgetSummary],
    reference: str | None,
    stop: StopRule,
    stops: Sequence[StopSummary] = (),
) -> str:
    task = cfg.task.name
    header = (
        f"# vical-evaluate: {task} task, workspace {cfg.env.workspace.name}\n\n"
        f"{len(seeds)} sensors per policy (reset seeds {seeds[0]}..{seeds[-1]}); error = the task's "
        f"{cfg.task.error_metric} metric. {stop_sentence(stop)}"
        "\n\n## Whole episodes\n\n"
        "Errors over successful calibrations, path length and calibration time over all episodes; absolute "
        "errors are means (intrinsics: ||[fx, fy, cx, cy] - truth||).\n\n"
    )
    failures = [f"- {s.policy}: {s.failed} of {s.episodes} calibrations failed" for s in summaries if s.failed]
    notes = "\n\nFailed calibrations (see results.csv, column error):\n" + "\n".join(failures) if failures else ""
    text = header + summary_table(summaries) + notes + "\n"
    if len(effort) > len(summaries):  # budgets were evaluated
        text += (
            "\n## Error versus effort\n\n"
            "Each episode calibrated on its recording cut where the path reached the budget (episodes that "
            "ended earlier count with their whole recording: `reached` says how many got that far). Errors "
            "count a failed calibration at the nominal parameters' error; absolute errors are medians over "
            "successful calibrations; the last column is the mean paired difference to the reference over "
            f"the same sensors with its 95 % bootstrap interval. Figure: {FIGURE}.\n\n" + effort_table(effort) + "\n"
        )
        if reference is not None:
            text += "\n" + "\n".join(significance_lines(effort, reference)) + "\n"
    if stops:
        text += (
            "\n## Time to the tolerances\n\n"
            "Every policy stopped by the same information state (stop=information). `stopped`: episodes that reached "
            "the goal within the step limit; `right`: of those, the share whose true errors of the task's scored "
            "groups are within the tolerances; time and path at the stop (an episode that never stopped counts "
            "with its whole recording, or at the horizon where `stop.horizon_s` sets one: `cut short` counts the "
            "episodes whose own limit ended them before it); decision: the policy's time to choose an action; the "
            "last columns: the "
            "mean paired difference to the reference on the same sensors with its 95 % bootstrap interval.\n\n"
            + stops_table(stops)
            + "\n"
        )
    return text


def _interval_cell(interval: Interval | None, fmt: str) -> str:
    if interval is None:
        return "-"
    return f"{fmt.format(interval.estimate)} [{fmt.format(interval.low)}, {fmt.format(interval.high)}]"


def stops_table(stops: Sequence[StopSummary]) -> str:
    """Markdown table of ``vical.evaluation.time_to_tolerance.summarize_stops``."""
    lines = [
        "| policy | sensors | stopped | right | out of reach | verdict right | forecast within 1.5x | cut short "
        "| time [s] (mean / median) | path [m] | decision [ms / step] | time vs reference [s] "
        "| path vs reference [m] |",
        "|" + "---|" * 13,
    ]
    for s in stops:
        right, verdict, forecast = (_share_cell(v) for v in (s.right, s.verdict_right, s.forecast_right))
        decision = "-" if math.isnan(s.decision_ms) else f"{s.decision_ms:.1f}"
        time_versus, path_versus = _interval_cell(s.time_versus, "{:+.1f}"), _interval_cell(s.path_versus, "{:+.2f}")
        lines.append(
            f"| {s.policy} | {s.sensors} | {s.stopped:.0%} | {right} | {s.out_of_reach:.0%} | {verdict} | {forecast} "
            f"| {s.cut_short:.0%} | {s.time_s:.1f} / {s.median_time_s:.1f} | {s.path_m:.2f} | {decision} "
            f"| {time_versus} | {path_versus} |"
        )
    return "\n".join(lines)


def _share_cell(value: float) -> str:
    return "-" if math.isnan(value) else f"{value:.0%}"


def overridden_env_keys(overrides: Sequence[str]) -> list[str]:
    """The ``env.*`` keys a Hydra command line sets (``env.max_steps=30``: ``env.max_steps``)."""
    keys = (o.split("=", 1)[0].lstrip("+~") for o in overrides if "=" in o)
    return [k for k in keys if k.startswith("env.")]


def unapplied_override_warnings(specs: Sequence[PolicySpec], env_cfg: dict, overrides: Sequence[str]) -> list[str]:
    """One line per policy whose own MDP settings (``Policy.env_settings``) replace ``env.*`` keys the user set.

    A learned policy of the information state runs in the MDP it was trained in: an
    ``env.information.*`` override changes the other policies' episodes, never its own.
    """
    keys = overridden_env_keys(overrides)
    if not keys:
        return []
    task = CalibrationTask.from_config(env_cfg["task"])
    lines = []
    for spec in specs:
        policies = [with_stop(instantiate_policy(s, spec.name), spec.stop) for s in spec.for_task(task)]
        carried = {key for policy in policies for key in policy.env_settings}
        replaced = [k for k in keys if k.split(".")[1] in carried]
        if replaced:
            lines.append(
                f"warning: {', '.join(replaced)} does not apply to {spec.name!r}: it runs with the settings it was "
                f"trained with (its run's env.{', env.'.join(sorted(carried))}); the other policies get it"
            )
    return lines


def evaluate(
    cfg: DictConfig, chosen: str | None, overrides: Sequence[str] = ()
) -> tuple[Path, list[Summary], list[BudgetSummary]]:
    """Evaluate every configured policy and write the results; the output directory and the summaries."""
    seeds = seeds_of(cfg)
    out = output_dir(cfg)
    budgets = check_budgets(cfg.get("budgets") or [])
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    configs = policy_configs(cfg, chosen)
    stop = StopRule.from_config(plain(cfg.get("stop")))
    specs = [dataclasses.replace(PolicySpec.from_config(c, "policy"), stop=stop) for c in configs]
    reference = reference_policy(cfg, specs, configs)
    paper = bool(cfg.get("paper_protocol", False))
    parallel = ParallelConfig.from_config(cfg.get("parallel"))
    for line in unapplied_override_warnings(specs, env_cfg, overrides):
        print(line, file=sys.stderr)
    evaluations = evaluate_policies(specs, env_cfg, seeds, budgets, paper, parallel, bool(cfg.progress))
    for evaluation in evaluations:
        for row in evaluation.rows:
            if row.error.startswith(EPISODE_FAILED):
                print(f"warning: {row.policy}: {row.error}", file=sys.stderr)
    summaries = [e.summary for e in evaluations]
    rows = {e.summary.policy: e.rows for e in evaluations}
    effort = summarize_effort(rows, budgets, reference)
    stops = []
    if stop.rule == "information":
        tolerances = information_settings(stop)["information"]["tolerances"]
        verifying = stop.out_of_reach and stop.verify_s is not None
        stops = summarize_stops(rows, cfg.task.name, tolerances, reference, stop.horizon_s, verifying)
    with files_together(out) as path_of:  # overwrite=true: the old set stays until the new one is whole
        path_of(RESULTS).write_text(results_csv(evaluations))
        path_of(SUMMARY).write_text(summary_markdown(cfg, summaries, seeds, effort, reference, stop, stops))
        if budgets:
            write_effort_figure(path_of(FIGURE), effort, cfg.task.name)
    return out, summaries, effort


YARDSTICKS = ("yardstick", "time_to_tolerance")  # conf/experiment/<kind>_<task>.yaml


def yardstick_config(task: str, kind: str = "yardstick") -> dict[str, Any]:
    """What ``fingerprint`` hashes of ``+experiment=<kind>_<task>``, as vical-evaluate composes it."""
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"+experiment={kind}_{task}"])
    chosen = "learned"  # the experiment's `policy` choice (for a learned policy added on the command line)
    names = list(cfg.policies)
    out = {
        "policy_configs": dict(zip(names, policy_configs(cfg, chosen), strict=True)),
        "env": OmegaConf.to_container(cfg.env, resolve=True),
        **{
            key: OmegaConf.to_container(cfg[key]) if OmegaConf.is_config(cfg[key]) else cfg[key]
            for key in PROTOCOL_KEYS
        },
    }
    stop = StopRule.from_config(plain(cfg.get("stop")))
    if stop.rule == "information":
        out["stop"] = {**information_settings(stop), "horizon_s": stop.horizon_s, "out_of_reach": stop.out_of_reach,
                       "verify_s": stop.verify_s}  # fmt: skip
    return out


def yardstick_fingerprint(task: str, kind: str = "yardstick") -> dict[str, str]:
    """The fingerprint of ``+experiment=<kind>_<task>`` (vical.evaluation.yardstick)."""
    return fingerprint(yardstick_config(task, kind))


@hydra.main(config_path=str(CONF_DIR), config_name="evaluate", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    task_begins()
    try:
        hydra_cfg = HydraConfig.get()
        with write_faults_in_one_line(APP, "out=", cfg.out):
            out, summaries, effort = evaluate(cfg, hydra_cfg.runtime.choices.get("policy"), hydra_cfg.overrides.task)
    except USER_ERRORS as err:
        fail(APP, err)
    print(summary_table(summaries))
    if len(effort) > len(summaries):
        print(effort_table(effort))
    print(f"results written to {out / RESULTS} and {out / SUMMARY}")


def main() -> None:
    """Console entry point: an unknown ``policy=``, a missing launcher plugin and Hydra's own override errors are
    one line before Hydra starts."""
    one_line_warnings()
    quiet_library_logs()
    name = override_value(sys.argv[1:], "policy")
    with hydra_start_up_held():
        try:
            check_launcher(sys.argv[1:])
            if name is not None:
                check_policy_name(name)
            check_composes(CONF_DIR, "evaluate", sys.argv[1:])
        except ConfigError as err:
            fail(APP, err)
        hydra_main()


if __name__ == "__main__":  # python -m: the console script's handling of Ctrl-C and SIGTERM
    run_command(APP, main)
