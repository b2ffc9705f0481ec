"""experiments/guided_comparison.py on one tuning sensor: its settings reach every condition and its runs are kept."""

import math
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "experiments"))
import guided_comparison  # noqa: E402

from vical.evaluation.harness import END  # noqa: E402
from vical.evaluation.results_file import read_results  # noqa: E402

GREEDY = "guided, greedy planner"


@pytest.mark.integration
def test_two_guided_conditions_on_one_sensor_are_kept_as_a_results_file(tmp_path, capsys):
    out = tmp_path / "guided"
    settings = ["--set", "limits.max_steps=4", "--out", str(out)]
    assert guided_comparison.main(["--sensors", "1", "--seed", "40000", "--conditions", GREEDY, *settings]) == 0
    printed = capsys.readouterr().out
    assert (out / "summary.md").read_text() == printed
    assert "(seeds 40000-40000), with limits.max_steps=4" in printed
    rows = {row.policy: row for row in read_results(out / "results.csv")}
    assert set(rows) == {guided_comparison.REFERENCE, GREEDY}
    for row in rows.values():
        assert row.seed == 40000 and row.budget_m == END
        assert row.steps == 4  # the setting reached both conditions: 4 poses shown, no "done" that soon
        assert not row.coverage_reached and not row.failed
        assert 4 * 1.5 < row.recording_time_s < 4 * 8.0 + 5  # a reach of at least 1.5 s a pose, 8 s patience at most
        assert row.decision_ms > 1.0  # the planners predict their candidates: wall time per pose shown
        assert math.isfinite(row.rotation_deg) and math.isfinite(row.translation_mm)
