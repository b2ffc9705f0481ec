"""``vical-evaluate``: run policies on sampled sensors, calibrate every episode, print the paper's table.

Config: ``conf/evaluate.yaml`` (groups ``sim``, ``sensor``, ``task``, ``env``, ``policy``; ``policies`` for
a table of several; ``+experiment=table1_intrinsic`` etc. for the paper's tables). Writes
``<out>/results.csv`` (one row per episode) and ``<out>/summary.md`` (the table), both atomically.

User-facing errors (an unknown policy, a missing run directory of the learned policy, a bad config
value) print one line ``vical-evaluate: error: ...`` and exit with status 2, as ``vical-train`` does.
"""

from __future__ import annotations

import csv
import io
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf
from omegaconf.errors import OmegaConfBaseException

from vical.apps.cli import fail, override_value
from vical.config import ConfigError, require
from vical.io.atomic import write_text_atomic
from vical.policies.evaluation import COLUMNS, Evaluation, PolicyEvaluator, PolicySpec, Summary, run_evaluator

# An absolute path: the console script imports this module from anywhere.
CONF_DIR = Path(__file__).resolve().parents[2] / "conf"
POLICY_DIR = CONF_DIR / "policy"
USER_ERRORS = (ConfigError, FileNotFoundError, FileExistsError, OmegaConfBaseException)
APP = "vical-evaluate"
RESULTS, SUMMARY = "results.csv", "summary.md"

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
    command-line overrides), the others are read from ``conf/policy/<name>.yaml``.
    """
    names = list(cfg.get("policies") or [])
    if not names:
        return [OmegaConf.to_container(cfg.policy, resolve=True)]
    require(len(set(names)) == len(names), "policies", "a list of distinct policy names", names)
    configs = []
    for name in names:
        node = cfg.policy if name == chosen else OmegaConf.load(POLICY_DIR / f"{check_policy_name(name)}.yaml")
        configs.append(OmegaConf.to_container(node, resolve=True))
    return configs


def seeds_of(cfg: DictConfig) -> list[int]:
    """Reset seeds ``seed .. seed + episodes - 1`` (the same sensors for every policy)."""
    episodes, seed = cfg.get("episodes"), cfg.get("seed")
    ok = isinstance(episodes, int) and not isinstance(episodes, bool) and episodes >= 1
    require(ok, "episodes", "an integer >= 1", episodes)
    require(isinstance(seed, int) and not isinstance(seed, bool) and seed >= 0, "seed", "an integer >= 0", seed)
    return list(range(seed, seed + episodes))


def output_dir(cfg: DictConfig) -> Path:
    """``out``, refused when it already holds results and ``overwrite`` is false."""
    out = Path(str(cfg.out))
    if out.exists() and not out.is_dir():
        raise FileExistsError(f"out={out} exists and is not a directory; choose another directory")
    if not cfg.overwrite and any((out / f).exists() for f in (RESULTS, SUMMARY)):
        raise FileExistsError(f"out={out} already holds results; choose another directory or pass overwrite=true")
    return out


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
    """Every episode of every policy as CSV (``vical.policies.evaluation.EpisodeRow`` columns; empty = n/a)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for evaluation in evaluations:
        for row in evaluation.rows:
            writer.writerow({k: "" if v is None else v for k, v in vars(row).items()})
    return buffer.getvalue()


def summary_markdown(cfg: DictConfig, summaries: Sequence[Summary], seeds: Sequence[int]) -> str:
    task = cfg.task.name
    header = (
        f"# vical-evaluate: {task} task\n\n"
        f"{len(seeds)} sensors per policy (reset seeds {seeds[0]}..{seeds[-1]}); error = the task's "
        f"{cfg.task.error_metric} metric; errors over successful calibrations, path length and calibration "
        "time over all episodes; absolute errors are means (intrinsics: ||[fx, fy, cx, cy] - truth||).\n\n"
    )
    failures = [f"- {s.policy}: {s.failed} of {s.episodes} calibrations failed" for s in summaries if s.failed]
    notes = "\n\nFailed calibrations (see results.csv, column error):\n" + "\n".join(failures) if failures else ""
    return header + summary_table(summaries) + notes + "\n"


def evaluate(cfg: DictConfig, chosen: str | None) -> tuple[Path, list[Summary]]:
    """Evaluate every configured policy and write the results; the output directory and the summaries."""
    seeds = seeds_of(cfg)
    out = output_dir(cfg)
    env_cfg = OmegaConf.to_container(cfg.env, resolve=True)
    specs = [PolicySpec.from_config(c, "policy") for c in policy_configs(cfg, chosen)]
    # Build every policy before the first episode, so a bad spec (a missing run) fails in seconds.
    evaluators = [PolicyEvaluator(spec, env_cfg) for spec in specs]
    evaluations = [run_evaluator(e, seeds, bool(cfg.progress)) for e in evaluators]
    summaries = [e.summary for e in evaluations]
    write_text_atomic(out / RESULTS, results_csv(evaluations))
    write_text_atomic(out / SUMMARY, summary_markdown(cfg, summaries, seeds))
    return out, summaries


@hydra.main(config_path=str(CONF_DIR), config_name="evaluate", version_base="1.3")
def hydra_main(cfg: DictConfig) -> None:
    try:
        out, summaries = evaluate(cfg, HydraConfig.get().runtime.choices.get("policy"))
    except USER_ERRORS as err:
        fail(APP, err)
    print(summary_table(summaries))
    print(f"results written to {out / RESULTS} and {out / SUMMARY}")


def main() -> None:
    """Console entry point: refuse an unknown ``policy=`` choice in one line before Hydra composes."""
    name = override_value(sys.argv[1:], "policy")
    if name is not None:
        try:
            check_policy_name(name)
        except ConfigError as err:
            fail(APP, err)
    hydra_main()


if __name__ == "__main__":
    main()
