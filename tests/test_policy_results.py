"""Reading vical-evaluate's results files back, and the rule that picks the training seed to ship."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from vical.apps.evaluate import results_csv
from vical.evaluation.error_vs_effort import rows_at_budget
from vical.evaluation.harness import EpisodeRow
from vical.evaluation.results_file import by_policy, compare, read_results
from vical.evaluation.seed_choice import ShipRule, assess, choose_seed

ROOT = Path(__file__).resolve().parents[1]


def experiment_script(name: str):
    """``experiments/<name>.py`` as a module (its ``main(argv)`` runs in this process)."""
    spec = importlib.util.spec_from_file_location(name, ROOT / "experiments" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TOLERANCES = {"focal_px": 0.35, "principal_point_px": 0.35, "distortion_px": 0.5, "rotation_deg": 0.1,
              "translation_mm": 2.0, "time_offset_ms": 0.1}  # fmt: skip
EXPERT = "expert (long)"
LEARNED = "model-free learned policy"


def joint_end(policy: str, seed: int, score: float, *, stopped=True, rotation=0.05, failed=False, path=1.0, time=20.0):
    return EpisodeRow(policy, seed, score_pct=None if failed else score, prior_score_pct=5.0, rotation_deg=rotation,
                      translation_mm=1.0, time_offset_ms=0.02, path_length_m=path, recording_time_s=time,
                      coverage_reached=stopped, failed=failed)  # fmt: skip


def write(path: Path, rows: list[EpisodeRow]) -> Path:
    path.write_text(results_csv([SimpleNamespace(rows=rows)]))
    return path


def read_back(tmp_path: Path, rows: list[EpisodeRow]) -> list[EpisodeRow]:
    """``rows`` as vical-evaluate writes them and as the results reader gives them back."""
    path = tmp_path / f"results_{len(list(tmp_path.iterdir()))}.csv"
    return read_results(write(path, rows))


def expert_rows() -> list[EpisodeRow]:
    """The long expert on 4 sensors: 0.10 % at 0.5 m, 0.05 % at its end (100 m, 400 s)."""
    rows = []
    for seed in range(4):
        rows.append(EpisodeRow(EXPERT, seed, budget_m=0.5, score_pct=0.10, path_length_m=0.5, recording_time_s=10.0))
        rows.append(joint_end(EXPERT, seed, 0.05, stopped=False, path=100.0, time=400.0))
    return rows


def test_a_policy_that_ended_before_the_budget_is_scored_by_its_whole_episode(tmp_path):
    rows = [*expert_rows()]
    # Seeds 0-1 ended before 0.5 m (their end rows count there); seed 2's calibration failed (its
    # nominal parameters' 5 % count); seed 3 has a row at 0.5 m.
    rows += [joint_end(LEARNED, 0, 0.04, path=0.4), joint_end(LEARNED, 1, 0.06, path=0.45)]
    rows += [joint_end(LEARNED, 2, 0.0, failed=True), joint_end(LEARNED, 3, 0.02)]
    rows.append(EpisodeRow(LEARNED, 3, budget_m=0.5, score_pct=0.08))
    results = by_policy(read_results(write(tmp_path / "results.csv", rows)))
    at_half = {seed: row.effective_score_pct for seed, row in rows_at_budget(results[LEARNED], 0.5).items()}
    assert at_half == {0: 0.04, 1: 0.06, 2: 5.0, 3: 0.08}
    d = compare(results, LEARNED, EXPERT, 0.5)
    assert d.estimate == pytest.approx(np.mean([0.04, 0.06, 5.0, 0.08]) - 0.10)
    assert d.low <= d.estimate <= d.high
    # A budget another policy reached but neither of the two did: their whole episodes count.
    results["short a"] = [joint_end("short a", s, 0.3) for s in range(4)]
    results["short b"] = [joint_end("short b", s, 0.1 * s) for s in range(4)]
    assert compare(results, "short a", "short b", 0.5).estimate == pytest.approx(0.3 - 0.15)
    # One that no policy of the file reached is an error naming those it holds.
    with pytest.raises(ValueError, match=r"no path budget 1 m in the results; they hold \[0.5\] m"):
        compare(results, LEARNED, EXPERT, 1.0)


def test_results_read_back_as_written(tmp_path):
    rows = [*expert_rows(), joint_end(LEARNED, 0, 0.0, failed=True), EpisodeRow(LEARNED, 0, budget_m=0.25)]
    assert read_results(write(tmp_path / "results.csv", rows)) == rows  # empty cells back to None, end to inf
    path = tmp_path / "bad.csv"
    path.write_text(results_csv([SimpleNamespace(rows=rows)]).replace(",0.25,", ",a quarter,"))
    with pytest.raises(ValueError, match=r"bad.csv, line 11: budget_m 'a quarter' is not a float"):
        read_results(path)


def test_assess_counts_right_stops_only_among_the_stopped_episodes(tmp_path):
    learned = [
        joint_end(LEARNED, 0, 0.03, rotation=0.05),
        joint_end(LEARNED, 1, 0.03, rotation=0.15),  # stopped, but its rotation is outside 0.1 deg
        joint_end(LEARNED, 2, 0.03, failed=True),  # stopped, calibration failed: not right
        joint_end(LEARNED, 3, 0.03, stopped=False, rotation=0.5),  # ran to the step limit: not a stop
    ]
    # The baselines' file may hold a learned policy of the same name: it must not replace the candidate's.
    baselines = expert_rows() + [joint_end(LEARNED, s, 9.0) for s in range(4)]
    a = assess(read_back(tmp_path, learned), read_back(tmp_path, baselines), "joint", TOLERANCES, ShipRule())
    assert a.goal == pytest.approx(0.75)
    assert a.right == pytest.approx(1 / 3)
    assert (a.path_m, a.time_s, a.reference_path_m, a.reference_time_s) == (1.0, 20.0, 100.0, 400.0)
    assert a.versus.estimate == pytest.approx(np.mean([0.03, 0.03, 5.0, 0.03]) - 0.10)


def _assessment(tmp_path, score, *, time=20.0, rotation=0.05, stopped=True):
    learned = [joint_end(LEARNED, s, score, time=time, rotation=rotation, stopped=stopped) for s in range(4)]
    return {
        "joint": assess(
            read_back(tmp_path, learned), read_back(tmp_path, expert_rows()), "joint", TOLERANCES, ShipRule()
        )
    }


def test_the_rule_ships_the_best_eligible_candidate(tmp_path):
    rule = ShipRule()
    candidates = {
        "best but slow": _assessment(tmp_path, 0.01, time=101.0),  # over 1/4 of the expert's 400 s
        "best but wrong stops": _assessment(tmp_path, 0.01, rotation=0.2),
        "good": _assessment(tmp_path, 0.04),
        "worse": _assessment(tmp_path, 0.06),
    }
    assert rule.failures("joint", candidates["best but slow"]["joint"]) == ["joint: time 101.0 s > 0.25 x 400.0 s"]
    assert rule.failures("joint", candidates["best but wrong stops"]["joint"]) == ["joint: stops right 0% < 90%"]
    never_stopped = _assessment(tmp_path, 0.01, stopped=False)["joint"]
    assert rule.failures("joint", never_stopped) == ["joint: goal 0% < 90%", "joint: no episode stopped at the goal"]
    assert choose_seed(candidates, rule) == "good"
    assert choose_seed({k: candidates[k] for k in ("best but slow", "best but wrong stops")}, rule) is None


def test_bad_results_files_and_tolerances_are_named(tmp_path):
    with pytest.raises(ValueError, match="no such results file"):
        read_results(tmp_path / "missing.csv")
    (tmp_path / "other.csv").write_text("a,b\n1,2\n")
    with pytest.raises(ValueError, match=r"other.csv: not a vical-evaluate results file, it lacks the columns"):
        read_results(tmp_path / "other.csv")
    learned, expert = (
        read_back(tmp_path, [joint_end(LEARNED, s, 0.03) for s in range(4)]),
        read_back(tmp_path, expert_rows()),
    )
    with pytest.raises(ValueError, match=r"tolerances lack \['time_offset_ms'\] of the joint task"):
        tolerances = {k: v for k, v in TOLERANCES.items() if k != "time_offset_ms"}
        assess(learned, expert, "joint", tolerances, ShipRule())
    with pytest.raises(ValueError, match="no whole-episode rows of policy 'expert \\(long\\)'"):
        assess(learned, learned, "joint", TOLERANCES, ShipRule())


def test_choose_seed_script_ships_from_files(tmp_path, capsys):
    """experiments/choose_seed.py end to end: run configs, results files, the table and the choice."""
    base = {t: write(tmp_path / f"base_{t}.csv", expert_rows()) for t in ("joint", "intrinsic")}
    args = ["--baselines", str(base["joint"]), str(base["intrinsic"])]
    for name, score in (("s0", 0.06), ("s1", 0.04)):
        run = tmp_path / name
        run.mkdir()
        tol = "\n".join(f"      {k}: {v}" for k, v in TOLERANCES.items())
        (run / "config.yaml").write_text(f"env:\n  information:\n    tolerances:\n{tol}\n")
        rows = [joint_end(LEARNED, s, score) for s in range(4)]
        # The intrinsic task is scored by the intrinsic groups: within tolerance.
        intrinsic = [
            EpisodeRow(LEARNED, s, score_pct=score, prior_score_pct=5.0, focal_px=0.2, principal_point_px=0.2,
                       distortion_px=0.3, path_length_m=1.0, recording_time_s=20.0, coverage_reached=True)
            for s in range(4)
        ]  # fmt: skip
        args += ["--candidate", str(run), str(write(tmp_path / f"{name}_j.csv", rows)),
                 str(write(tmp_path / f"{name}_i.csv", intrinsic))]  # fmt: skip
    choose_seed_script = experiment_script("choose_seed")
    choose_seed_script.main(args)
    out = capsys.readouterr().out
    assert out.strip().endswith(f"ship: {tmp_path / 's1'}")
    assert "| joint | 100% | 100% | 1.00 / 100.00 | 20.0 / 400.0 | -0.060" in out
    with pytest.raises(SystemExit, match=r"config\.yaml is missing: pass the run_dir of a vical-train run"):
        choose_seed_script.main([*args[:3], "--candidate", str(tmp_path), args[-2], args[-1]])


def test_compare_results_script_prints_every_budget(tmp_path, capsys):
    """experiments/compare_results.py end to end: one row per budget the file holds, end last."""
    rows = expert_rows() + [joint_end(LEARNED, s, 0.02 * s, path=0.4) for s in range(4)]
    script = experiment_script("compare_results")
    args = [str(write(tmp_path / "results.csv", rows)), "--policy", LEARNED]
    script.main([*args, "--against", EXPERT])
    out = capsys.readouterr().out
    lines = [line for line in out.splitlines() if line.startswith("| 0.5 m") or line.startswith("| end")]
    # The learned episodes end before 0.5 m (their whole episodes count there): mean 0.03 against 0.10 and 0.05.
    assert [line.split(" | ")[1].split()[0] for line in lines] == ["-0.070", "-0.020"]
    with pytest.raises(SystemExit, match="no policy 'nobody'"):
        script.main([*args, "--against", "nobody"])
