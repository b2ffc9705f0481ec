"""Module paths that moved stay importable: every name a module defines is the same object at its old path."""

import ast
import importlib
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "vical"

# old module -> the modules its names moved to
MOVED = {
    "vical.policies.evaluation": ("vical.evaluation.harness",),
    "vical.policies.effort": ("vical.evaluation.error_vs_effort",),
    "vical.policies.statistics": ("vical.evaluation.intervals",),
    "vical.policies.yardstick": ("vical.evaluation.yardstick",),
    "vical.policies.results": ("vical.evaluation.results_file", "vical.evaluation.seed_choice"),
    "vical.policies.collect": ("vical.collection.runner",),
    "vical.sim.robot": ("vical.sim.panda",),
    "vical.io.checks": ("vical.io.sample_checks",),
    "vical.config": ("vical.config_checks",),
    "vical.sim.config": ("vical.sim.settings",),
    "vical.env.config": ("vical.env.settings",),
    "vical.data.types": (
        "vical.data.errors",
        "vical.data.sample_arrays",
        "vical.data.imu",
        "vical.data.camera_frames",
        "vical.data.sensor_truth",
        "vical.data.trajectory",
        "vical.data.sensor_recording",
    ),
}


def defined_names(module: str) -> set[str]:
    """Public names a module defines itself (functions, classes, assignments), read from its source."""
    tree = ast.parse((PACKAGE.parent / (module.replace(".", "/") + ".py")).read_text())
    names = set()
    for node in tree.body:
        if isinstance(node, ast.FunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            targets = [e for t in node.targets for e in (t.elts if isinstance(t, ast.Tuple) else [t])]
            names |= {t.id for t in targets if isinstance(t, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    return {n for n in names if not n.startswith("_")}


def imported_modules(module: str) -> set[str]:
    tree = ast.parse((PACKAGE.parent / (module.replace(".", "/") + ".py")).read_text())
    return {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_module_path_holds_every_name_of_its_new_modules(old):
    kept = importlib.import_module(old)
    for new in MOVED[old]:
        module = importlib.import_module(new)
        for name in sorted(defined_names(new)):
            assert getattr(kept, name, None) is getattr(module, name), f"{old}.{name} is not {new}.{name}"


@pytest.mark.parametrize("old", sorted(MOVED))
def test_an_old_module_path_only_re_exports_its_new_modules(old):
    assert not defined_names(old), f"{old} defines names of its own"
    assert imported_modules(old) == set(MOVED[old])


# modules that kept their path but not every definition -> the names they held (still importable from them)
KEPT = {
    "vical.rl.trainer": (
        "AGENT", "CHECKPOINT", "EVAL_SEED_OFFSET", "LAST_GOOD", "MAX_POLICY_LAG", "BoxActions", "Episode",
        "RunSettings",
        "TrainConfig", "TrainResult", "Trainer", "TrainingDivergedError", "checkpoint_step", "make_env",
        "parse_settings", "resume_status", "train",
    ),
}  # fmt: skip


@pytest.mark.parametrize("module", sorted(KEPT))
def test_a_module_that_kept_its_path_still_holds_the_names_it_held(module):
    kept = importlib.import_module(module)
    missing = [name for name in KEPT[module] if not hasattr(kept, name)]
    assert not missing, f"{module} lost {missing}"
