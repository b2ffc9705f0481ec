"""Every option of every config group composes with Hydra (and root configs with their defaults)."""

from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

CONF = Path(__file__).resolve().parents[1] / "conf"
GROUPS = sorted(p.name for p in CONF.iterdir() if p.is_dir() and p.name != "experiment")
OPTIONS = [(g, f.stem) for g in GROUPS for f in sorted((CONF / g).glob("*.yaml"))]
ROOTS = sorted(f.stem for f in CONF.glob("*.yaml"))
# Groups whose options interpolate other groups of the root config (env=calibration reads sim, sensor, task and
# workspace; model_based and stop=information read the workspace's name; a workspace writes into sim; robot=sim
# and person=sim read sim, sensor, task and the seed).
NEEDS = {
    "env": ["+sim=default", "+sensor=paper", "+task=joint", "+workspace=practitioner"],
    "policy": ["+workspace=practitioner"],
    "stop": ["+workspace=practitioner"],
    "workspace": ["+sim=default"],
    "robot": ["+sim=default", "+sensor=paper", "+task=joint", "+seed=0"],
    "person": ["+sim=default", "+sensor=paper", "+task=joint", "+seed=0"],
}


def test_every_group_has_options():
    assert {"sim", "sensor", "task", "env", "agent", "workspace"} <= set(GROUPS)
    for group in ("task", "env"):
        assert any(g == group for g, _ in OPTIONS), f"conf/{group}/ has no options"


@pytest.mark.parametrize(("group", "option"), OPTIONS)
def test_group_option_composes(group, option):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(overrides=[f"+{group}={option}", *NEEDS.get(group, [])])
    node = OmegaConf.to_container(cfg[group], resolve=True)
    assert isinstance(node, dict) and node


@pytest.mark.parametrize("root", ROOTS)
def test_root_config_composes(root):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name=root)
    raw = OmegaConf.to_container(cfg, resolve=False)
    for key, value in raw.items():
        # ${hydra:...} (run directories) resolves only inside a Hydra run; everything else must resolve here.
        if isinstance(value, str) and "${hydra:" in value:
            continue
        node = cfg[key]
        OmegaConf.to_container(node, resolve=True) if OmegaConf.is_config(node) else str(node)


def test_task_files_name_themselves_and_a_metric():
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        for task in ("intrinsic", "extrinsic", "joint"):
            cfg = compose(overrides=[f"+task={task}"]).task
            assert cfg.name == task
            assert cfg.error_metric in ("intrinsic_relative", "extrinsic_relative")


# train_*.yaml configure vical-train; the others (the paper's tables, the yardstick) vical-evaluate.
EXPERIMENTS = sorted(f.stem for f in (CONF / "experiment").glob("*.yaml"))
TRAIN_EXPERIMENTS = [e for e in EXPERIMENTS if e.startswith("train_")]
TABLE_EXPERIMENTS = [e for e in EXPERIMENTS if not e.startswith("train_")]
PAPER_TABLES = [e for e in TABLE_EXPERIMENTS if e.startswith("table")]


@pytest.mark.parametrize("experiment", TRAIN_EXPERIMENTS)
def test_training_experiment_composes_with_vical_train(experiment):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"+experiment={experiment}"])
    assert cfg.env._target_ == "vical.env.calibration.CalibrationEnv"
    OmegaConf.to_container(cfg.env, resolve=True)
    if cfg.train.distill is None:  # a distillation trains in its rounds, SAC's steps (total_steps) may be none
        assert cfg.train.total_steps > cfg.train.warmup_steps
    else:
        assert cfg.train.distill.rounds >= 1 and cfg.train.demonstrator is not None


@pytest.mark.parametrize("experiment", TABLE_EXPERIMENTS)
def test_experiment_composes_with_vical_evaluate(experiment):
    with initialize_config_dir(config_dir=str(CONF), version_base="1.3"):
        cfg = compose(config_name="evaluate", overrides=[f"+experiment={experiment}", "policy.run_dir=runs/x"])
    assert cfg.task.name in experiment  # table1_intrinsic -> the intrinsic task
    paper = experiment in PAPER_TABLES  # the paper's tables: 20 sensors in the authors' box, its protocol
    assert (cfg.episodes, cfg.paper_protocol, cfg.workspace.name) == (
        (20, True, "paper") if paper else (50, False, "practitioner")
    )
    assert not cfg.budgets if paper else list(cfg.budgets) == sorted(cfg.budgets)
    known = {f.stem for f in (CONF / "policy").glob("*.yaml")}
    assert cfg.policies and set(cfg.policies) <= known
    assert cfg.policy.run_dir == "runs/x"  # the learned policy takes the run from the command line
    OmegaConf.to_container(cfg.env, resolve=True)
