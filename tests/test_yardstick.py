"""The frozen yardstick: docs/results.md records its fingerprint, and any change of a baseline shows."""

import copy
import re
from pathlib import Path

import pytest
import yaml

from vical.apps.evaluate import yardstick_config, yardstick_fingerprint
from vical.evaluation.yardstick import fingerprint
from vical.policies.fourier import DEFAULT_PARAMS_FILE

RESULTS = Path(__file__).resolve().parents[1] / "docs" / "results.md"
TASKS = ("joint", "intrinsic")


HEADINGS = {"yardstick": "### The yardstick's fingerprint",
            "time_to_tolerance": "### The time-to-tolerance yardstick's fingerprint"}  # fmt: skip


def recorded_fingerprints(kind: str = "yardstick") -> dict[str, dict[str, str]]:
    """The table under the ``kind`` yardstick's fingerprint heading in docs/results.md: task -> part -> hash."""
    text = RESULTS.read_text()
    section = text.split(HEADINGS[kind], 1)[1].split("\n#", 1)[0]  # up to the next heading
    header = re.search(r"^\| part \|(.+)\|$", section, re.M)
    assert header, "docs/results.md: the fingerprint table has no header row"
    columns = [c.strip().strip("`").removeprefix(f"{kind}_") for c in header.group(1).split("|")]
    table: dict[str, dict[str, str]] = {task: {} for task in columns}
    for line in re.findall(r"^\| `?(\w+)`? \|(.+)\|$", section, re.M):
        part, cells = line
        if part == "part":
            continue
        for task, cell in zip(columns, cells.split("|"), strict=True):
            table[task][part] = cell.strip().strip("`")
    return table


@pytest.fixture(scope="module")
def computed():
    return {task: yardstick_fingerprint(task) for task in TASKS}


@pytest.mark.parametrize("task", TASKS)
def test_recorded_fingerprint_matches_the_yardstick_as_composed(task, computed):
    # A failure here means a baseline, its environment or the protocol changed after the yardstick was frozen:
    # rerun experiments/yardstick.py and record the new results and hashes with the reason, never silently.
    assert recorded_fingerprints()[task] == computed[task]


@pytest.mark.parametrize("task", TASKS)
def test_recorded_fingerprint_matches_the_time_to_tolerance_yardstick_as_composed(task):
    # As above, for experiments/time_to_tolerance.py's yardstick: its baselines, sensors, shared rule and horizon.
    assert recorded_fingerprints("time_to_tolerance")[task] == yardstick_fingerprint(task, "time_to_tolerance")


def test_baselines_are_the_same_in_both_tasks_and_the_environments_differ(computed):
    joint, intrinsic = computed["joint"], computed["intrinsic"]
    assert joint["baselines"] == intrinsic["baselines"]
    assert joint["environment"] != intrinsic["environment"]  # the task (and its sensor sampling) differs


@pytest.fixture(scope="module")
def resolved_joint():
    return yardstick_config("joint")


def test_a_changed_baseline_changes_its_hash_and_the_yardstick(resolved_joint, computed):
    assert fingerprint(resolved_joint) == computed["joint"]
    changed = copy.deepcopy(resolved_joint)
    changed["policy_configs"]["expert_short"]["joint"]["length"] = "long"
    after = fingerprint(changed)
    assert after["expert_short"] != computed["joint"]["expert_short"]
    assert after["baselines"] != computed["joint"]["baselines"]
    assert after["yardstick"] != computed["joint"]["yardstick"]
    assert after["expert_long"] == computed["joint"]["expert_long"]


def test_refitted_coefficients_change_the_model_based_hash(resolved_joint, computed, tmp_path):
    params = yaml.safe_load(DEFAULT_PARAMS_FILE.read_text())
    params["practitioner"]["joint"]["coefficients"][0][0][0] += 0.01
    refit = tmp_path / "model_based.yaml"
    refit.write_text(yaml.safe_dump(params))
    changed = copy.deepcopy(resolved_joint)
    changed["policy_configs"]["model_based"]["joint"]["params_file"] = str(refit)
    after = fingerprint(changed)
    assert after["model_based"] != computed["joint"]["model_based"]


def test_the_environment_hash_follows_the_episode_not_the_reward(resolved_joint, computed):
    reward = copy.deepcopy(resolved_joint)
    reward["env"]["reward"]["path_weight"] = 1.0
    reward["env"]["step_limit_final"] = True  # the learner's discount at the limit, not the episode
    assert fingerprint(reward) == computed["joint"]
    board = copy.deepcopy(resolved_joint)
    board["env"]["sim"]["board"]["distance"] = 0.8
    assert fingerprint(board)["environment"] != computed["joint"]["environment"]
    assert fingerprint(board)["baselines"] == computed["joint"]["baselines"]


@pytest.fixture(scope="module")
def time_to_tolerance_joint():
    return yardstick_config("joint", "time_to_tolerance")


def test_the_time_to_tolerance_yardstick_hashes_the_planners_candidates_and_the_shared_rule(time_to_tolerance_joint):
    resolved = time_to_tolerance_joint
    before = fingerprint(resolved)
    assert resolved["stop"]["information"]["tolerances"] == {
        "focal_px": 0.35, "principal_point_px": 0.35, "distortion_px": 0.5, "rotation_deg": 0.1,
        "translation_mm": 2.0, "time_offset_ms": 0.1,
    }  # fmt: skip
    assert resolved["stop"]["information"]["confidence"] == 0.9
    samples = copy.deepcopy(resolved)
    samples["policy_configs"]["greedy_information"]["joint"]["samples"] = 11
    after = fingerprint(samples)
    assert after["greedy_information"] != before["greedy_information"] and after["yardstick"] != before["yardstick"]
    assert after["expert_long"] == before["expert_long"]
    tolerance = copy.deepcopy(resolved)
    tolerance["stop"]["information"]["tolerances"]["rotation_deg"] = 0.2
    assert fingerprint(tolerance)["protocol"] != before["protocol"]
    assert fingerprint(tolerance)["baselines"] == before["baselines"]
    without = {k: v for k, v in resolved.items() if k != "stop"}
    assert fingerprint(without)["protocol"] != before["protocol"]  # the rule is part of this yardstick's protocol
