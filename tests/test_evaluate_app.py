"""vical-evaluate end to end: results.csv + summary.md, and one-line errors with exit status 2."""

import csv
import subprocess
import sys
from pathlib import Path

from vical.policies.evaluation import COLUMNS

ROOT = Path(__file__).resolve().parents[1]


def evaluate(*overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "vical.apps.evaluate", *overrides], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


def test_two_random_moving_episodes_write_the_results_and_the_table(tmp_path):
    out = tmp_path / "eval"
    done = evaluate("episodes=2", "seed=5", f"out={out}", "progress=false")
    assert done.returncode == 0, done.stderr
    with open(out / "results.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == COLUMNS
    assert [r["seed"] for r in rows] == ["5", "6"]
    assert {r["policy"] for r in rows} == {"random moving policy"}
    for row in rows:
        assert row["failed"] == "False"
        assert 0.0 < float(row["score_pct"]) < 100.0 and row["score_pct"] == row["intrinsic_pct"]
        assert float(row["path_length_m"]) > 0.0 and 1 <= int(row["steps"]) <= 20
        assert row["extrinsic_pct"] == ""  # the intrinsic task estimates no extrinsic
    summary = (out / "summary.md").read_text()
    header = "| policy | mean error [%] | error std [%] | path length [m] | calibration time [s] |"
    assert "intrinsic task" in summary and header in summary
    (line,) = [l for l in summary.splitlines() if l.startswith("| random moving policy |")]
    mean = sum(float(r["score_pct"]) for r in rows) / 2
    assert line.split("|")[2].strip() == f"{mean:.2f}"
    assert header in done.stdout
    again = evaluate("episodes=1", f"out={out}", "progress=false")  # results are never overwritten silently
    assert again.returncode == 2 and "overwrite=true" in again.stderr


def test_an_unknown_policy_exits_2_with_one_line(tmp_path):
    for override in ("policy=nope", "policies=[random_moving,nope]"):
        done = evaluate(override, f"out={tmp_path / 'x'}")
        assert done.returncode == 2
        lines = done.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("vical-evaluate: error: unknown policy 'nope'")
        assert "random_moving" in lines[0]
    assert not (tmp_path / "x").exists()
