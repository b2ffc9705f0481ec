"""What users keep across vical versions still loads: a run directory written by ``vical-train`` and the shipped
policies' configs, whose ``_target_`` dotted paths name vical's modules.

``tests/data/tiny_intrinsic_run`` is a real run (its ``agent.pt``, ``config.yaml`` and ``train.log``), written by

    vical-train env=calibration task=intrinsic "agent.hidden_sizes=[16,16]" agent.batch_size=32 torch_threads=1 \\
        train.total_steps=300 train.warmup_steps=100 train.eval_every=0 train.checkpoint_every=0 \\
        train.plot_every_episodes=0 train.progress=false run_dir=tiny_intrinsic_run
"""

import csv
from pathlib import Path

import pytest
import yaml
from hydra import compose, initialize_config_dir
from hydra.utils import get_object

from vical.apps.evaluate import CONF_DIR, evaluate
from vical.policies.learned import PARAMS_DIR, SHIPPED_POLICIES

RUN = Path(__file__).resolve().parent / "data" / "tiny_intrinsic_run"
SAVED_CONFIGS = sorted(PARAMS_DIR.glob("*/config.yaml")) + [RUN / "config.yaml"]


def targets(node) -> list[str]:
    """Every ``_target_`` value in a nested config."""
    if isinstance(node, dict):
        found = [node["_target_"]] if isinstance(node.get("_target_"), str) else []
        return found + [t for value in node.values() for t in targets(value)]
    if isinstance(node, list):
        return [t for value in node for t in targets(value)]
    return []


def test_every_shipped_policy_is_a_saved_config():
    assert {path.parent for path in SAVED_CONFIGS} >= set(SHIPPED_POLICIES.values())


@pytest.mark.parametrize("config", SAVED_CONFIGS, ids=lambda p: p.parent.name)
def test_every_target_of_a_saved_run_config_resolves(config):
    names = targets(yaml.safe_load(config.read_text()))
    assert names, f"{config} names no _target_"
    for name in names:
        assert callable(get_object(name)), name


def test_a_saved_run_directory_evaluates_through_policy_run_dir(tmp_path):
    """``vical-evaluate policy=learned policy.run_dir=<run> task=intrinsic``, one short episode."""
    out = tmp_path / "eval"
    overrides = [
        "policy=learned",
        f"policy.run_dir={RUN}",
        "task=intrinsic",
        "episodes=1",
        "budgets=[]",
        "env.max_steps=3",
        f"out={out}",
        "progress=false",
    ]
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=overrides)
    _, (summary,), _ = evaluate(cfg, "learned", overrides)
    assert summary.policy == "model-free learned policy" and summary.episodes == 1
    with open(out / "results.csv", newline="") as f:
        (row,) = csv.DictReader(f)
    assert row["budget_m"] == "end" and 1 <= int(row["steps"]) <= 3 and float(row["path_length_m"]) > 0.0
