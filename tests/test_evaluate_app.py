"""vical-evaluate end to end: results.csv + summary.md, and one-line errors with exit status 2."""

import contextlib
import csv
import subprocess
import sys
from pathlib import Path

import pytest

from vical.evaluation.harness import COLUMNS

ROOT = Path(__file__).resolve().parents[1]


def evaluate(*overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "vical.apps.evaluate", *overrides], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_two_random_moving_episodes_write_the_results_the_tables_and_the_figure(tmp_path):
    out = tmp_path / "eval"
    done = evaluate("episodes=2", "seed=5", f"out={out}", "progress=false", "budgets=[0.5,1]")
    assert done.returncode == 0, done.stderr
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS
    assert {r["policy"] for r in rows} == {"random moving policy"}
    for seed in ("5", "6"):
        episode = [r for r in rows if r["seed"] == seed]
        end = episode[-1]
        assert end["budget_m"] == "end" and float(end["path_length_m"]) > 1.0
        # One row per budget below the episode's path, cut where the path reached the budget.
        assert [r["budget_m"] for r in episode[:-1]] == ["0.5", "1.0"]
        for row in episode[:-1]:
            assert float(row["path_length_m"]) == pytest.approx(float(row["budget_m"]), abs=0.01)
            assert float(row["recording_time_s"]) < float(end["recording_time_s"])
        for row in episode:
            assert row["failed"] == "False"
            assert 0.0 < float(row["score_pct"]) < 100.0 and row["score_pct"] == row["intrinsic_pct"]
            assert float(row["prior_score_pct"]) > float(end["score_pct"])
            assert row["extrinsic_pct"] == ""  # the intrinsic task estimates no extrinsic
        assert 1 <= int(end["steps"]) <= 20
        assert 0.0 < float(end["decision_ms"]) < 5.0  # a random draw per step: well under a millisecond's work
    summary = (out / "summary.md").read_text()
    header = "| policy | mean error [%] | error std [%] | path length [m] | calibration time [s] |"
    assert "intrinsic task, workspace practitioner" in summary and header in summary
    line = next(l for l in summary.splitlines() if l.startswith("| random moving policy |"))  # the first table
    ends = [r for r in rows if r["budget_m"] == "end"]
    mean = sum(float(r["score_pct"]) for r in ends) / 2
    assert line.split("|")[2].strip() == f"{mean:.2f}"
    at_half = [l for l in summary.splitlines() if l.startswith("| random moving policy | 0.5 m |")]
    assert len(at_half) == 1 and "100%" in at_half[0]  # both episodes travelled 0.5 m
    assert (out / "error_vs_effort.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert header in done.stdout
    again = evaluate("episodes=1", f"out={out}", "progress=false")  # results are never overwritten silently
    assert again.returncode == 2 and "overwrite=true" in again.stderr


def test_budgets_that_do_not_increase_exit_2_before_any_episode(tmp_path):
    for budgets in ("[1,0.5]", "[0,1]", "[1,inf]"):
        done = evaluate(f"budgets={budgets}", f"out={tmp_path / 'x'}", "progress=false")
        assert done.returncode == 2
        (line,) = done.stderr.strip().splitlines()
        assert line.startswith("vical-evaluate: error: budgets must be strictly increasing path lengths > 0 [m]")
    assert not (tmp_path / "x").exists()


def test_an_unknown_policy_exits_2_with_one_line(tmp_path):
    for override in ("policy=nope", "policies=[random_moving,nope]"):
        done = evaluate(override, f"out={tmp_path / 'x'}")
        assert done.returncode == 2
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("vical-evaluate: error: unknown policy 'nope'")
        assert "random_moving" in lines[0]
    assert not (tmp_path / "x").exists()


def test_an_env_override_a_learned_policy_replaces_is_named_in_a_warning(tmp_path):
    """The shipped information policy runs with its training's env.information: the override reaches the others."""
    done = evaluate(
        "task=joint", "env=information", "policies=[learned,random_moving]", "episodes=1", "seed=3", "budgets=[]",
        "progress=false", "env.information.confidence=0.95", "env.reward.path_weight=1", f"out={tmp_path / 'eval'}",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    warnings = [line for line in done.stderr.splitlines() if line.startswith("warning:")]
    assert warnings == [
        "warning: env.information.confidence does not apply to 'model-free learned policy': it runs with the "
        "settings it was trained with (its run's env.information, env.max_steps, env.state); the other policies get it"
    ]


def test_an_evaluation_stopped_while_writing_leaves_the_previous_results_whole(tmp_path, monkeypatch):
    """overwrite=true: the new results.csv, summary.md and figure replace the old ones only together, once all
    three are made; an interrupt while making them (here the figure) leaves the old set as it was."""
    from hydra import compose, initialize_config_dir

    from vical.apps import evaluate as app

    out = tmp_path / "eval"

    def run(*overrides: str):
        with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
            cfg = compose("evaluate", overrides=[f"out={out}", "progress=false", "budgets=[0.5]", *overrides])
        return app.evaluate(cfg, None)

    run("episodes=1", "seed=5")
    before = {name: (out / name).read_bytes() for name in ("results.csv", "summary.md", "error_vs_effort.png")}

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(app, "write_effort_figure", interrupted)
    with contextlib.suppress(KeyboardInterrupt):
        run("episodes=1", "seed=6", "overwrite=true")
    assert {name: (out / name).read_bytes() for name in before} == before
    assert sorted(p.name for p in out.iterdir()) == sorted(before)  # no temporary left


def test_stop_information_ends_the_baselines_by_the_information_state_and_the_summary_says_so(tmp_path):
    from hydra import compose, initialize_config_dir

    from vical.apps import evaluate as app

    out = tmp_path / "eval"
    overrides = [f"out={out}", "progress=false", "budgets=[]", "episodes=2", "seed=3", "workspace=practitioner"]
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("evaluate", overrides=[*overrides, "policies=[expert_long]", "stop=information"])
    _, (stopped,), _ = app.evaluate(cfg, None)
    with initialize_config_dir(str(ROOT / "conf"), version_base="1.3"):
        cfg = compose("evaluate", overrides=[*overrides, "policies=[expert_long]", f"out={tmp_path / 'own'}"])
    _, (own,), _ = app.evaluate(cfg, None)
    assert stopped.coverage_rate == 1.0 and own.coverage_rate == 0.0  # a trajectory has no goal of its own
    assert stopped.path_length_m < 0.5 * own.path_length_m
    summary = (out / "summary.md").read_text()
    assert "Every baseline stops by the learned policy's information state" in summary
    assert "## Time to the tolerances" in summary and "| expert (long) | 2 | 100% |" in summary
    own_summary = (tmp_path / "own" / "summary.md").read_text()
    assert "Each policy stops by its own rule" in own_summary and "Time to the tolerances" not in own_summary
